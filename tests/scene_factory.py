"""Small seeded scenes for tracer tests, built with :class:`tracer.scenes.model.SceneBuilder`."""
from __future__ import annotations

import numpy as np

from tracer.scenes.model import Camera, Material, SceneBuilder

KINDS = ("sphere", "triangle", "polygon", "patch", "cone")


def _regular_polygon(rng, n, centre, radius):
    # a convex planar n-gon, counter-clockwise about a random normal
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    a = np.cross(normal, [1.0, 0.0, 0.0])
    if np.linalg.norm(a) < 1e-3:
        a = np.cross(normal, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    if np.diff(np.r_[angles, angles[0] + 2 * np.pi]).max() >= np.pi:
        angles = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 1)
    return centre + radius * (np.cos(angles)[:, None] * a + np.sin(angles)[:, None] * b), normal


def random_scene(kinds=KINDS, n=60, seed=0, extent=4.0, size=0.6, lights=2):
    """A seeded scene of ``n`` elements of the given kinds (round robin).

    Elements overlap and vary in size; materials alternate diffuse,
    reflective and transparent so every ray type occurs.
    """
    rng = np.random.default_rng(seed)
    b = SceneBuilder(f"random-{'-'.join(kinds)}-{seed}")
    b.camera = Camera(eye=(0.0, -3.0 * extent, 0.5 * extent), look_at=(0.0, 0.0, 0.0), up=(0, 0, 1),
                      angle=40.0, hither=1e-3, resolution=(32, 32))
    b.background = (0.1, 0.2, 0.3)
    b.max_depth = 4
    mats = [Material((0.9, 0.3, 0.2), 0.8, 0.0, 10.0, 0.0, 1.0),
            Material((0.8, 0.8, 0.8), 0.5, 0.5, 20.0, 0.0, 1.0),
            Material((0.9, 0.9, 1.0), 0.2, 0.2, 50.0, 0.7, 1.5)]
    for e in range(n):
        kind = kinds[e % len(kinds)]
        b.material(mats[rng.integers(len(mats))])
        c = rng.uniform(-extent, extent, 3)
        s = size * rng.uniform(0.2, 1.5)
        if kind == "sphere":
            b.sphere(c, s)
        elif kind == "triangle":
            b.triangle(c + rng.normal(scale=s, size=(3, 3)))
        elif kind == "polygon":
            v, _ = _regular_polygon(rng, int(rng.integers(4, 7)), c, s)
            b.polygon(v)
        elif kind == "patch":
            v, nrm = _regular_polygon(rng, int(rng.integers(3, 6)), c, s)
            normals = nrm + rng.normal(scale=0.2, size=v.shape)
            b.patch(v, normals / np.linalg.norm(normals, axis=1)[:, None])
        elif kind == "cone":
            axis = rng.normal(size=3)
            axis *= s * 2 / np.linalg.norm(axis)
            r0 = s * rng.uniform(0.2, 0.8)
            r1 = s * rng.uniform(0.0, 0.8) * (1 if e % 2 else 0)
            sign = -1.0 if e % 3 == 0 else 1.0
            b.cone(c, sign * r0, c + axis, sign * r1 if r1 else 0.0)
        else:
            raise ValueError(kind)
    for k in range(lights):
        b.light(rng.uniform(-extent, extent, 3) + [0, 0, 2 * extent])
    return b.build()


def one_sphere(radius=1.0, centre=(0.0, 0.0, 0.0)):
    """A single diffuse sphere seen from +z at distance 5, one light."""
    b = SceneBuilder("one-sphere")
    b.camera = Camera(eye=(0.0, 0.0, 5.0), look_at=(0.0, 0.0, 0.0), up=(0, 1, 0), angle=40.0,
                      hither=1e-3, resolution=(9, 9))
    b.max_depth = 1
    b.material(Material((1.0, 1.0, 1.0), 1.0, 0.0, 1.0, 0.0, 1.0))
    b.sphere(centre, radius)
    b.light((0.0, 0.0, 10.0))
    return b.build()


def random_rays(n, seed, extent=4.0):
    """Seeded rays: origins in a box a bit larger than the scene, random directions."""
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.5 * extent, 1.5 * extent, (n, 3))
    # half of the rays aim at points inside the scene so that many hit
    target = rng.uniform(-extent, extent, (n, 3))
    d = np.where(rng.random(n)[:, None] < 0.5, target - o, rng.normal(size=(n, 3)))
    return o, d / np.linalg.norm(d, axis=1)[:, None]
