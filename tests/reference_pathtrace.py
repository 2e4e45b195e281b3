"""A slow, obvious path tracer in plain Python for scenes of spheres: the reference the compiled one is checked
against.

It restates the rules of :mod:`tracer.rendering.pathtrace` and the generator of
:mod:`tracer.rendering.sampling` with Python integers and floats, tests every
sphere for every ray (no kd-tree), and returns the radiance of one sample.
"""
from __future__ import annotations

import math

MASK = (1 << 64) - 1
GAMMA = 0x9E3779B97F4A7C15
N_DIMENSIONS = 6
LOBE, DIRECTION_U, DIRECTION_V, ROULETTE, JITTER_X, JITTER_Y = range(6)
ROULETTE_BOUNCE = 3
ROULETTE_CAP = 0.95


def mix(z):
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def key_of(seed, pixel, sample):
    h = mix((seed + GAMMA * (pixel + 1)) & MASK)
    return mix((h + GAMMA * (sample + 1)) & MASK)


def rand(key, bounce, dimension):
    return (mix((key + GAMMA * (bounce * N_DIMENSIONS + dimension + 1)) & MASK) >> 11) / 2.0 ** 53


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cosine_sample(n, u, v):
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    t = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    s = (b, sign + n[1] * n[1] * a, -n[1])
    r, phi = math.sqrt(u), 2.0 * math.pi * v
    x, y, z = r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - u))
    return tuple(x * t[i] + y * s[i] + z * n[i] for i in range(3))


class SphereScene:
    """Spheres (centre, radius, material row), materials (colour, kd, ks, t, ior), lights (position, colour)."""

    def __init__(self, spheres, materials, lights, background):
        self.spheres, self.materials, self.background = spheres, materials, background
        scale = math.sqrt(len(lights)) / (2.0 * len(lights)) if lights else 0.5
        self.lights = [(p, tuple(c * scale for c in colour)) for p, colour in lights]

    def hit(self, o, d, tmin, tmax):
        best, which = tmax, -1
        for i, (c, r, _) in enumerate(self.spheres):
            p = (o[0] - c[0], o[1] - c[1], o[2] - c[2])
            b = dot(p, d)
            disc = b * b - (dot(p, p) - r * r)
            if disc < 0.0:
                continue
            s = math.sqrt(disc)
            for t in (-b - s, -b + s):
                if tmin < t < best:
                    best, which = t, i
                    break
        return best, which


def radiance(scene, o, d, key, hither, eps, max_depth):
    """The radiance of one path from ``o`` along unit ``d`` (the sample of ``key``)."""
    total = [0.0, 0.0, 0.0]
    thr = [1.0, 1.0, 1.0]
    for bounce in range(max_depth):
        t, i = scene.hit(o, d, hither if bounce == 0 else eps, math.inf)
        if i < 0:
            for c in range(3):
                total[c] += thr[c] * scene.background[c]
            break
        h = tuple(o[c] + t * d[c] for c in range(3))
        centre, r, m = scene.spheres[i]
        n = tuple((h[c] - centre[c]) / r for c in range(3))
        ddn = dot(d, n)
        f = tuple(-x for x in n) if ddn > 0.0 else n
        colour, kd, ks, tr, ior = scene.materials[m]
        albedo = [kd * colour[c] for c in range(3)]
        if kd > 0.0:
            for position, light in scene.lights:
                lvec = tuple(position[c] - h[c] for c in range(3))
                dist = math.sqrt(dot(lvec, lvec))
                if dist == 0.0:
                    continue
                lvec = tuple(x / dist for x in lvec)
                ndl = dot(f, lvec)
                if ndl <= 0.0 or scene.hit(h, lvec, eps, dist)[1] >= 0:
                    continue
                for c in range(3):
                    total[c] += thr[c] * albedo[c] * ndl * light[c]
        if bounce + 1 >= max_depth:
            break
        w_diffuse = kd * max(colour)
        weights = w_diffuse + ks + tr
        if weights <= 0.0:
            break
        u = rand(key, bounce, LOBE) * weights
        if u < w_diffuse:
            d = cosine_sample(f, rand(key, bounce, DIRECTION_U), rand(key, bounce, DIRECTION_V))
            thr = [thr[c] * albedo[c] * (weights / w_diffuse) for c in range(3)]
        else:
            new = None
            if u >= w_diffuse + ks:
                eta, cosi = (1.0 / ior, -ddn) if ddn < 0.0 else (ior, ddn)
                k2 = 1.0 - eta * eta * (1.0 - cosi * cosi)
                if k2 >= 0.0:
                    c2 = eta * cosi - math.sqrt(k2)
                    new = tuple(eta * d[c] - c2 * f[c] for c in range(3))
            if new is None:
                dn = dot(d, f)
                new = tuple(d[c] - 2.0 * dn * f[c] for c in range(3))
            length = math.sqrt(dot(new, new))
            d = tuple(x / length for x in new)
            thr = [x * weights for x in thr]
        if bounce + 1 >= ROULETTE_BOUNCE:
            q = min(max(thr), ROULETTE_CAP)
            if q <= 0.0 or rand(key, bounce, ROULETTE) >= q:
                break
            thr = [x / q for x in thr]
        o = h
    return total
