"""Sorted wavefronts: the wavefront walk with each phase's rays sorted by a spatial key.

Every order here runs :func:`~coherence.ray_order_base.wavefront_pieces`
(phases by bounce, so every ray still runs after its parent) and sorts each
phase's queue stably by a 63-bit key before running it, paying
:func:`coherence.cost.ray_sort_cycles` for it. Positions are quantised in
the box of the whole trace's origins and hit points
(:func:`coherence.ray_orders.scene_bounds_of`), the same for every process.

* ``morton-origin``: the Morton code (Z curve, 21 bits per axis) of the ray's origin.
* ``octant-origin``: the direction's octant (3 sign bits) first, then the
  Morton code of the origin at 20 bits per axis.
* ``hit-point``: the Morton code (21 bits per axis) of a proxy of where the
  ray ends, after Moon et al.'s hit-point heuristic. The proxy is the ray's
  own logged hit (for a shadow ray, its blocker), or where a ray that hit
  nothing leaves the box (origin plus the box's diagonal length along the
  direction, clamped to the box). A renderer would find its proxy with a
  cheap trace of a coarse scene; the logged hit is that proxy at its best,
  so this order bounds what the heuristic can gain.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from tracer.trace.segments import SegmentRayColumn

from .ray_order_base import OrderedPieces, RayOrder, wavefront_pieces

#: Bits per axis of a 63-bit Morton key.
MORTON_BITS = 21


@njit(cache=True, inline="always")
def _spread(v):
    """The low 21 bits of ``v`` spread to every third bit of a 63-bit integer."""
    v = np.uint64(v) & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


@njit(cache=True, nogil=True)
def _morton_keys(points, lo, hi, bits):
    """Morton keys of ``points`` (S, 3) quantised to ``bits`` (<= 21) bits per axis in the box lo..hi.

    A coordinate maps to ``floor((x - lo) / (hi - lo) * 2**bits)``, clamped to
    ``0 .. 2**bits - 1`` (a flat axis maps to 0); bit ``i`` of axis ``a`` goes
    to bit ``3 i + 2 - a`` of the key (x most significant).
    """
    n = points.shape[0]
    keys = np.zeros(n, dtype=np.uint64)
    top = (1 << bits) - 1
    for i in range(n):
        key = np.uint64(0)
        for axis in range(3):
            extent = hi[axis] - lo[axis]
            cell = 0
            if extent > 0.0:
                scaled = (points[i, axis] - lo[axis]) / extent * (1 << bits)
                cell = min(max(np.int64(np.floor(scaled)), 0), top)
            key |= _spread(cell) << np.uint64(2 - axis)
        keys[i] = key
    return keys


@njit(cache=True, nogil=True)
def _octants(directions):
    """Octant of each direction (S, 3): bit 2 - a set where axis a is negative (x most significant)."""
    n = directions.shape[0]
    out = np.zeros(n, dtype=np.uint64)
    for i in range(n):
        octant = 0
        for axis in range(3):
            if directions[i, axis] < 0.0:
                octant |= 1 << (2 - axis)
        out[i] = np.uint64(octant)
    return out


@njit(cache=True, nogil=True)
def _proxy_hits(rays, lo, hi):
    """Proxy end points (S, 3) of rays (S, 9): the logged hit, else origin + diagonal * direction clamped."""
    n = rays.shape[0]
    out = np.empty((n, 3), dtype=np.float64)
    reach = np.sqrt(((hi - lo) ** 2).sum())
    for i in range(n):
        hit = True
        for axis in range(3):
            if not np.isfinite(rays[i, SegmentRayColumn.HIT + axis]):
                hit = False
        for axis in range(3):
            if hit:
                out[i, axis] = rays[i, SegmentRayColumn.HIT + axis]
            else:
                x = rays[i, SegmentRayColumn.ORIGIN + axis] + reach * rays[i, SegmentRayColumn.DIRECTION + axis]
                out[i, axis] = min(max(x, lo[axis]), hi[axis])
    return out


def morton_keys(points, scene_bounds, bits: int = MORTON_BITS) -> np.ndarray:
    """Morton keys (uint64, (S,)) of ``points`` (float, (S, 3)) in ``scene_bounds`` (2, 3), ``bits`` per axis."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    bounds = np.asarray(scene_bounds, dtype=np.float64)
    return _morton_keys(points, bounds[0].copy(), bounds[1].copy(), int(bits))


def _origins(segments, rows):
    return np.ascontiguousarray(segments.rays[rows, SegmentRayColumn.ORIGIN:SegmentRayColumn.ORIGIN + 3])


@dataclass(frozen=True)
class MortonOrigin(RayOrder):
    """Wavefront whose phases run in Morton order of the rays' origins (21 bits per axis)."""

    name = "morton-origin"

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        keys = morton_keys(_origins(segments, rows), scene_bounds)
        return wavefront_pieces(segments, rows, keys, 3 * MORTON_BITS)


@dataclass(frozen=True)
class OctantOrigin(RayOrder):
    """Wavefront whose phases run by direction octant, then in Morton order of the origins (20 bits per axis)."""

    name = "octant-origin"

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        bits = MORTON_BITS - 1
        column = SegmentRayColumn.DIRECTION
        directions = np.ascontiguousarray(segments.rays[rows, column:column + 3])
        keys = (_octants(directions) << np.uint64(3 * bits)) | morton_keys(_origins(segments, rows), scene_bounds,
                                                                               bits)
        return wavefront_pieces(segments, rows, keys, 3 + 3 * bits)


@dataclass(frozen=True)
class HitPoint(RayOrder):
    """Wavefront whose phases run in Morton order of each ray's proxy hit point (module docstring)."""

    name = "hit-point"

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        lo, hi = scene_bounds[0].copy(), scene_bounds[1].copy()
        proxies = _proxy_hits(np.ascontiguousarray(segments.rays[rows]), lo, hi)
        return wavefront_pieces(segments, rows, morton_keys(proxies, scene_bounds), 3 * MORTON_BITS)
