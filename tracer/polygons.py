"""Planar polygons: which are convex, and the ray tests of both kinds.

NFF allows concave polygons (SPD gears has 128 concave 144-gons). A convex
polygon keeps the fast edge test (:func:`hit_convex`: the hit point must lie
inside every edge's half-plane), which for a concave one accepts only its
convex core. :func:`polygon_even_odd_axes` finds, once per scene, which
polygons are not convex; :func:`hit_polygon` tests those by the even-odd
rule, so convex scenes render exactly as before and records stay one per
polygon (nothing is triangulated).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from rtcommon.jit import NO_REFCOUNTS

INF = np.inf
#: ``Geometry.polygon_even_odd_axis`` of a convex polygon: its edges' half-planes decide a hit.
CONVEX = -1
#: A polygon is convex when no vertex lies further than this share of its extent squared (a
#: cross product) to the outside of any edge line; float noise in convex files stays below it.
CONVEXITY_TOLERANCE = 1e-9

def polygon_even_odd_axes(offsets: np.ndarray, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Per polygon: :data:`CONVEX`, or for a concave (or self-intersecting) one the axis to drop.

    A polygon is convex when every vertex lies inside (or within
    :data:`CONVEXITY_TOLERANCE` of) the half-plane of every edge, which is
    exactly when the edge test of :func:`hit_convex` accepts the whole
    polygon. Others are tested by the even-odd rule in the plane of the two
    axes left after dropping the normal's largest component.

    Parameters
    ----------
    offsets : ndarray of int64, shape (P + 1,)
    vertices : ndarray, shape (V, 3)
    normals : ndarray, shape (P, 3)
        Unit Newell normals.

    Returns
    -------
    ndarray of int64, shape (P,)
    """
    counts = np.diff(offsets)
    axes = np.full(counts.size, CONVEX, dtype=np.int64)
    for count in np.unique(counts[counts > 3]):
        which = np.flatnonzero(counts == count)
        for chunk in np.array_split(which, max(1, which.size * int(count) ** 2 // 4_000_000)):
            corners = vertices[offsets[chunk][:, None] + np.arange(count)]           # (m, c, 3)
            edges = np.roll(corners, -1, axis=1) - corners                           # (m, c, 3)
            relative = corners[:, None, :, :] - corners[:, :, None, :]              # (m, edge, vertex, 3)
            side = np.einsum("mevk,mk->mev", np.cross(edges[:, :, None, :], relative), normals[chunk])
            extent = np.max(np.ptp(corners, axis=1), axis=1)
            concave = np.any(side < -CONVEXITY_TOLERANCE * extent[:, None, None] ** 2, axis=(1, 2))
            axes[chunk[concave]] = np.argmax(np.abs(normals[chunk[concave]]), axis=1)
    return axes


@njit(cache=True, error_model="numpy", inline="always")
def _plane_distance(offsets, vertices, normal, i, ray, tmin, tmax):
    """``t`` where ``ray`` meets polygon ``i``'s plane, or ``INF`` if parallel or outside ``(tmin, tmax)``."""
    ox, oy, oz, dx, dy, dz = ray
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    denom = nx * dx + ny * dy + nz * dz
    if denom == 0.0:
        return INF
    a = offsets[i]
    t = (nx * (vertices[a, 0] - ox) + ny * (vertices[a, 1] - oy) + nz * (vertices[a, 2] - oz)) / denom
    if not (t > tmin and t < tmax):
        return INF
    return t


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def hit_convex(offsets, vertices, normal, i, ray, tmin, tmax):
    """Test ``ray`` and convex planar polygon ``i`` (CSR ``offsets``/``vertices``, plane ``normal`` (P, 3))."""
    t = _plane_distance(offsets, vertices, normal, i, ray, tmin, tmax)
    if t == INF:
        return INF
    ox, oy, oz, dx, dy, dz = ray
    nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
    a = offsets[i]
    b = offsets[i + 1]
    hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
    for k in range(a, b):
        k1 = k + 1 if k + 1 < b else a
        ex = vertices[k1, 0] - vertices[k, 0]
        ey = vertices[k1, 1] - vertices[k, 1]
        ez = vertices[k1, 2] - vertices[k, 2]
        wx = hx - vertices[k, 0]
        wy = hy - vertices[k, 1]
        wz = hz - vertices[k, 2]
        # (e x w) . n must not be negative for a point inside (CCW about n)
        s = (ey * wz - ez * wy) * nx + (ez * wx - ex * wz) * ny + (ex * wy - ey * wx) * nz
        if s < 0.0:
            return INF
    return t


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def hit_polygon(offsets, vertices, normal, even_odd_axis, i, ray, tmin, tmax):
    """Test ``ray`` and planar polygon ``i``, convex or not (see :func:`polygon_even_odd_axes`).

    Convex polygons take :func:`hit_convex` unchanged; a concave one counts
    how many edges a half-line from the hit point crosses, in the plane of
    the two axes its normal does not dominate (even: outside).
    """
    drop = even_odd_axis[i]
    if drop == CONVEX:
        return hit_convex(offsets, vertices, normal, i, ray, tmin, tmax)
    t = _plane_distance(offsets, vertices, normal, i, ray, tmin, tmax)
    if t == INF:
        return INF
    ox, oy, oz, dx, dy, dz = ray
    a = offsets[i]
    b = offsets[i + 1]
    hit = (ox + t * dx, oy + t * dy, oz + t * dz)
    u_axis = 1 if drop == 0 else 0
    v_axis = 1 if drop == 2 else 2
    pu = hit[u_axis]
    pv = hit[v_axis]
    inside = False
    previous = b - 1
    for k in range(a, b):
        ku, kv = vertices[k, u_axis], vertices[k, v_axis]
        ju, jv = vertices[previous, u_axis], vertices[previous, v_axis]
        if (kv > pv) != (jv > pv):
            if pu < ku + (pv - kv) * (ju - ku) / (jv - kv):
                inside = not inside
        previous = k
    return t if inside else INF
