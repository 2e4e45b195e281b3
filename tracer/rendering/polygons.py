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
from rtcommon.validate import InputError

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

    The test pairs every edge with every vertex (time O(n^2) for an n-gon,
    stopping at the first vertex outside) but keeps no table of the pairs:
    memory is O(1) beyond the inputs, so a 10,000-vertex polygon costs no
    more memory than a square.

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
    offsets = np.ascontiguousarray(offsets, dtype=np.int64)
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    normals = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    if offsets.ndim != 1 or offsets.size != normals.shape[0] + 1:
        raise InputError(f"polygon offsets must have one entry per normal plus one, got {offsets.size} "
                         f"offsets for {normals.shape[0]} normals")
    if offsets.size and (offsets[0] < 0 or offsets[-1] > vertices.shape[0] or np.any(np.diff(offsets) < 0)):
        raise InputError(f"polygon offsets must rise within the {vertices.shape[0]} vertices")
    axes = np.full(normals.shape[0], CONVEX, dtype=np.int64)
    _even_odd_axes(offsets, vertices, normals, CONVEXITY_TOLERANCE, axes)
    return axes


@njit(cache=True, error_model="numpy")
def _even_odd_axes(offsets, vertices, normals, tolerance, axes):
    # Polygons of more than 3 vertices: each edge against each vertex, the
    # side of the vertex as (edge x (vertex - edge start)) . normal, in the
    # order of that product's components; the first vertex further outside
    # than tolerance * extent^2 makes the polygon concave.
    for i in range(normals.shape[0]):
        a = offsets[i]
        b = offsets[i + 1]
        if b - a <= 3:
            continue
        extent = 0.0
        for k in range(3):
            low = vertices[a, k]
            high = vertices[a, k]
            for j in range(a + 1, b):
                low = min(low, vertices[j, k])
                high = max(high, vertices[j, k])
            extent = max(extent, high - low)
        limit = tolerance * (extent * extent)
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        concave = False
        for e in range(a, b):
            following = e + 1 if e + 1 < b else a
            ex = vertices[following, 0] - vertices[e, 0]
            ey = vertices[following, 1] - vertices[e, 1]
            ez = vertices[following, 2] - vertices[e, 2]
            for v in range(a, b):
                rx = vertices[v, 0] - vertices[e, 0]
                ry = vertices[v, 1] - vertices[e, 1]
                rz = vertices[v, 2] - vertices[e, 2]
                side = (ey * rz - ez * ry) * nx + (ez * rx - ex * rz) * ny + (ex * ry - ey * rx) * nz
                if side < -limit:
                    concave = True
                    break
            if concave:
                break
        if concave:
            drop = 0
            for k in (1, 2):
                if abs(normals[i, k]) > abs(normals[i, drop]):
                    drop = k
            axes[i] = drop


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
