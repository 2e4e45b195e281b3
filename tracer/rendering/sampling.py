"""Counter-based random numbers and cosine-weighted directions for the path tracer.

The generator is a hash, not a stream: the number of dimension ``d`` at
bounce ``b`` of sample ``s`` of pixel ``p`` under seed ``seed`` is a function
of those five integers alone, so a path's random numbers do not depend on
which rays were traced before it (or in which order, or on which thread).

The hash is SplitMix64's output function (Steele, Lea and Flood 2014, the
finaliser of ``java.util.SplittableRandom``) applied in a chain:

* ``key = mix(mix(seed + G (p + 1)) + G (s + 1))`` per sample, with ``G`` the
  64-bit golden-ratio increment ``0x9E3779B97F4A7C15``;
* ``u = (mix(key + G (b N_DIMENSIONS + d + 1)) >> 11) * 2**-53``, a float in
  [0, 1) with 53 random bits.

All arithmetic is modulo 2**64. ``tests/reference_pathtrace.py`` restates it
in plain Python integers.
"""
from __future__ import annotations

import enum
import math

import numpy as np
from numba import njit

#: SplitMix64's increment, the odd integer nearest 2**64 / golden ratio.
GOLDEN_GAMMA = 0x9E3779B97F4A7C15
_MIX_1 = 0xBF58476D1CE4E5B9
_MIX_2 = 0x94D049BB133111EB
_UNIT = 1.0 / 9007199254740992.0  # 2**-53


class Dimension(enum.IntEnum):
    """The random numbers one bounce of a path draws (the ``d`` of the key)."""

    LOBE = 0         #: which lobe scatters: diffuse, specular or transmission
    DIRECTION_U = 1  #: cosine-weighted direction: radius**2
    DIRECTION_V = 2  #: cosine-weighted direction: angle / 2 pi
    ROULETTE = 3     #: Russian roulette
    JITTER_X = 4     #: camera ray's offset across the pixel (bounce 0 only)
    JITTER_Y = 5     #: camera ray's offset down the pixel (bounce 0 only)


N_DIMENSIONS = len(Dimension)


@njit(cache=True, inline="always")
def mix64(z):
    """SplitMix64's output function of a uint64 (wrapping arithmetic)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(_MIX_1)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(_MIX_2)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def sample_key(seed, pixel, sample):
    """The uint64 key of sample ``sample`` of pixel ``pixel`` under ``seed`` (all non-negative ints)."""
    gamma = np.uint64(GOLDEN_GAMMA)
    h = mix64(np.uint64(seed) + gamma * np.uint64(pixel + 1))
    return mix64(h + gamma * np.uint64(sample + 1))


@njit(cache=True, inline="always")
def uniform(key, bounce, dimension):
    """The number in [0, 1) of ``dimension`` (a :class:`Dimension`) at ``bounce`` of the sample of ``key``."""
    h = mix64(key + np.uint64(GOLDEN_GAMMA) * np.uint64(bounce * N_DIMENSIONS + dimension + 1))
    return np.float64(h >> np.uint64(11)) * _UNIT


@njit(cache=True, inline="always")
def cosine_direction(nx, ny, nz, u, v):
    """A unit direction about the unit normal ``n`` with density cos(theta) / pi, from ``u, v`` in [0, 1).

    Concentric-free mapping: radius ``sqrt(u)``, angle ``2 pi v`` on the disc,
    lifted to the hemisphere; the tangent frame is Duff et al.'s (2017)
    branchless orthonormal basis. Returns ``dx, dy, dz``.
    """
    sign = math.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    tx, ty, tz = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
    bx, by, bz = b, sign + ny * ny * a, -ny
    r = math.sqrt(u)
    phi = 2.0 * math.pi * v
    x = r * math.cos(phi)
    y = r * math.sin(phi)
    z = math.sqrt(max(0.0, 1.0 - u))
    return x * tx + y * bx + z * nx, x * ty + y * by + z * ny, x * tz + y * bz + z * nz
