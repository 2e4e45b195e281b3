"""Ray/primitive intersection and the flat geometry arrays the kernels read.

:func:`prepare_geometry` turns a :class:`~tracer.scenes.model.Scene` into a
:class:`Geometry` bundle of arrays with per-primitive quantities precomputed
once (triangle edges, polygon plane normals, cone frames). The compiled
functions here take that bundle, a :class:`Ray` and scalars only, so the
kd-tree traversal, the renderer
and the brute-force reference in the tests share one intersection routine
per primitive kind.

Conventions
-----------
* Ray directions are unit vectors; ``t`` is a distance along the ray.
* A test returns the nearest ``t`` with ``tmin < t < tmax`` or ``inf``.
* Intersection is two-sided; normals are *one-sided*: the normal a primitive
  defines (polygon winding, sphere outward, cone outward, flipped for a
  negative cone radius) is returned as is, even when the ray hits the back.
  Shading decides what a back-facing normal means (SPD rules).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.jit import NO_REFCOUNTS
from tracer.rendering.polygons import CONVEX, hit_convex, hit_polygon, polygon_even_odd_axes  # noqa: F401 (re-exported)
from tracer.scenes.model import ElementKind, Scene
from rtcommon.validate import InputError

INF = np.inf
class Geometry(NamedTuple):
    """The element table and per-primitive arrays the kernels read (see :func:`prepare_geometry`).

    C-contiguous; float64 but where noted; n elements, S spheres, T
    triangles, P polygons of V vertices, Q patches of W vertices, C cones.
    """

    element_kind: np.ndarray      #: (n,) uint8 ElementKind values
    element_index: np.ndarray     #: (n,) int64 row in that kind's arrays
    sphere_center: np.ndarray     #: (S, 3)
    sphere_radius: np.ndarray     #: (S,) ``|r|``
    triangle_v0e1e2: np.ndarray   #: (T, 3, 3): v0, v1 - v0, v2 - v0
    triangle_normal: np.ndarray   #: (T, 3) unit, (v1 - v0) x (v2 - v0)
    polygon_offsets: np.ndarray   #: (P + 1,) int64
    polygon_vertices: np.ndarray  #: (V, 3)
    polygon_normal: np.ndarray    #: (P, 3) unit Newell normal (counter-clockwise front)
    polygon_even_odd_axis: np.ndarray  #: (P,) int64 :data:`CONVEX`, or the axis a concave one drops
    patch_offsets: np.ndarray     #: (Q + 1,) int64
    patch_vertices: np.ndarray    #: (W, 3)
    patch_vnormals: np.ndarray    #: (W, 3) unit vertex normals
    patch_normal: np.ndarray      #: (Q, 3) unit Newell plane normal
    patch_even_odd_axis: np.ndarray  #: (Q,) int64 :data:`CONVEX`, or the axis a concave one drops
    cone_base: np.ndarray         #: (C, 3)
    cone_axis: np.ndarray         #: (C, 3) unit, base -> apex
    cone_height: np.ndarray       #: (C,)
    cone_r0: np.ndarray           #: (C,) ``|base radius|``
    cone_r1: np.ndarray           #: (C,) ``|apex radius|``
    cone_sign: np.ndarray         #: (C,) +1 (outside visible) or -1 (inside visible)


class Ray(NamedTuple):
    """A ray as the kernels take it: origin and unit direction (floats).

    ``t`` along it is a distance; the interval ``(tmin, tmax)`` searched
    travels separately because the traversal narrows it as it finds hits.
    """

    ox: float
    oy: float
    oz: float
    dx: float
    dy: float
    dz: float


#: Largest coordinate (and radius) magnitude the tracer accepts: its
#: routines multiply up to two coordinates (dot and cross products, squared
#: distances) and a few more factors of order one, which must stay finite.
COORDINATE_LIMIT = 1e100


#: The scene arrays of coordinates and sizes (:func:`check_coordinates`).
COORDINATE_FIELDS = ("sphere_center", "sphere_radius", "triangle_vertices", "polygon_vertices", "patch_vertices",
                     "cone_base", "cone_apex", "cone_base_radius", "cone_apex_radius")


def check_coordinates(scene: Scene) -> None:
    """Refuse non-finite or too large coordinates and sizes, naming the field and row, before any
    arithmetic overflows on them (the tree builder and :func:`prepare_geometry` both call it)."""
    for what in COORDINATE_FIELDS:
        values = np.asarray(getattr(scene, what), dtype=np.float64)
        if values.size == 0:
            continue
        rows = values.reshape(len(values), -1)
        bad = ~np.isfinite(rows) | (np.abs(rows) > COORDINATE_LIMIT)
        if bad.any():
            row, column = (int(i) for i in np.argwhere(bad)[0])
            raise InputError(f"Scene.{what}: row {row} holds {float(rows[row, column]):g}; coordinates and sizes "
                             f"must be finite and within +-{COORDINATE_LIMIT:.0e} (the tracer multiplies them)")


def _unit_rows(v: np.ndarray, what: str) -> np.ndarray:
    norm = np.linalg.norm(v, axis=1)
    if np.any(norm == 0.0) or not np.all(np.isfinite(norm)):
        bad = int(np.flatnonzero((norm == 0.0) | ~np.isfinite(norm))[0])
        raise InputError(f"Scene.{what}: degenerate entry at row {bad} (zero or non-finite normal)")
    return v / norm[:, None]


def _newell(offsets: np.ndarray, vertices: np.ndarray, what: str) -> np.ndarray:
    n = len(offsets) - 1
    normals = np.zeros((n, 3))
    if n == 0:
        return normals
    counts = np.diff(offsets)
    if np.any(counts < 3):
        raise InputError(f"Scene.{what}: every polygon needs at least 3 vertices")
    idx = np.arange(len(vertices))
    owner = np.repeat(np.arange(n), counts)
    nxt = idx + 1
    last = offsets[1:] - 1
    nxt[last] = offsets[:-1]
    a, b = vertices, vertices[nxt]
    terms = np.stack([(a[:, 1] - b[:, 1]) * (a[:, 2] + b[:, 2]),
                      (a[:, 2] - b[:, 2]) * (a[:, 0] + b[:, 0]),
                      (a[:, 0] - b[:, 0]) * (a[:, 1] + b[:, 1])], axis=1)
    np.add.at(normals, owner, terms)
    return _unit_rows(normals, what)


def newell_normal(vertices) -> np.ndarray:
    """Unit Newell normal, shape (3,), of one planar polygon's ``vertices`` (n, 3), n >= 3
    (counter-clockwise front, as the kernels use it)."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    return _newell(np.array([0, len(vertices)]), vertices, "polygon")[0]


def prepare_geometry(scene: Scene) -> Geometry:
    """Check the element table and precompute the per-primitive arrays the kernels read.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    Geometry

    Raises
    ------
    ValueError
        If the element table is inconsistent, a coordinate or size is not
        finite or beyond :data:`COORDINATE_LIMIT`, or a triangle, polygon or
        cone is degenerate (naming the field and row).
    """
    n = scene.n_elements
    if scene.element_index.shape != (n,):
        raise InputError(f"Scene.element_index must have shape ({n},)")
    ekind = np.ascontiguousarray(scene.element_kind, dtype=np.uint8)
    eidx = np.ascontiguousarray(scene.element_index, dtype=np.int64)
    if n and ekind.max() > max(ElementKind):
        raise InputError(f"Scene.element_kind holds a value outside ElementKind (0..{int(max(ElementKind))})")
    f = lambda a, shape: np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(shape))
    sc = f(scene.sphere_center, (-1, 3))
    sr = np.abs(f(scene.sphere_radius, (-1,)))
    tv = f(scene.triangle_vertices, (-1, 3, 3))
    check_coordinates(scene)
    tri = np.empty_like(tv)
    tri[:, 0] = tv[:, 0]
    tri[:, 1] = tv[:, 1] - tv[:, 0]
    tri[:, 2] = tv[:, 2] - tv[:, 0]
    tn = np.cross(tri[:, 1], tri[:, 2]) if len(tv) else np.zeros((0, 3))
    tn = _unit_rows(tn, "triangle_vertices") if len(tv) else tn
    po = np.ascontiguousarray(scene.polygon_offsets, dtype=np.int64)
    pv = f(scene.polygon_vertices, (-1, 3))
    pn = _newell(po, pv, "polygon_vertices")
    p_axes = polygon_even_odd_axes(po, pv, pn)
    qo = np.ascontiguousarray(scene.patch_offsets, dtype=np.int64)
    qv = f(scene.patch_vertices, (-1, 3))
    qvn = f(scene.patch_normals, (-1, 3))
    qvn = _unit_rows(qvn, "patch_normals") if len(qvn) else qvn
    qn = _newell(qo, qv, "patch_vertices")
    q_axes = polygon_even_odd_axes(qo, qv, qn)
    cb = f(scene.cone_base, (-1, 3))
    ca = f(scene.cone_apex, (-1, 3))
    axis = ca - cb
    height = np.linalg.norm(axis, axis=1) if len(cb) else np.zeros(0)
    if np.any(height == 0.0):
        raise InputError("Scene.cone_apex: a cone has apex == base (zero height)")
    axis = axis / height[:, None] if len(cb) else axis
    r0 = f(scene.cone_base_radius, (-1,))
    r1 = f(scene.cone_apex_radius, (-1,))
    sign = np.where((r0 < 0) | ((r0 == 0) & (r1 < 0)), -1.0, 1.0)
    return Geometry(ekind, eidx, sc, sr, tri, tn, po, pv, pn, p_axes, qo, qv, qvn, qn, q_axes,
                    np.ascontiguousarray(cb), np.ascontiguousarray(axis), np.ascontiguousarray(height),
                    np.abs(r0), np.abs(r1), sign)


def element_bounds(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of every element, in element-id order.

    Returns
    -------
    lo, hi : ndarray, shape (N, 3) float64
    """
    n = scene.n_elements
    lo = np.zeros((n, 3))
    hi = np.zeros((n, 3))
    kind = np.asarray(scene.element_kind, dtype=np.int64)
    index = np.asarray(scene.element_index, dtype=np.int64)
    for k in ElementKind:
        sel = np.flatnonzero(kind == k)
        if len(sel) == 0:
            continue
        rows = index[sel]
        if k == ElementKind.SPHERE:
            c = scene.sphere_center[rows]
            r = np.abs(scene.sphere_radius[rows])[:, None]
            lo[sel], hi[sel] = c - r, c + r
        elif k == ElementKind.TRIANGLE:
            v = scene.triangle_vertices[rows]
            lo[sel], hi[sel] = v.min(axis=1), v.max(axis=1)
        elif k in (ElementKind.POLYGON, ElementKind.PATCH):
            off = scene.polygon_offsets if k == ElementKind.POLYGON else scene.patch_offsets
            vert = scene.polygon_vertices if k == ElementKind.POLYGON else scene.patch_vertices
            plo = np.minimum.reduceat(vert, off[:-1], axis=0)
            phi = np.maximum.reduceat(vert, off[:-1], axis=0)
            lo[sel], hi[sel] = plo[rows], phi[rows]
        else:
            # A cone is the hull of its two end discs; a disc of radius r
            # with unit normal a spans r * sqrt(1 - a_i^2) along axis i.
            b, a = scene.cone_base[rows], scene.cone_apex[rows]
            ax = a - b
            ax = ax / np.linalg.norm(ax, axis=1)[:, None]
            ext = np.sqrt(np.clip(1.0 - ax * ax, 0.0, 1.0))
            e0 = np.abs(scene.cone_base_radius[rows])[:, None] * ext
            e1 = np.abs(scene.cone_apex_radius[rows])[:, None] * ext
            lo[sel] = np.minimum(b - e0, a - e1)
            hi[sel] = np.maximum(b + e0, a + e1)
    return lo, hi


def element_clip_shapes(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shapes used to clip elements to kd-tree nodes.

    Returns
    -------
    offsets : ndarray, shape (N + 1,) int64
        CSR offsets into ``vertices``; planar elements (triangles, polygons,
        patches) have their vertices, other kinds none.
    vertices : ndarray, shape (V, 3) float64
    spheres : ndarray, shape (N, 4) float64
        Centre and radius for sphere elements, radius -1 for other kinds.
    """
    n = scene.n_elements
    kind = np.asarray(scene.element_kind, dtype=np.int64)
    index = np.asarray(scene.element_index, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    counts[kind == ElementKind.TRIANGLE] = 3
    for k, off in ((ElementKind.POLYGON, scene.polygon_offsets), (ElementKind.PATCH, scene.patch_offsets)):
        sel = kind == k
        counts[sel] = np.diff(off)[index[sel]]
    offsets = np.zeros(n + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(counts)
    vertices = np.zeros((offsets[-1], 3))
    tri = np.flatnonzero(kind == ElementKind.TRIANGLE)
    vertices[offsets[tri][:, None] + np.arange(3)] = np.asarray(scene.triangle_vertices).reshape(-1, 3, 3)[index[tri]]
    for k, source, source_offsets in ((ElementKind.POLYGON, scene.polygon_vertices, scene.polygon_offsets),
                                      (ElementKind.PATCH, scene.patch_vertices, scene.patch_offsets)):
        elements = np.flatnonzero(kind == k)
        c = counts[elements]
        within = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)  # vertex number in its element
        vertices[np.repeat(offsets[elements], c) + within] = \
            np.asarray(source).reshape(-1, 3)[np.repeat(np.asarray(source_offsets)[index[elements]], c) + within]
    spheres = np.full((n, 4), -1.0)
    sel = kind == ElementKind.SPHERE
    spheres[sel, :3] = scene.sphere_center[index[sel]]
    spheres[sel, 3] = np.abs(scene.sphere_radius[index[sel]])
    return offsets, vertices, spheres


# --------------------------------------------------------------------------
# compiled intersection routines
# --------------------------------------------------------------------------

@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def hit_sphere(center, radius, i, ray, tmin, tmax):
    """Nearest ``t`` in ``(tmin, tmax)`` of ``ray`` and sphere ``i`` (``center`` (S, 3), ``radius`` (S,)).

    Returns ``(t, roots)``: ``t`` or ``inf``, and 1 if the test took a square
    root (the discriminant was not negative), else 0. Which path a test
    takes matters to its cost on a machine without a square-root
    instruction (``coherence.cost.SQUARE_ROOT_CYCLES_21164``).
    """
    cx, cy, cz, r = center[i, 0], center[i, 1], center[i, 2], radius[i]
    ox, oy, oz, dx, dy, dz = ray
    px, py, pz = ox - cx, oy - cy, oz - cz
    b = px * dx + py * dy + pz * dz
    c = px * px + py * py + pz * pz - r * r
    disc = b * b - c
    if disc < 0.0:
        return INF, 0
    s = math.sqrt(disc)
    t = -b - s
    if t > tmin and t < tmax:
        return t, 1
    t = -b + s
    if t > tmin and t < tmax:
        return t, 1
    return INF, 1


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def hit_triangle(tri, i, ray, tmin, tmax):
    """Moller-Trumbore test of ``ray`` and triangle ``i`` of ``tri`` (T, 3, 3) = v0, e1, e2."""
    ox, oy, oz, dx, dy, dz = ray
    e1x, e1y, e1z = tri[i, 1, 0], tri[i, 1, 1], tri[i, 1, 2]
    e2x, e2y, e2z = tri[i, 2, 0], tri[i, 2, 1], tri[i, 2, 2]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:
        return INF
    inv = 1.0 / det
    sx, sy, sz = ox - tri[i, 0, 0], oy - tri[i, 0, 1], oz - tri[i, 0, 2]
    u = (sx * px + sy * py + sz * pz) * inv
    if u < 0.0 or u > 1.0:
        return INF
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return INF
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t > tmin and t < tmax:
        return t
    return INF


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def hit_cone(geo, i, ray, tmin, tmax):
    """Test ``ray`` and the lateral surface of truncated cone ``i`` of ``geo`` (no caps).

    Returns ``(t, roots)`` as :func:`hit_sphere` does.
    """
    base, axis, height, r0s, r1s = geo.cone_base, geo.cone_axis, geo.cone_height, geo.cone_r0, geo.cone_r1
    ox, oy, oz, dx, dy, dz = ray
    ax, ay, az = axis[i, 0], axis[i, 1], axis[i, 2]
    h = height[i]
    r0 = r0s[i]
    k = (r1s[i] - r0) / h
    qx, qy, qz = ox - base[i, 0], oy - base[i, 1], oz - base[i, 2]
    zo = qx * ax + qy * ay + qz * az
    zd = dx * ax + dy * ay + dz * az
    wox, woy, woz = qx - zo * ax, qy - zo * ay, qz - zo * az
    wdx, wdy, wdz = dx - zd * ax, dy - zd * ay, dz - zd * az
    rr = r0 + k * zo
    a = wdx * wdx + wdy * wdy + wdz * wdz - k * k * zd * zd
    b = 2.0 * (wox * wdx + woy * wdy + woz * wdz - rr * k * zd)
    c = wox * wox + woy * woy + woz * woz - rr * rr
    t0 = INF
    t1 = INF
    roots = 0
    if abs(a) < 1e-300:
        if b == 0.0:
            return INF, 0
        t0 = -c / b
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return INF, 0
        roots = 1
        s = math.sqrt(disc)
        # numerically stable roots
        qq = -0.5 * (b + s) if b >= 0.0 else -0.5 * (b - s)
        ra = qq / a
        rb = c / qq if qq != 0.0 else INF
        t0 = min(ra, rb)
        t1 = max(ra, rb)
    for j in range(2):
        t = t0 if j == 0 else t1
        if t > tmin and t < tmax:
            z = zo + t * zd
            if z >= 0.0 and z <= h and r0 + k * z >= 0.0:
                return t, roots
    return INF, roots


@njit(cache=True, error_model="numpy", inline="always")
def hit_element(kind, idx, geo, ray, tmin, tmax):
    """Nearest ``t`` of ``ray`` and element (``kind``, ``idx``) in ``(tmin, tmax)`` or ``inf``, and its roots.

    Returns ``(t, roots)``: ``roots`` is 1 when the test took a square root
    (a sphere or cone whose quadratic has real roots), else 0.

    Inlined into the traversal (numba IR): called once per test, it would
    otherwise take the ``Geometry`` bundle apart, with reference counting,
    on every call.

    ``kind`` is an :class:`~tracer.scenes.model.ElementKind` value, ``idx`` the row
    in that kind's arrays of ``geo`` (:class:`Geometry`).
    """
    if kind == ElementKind.SPHERE:
        return hit_sphere(geo.sphere_center, geo.sphere_radius, idx, ray, tmin, tmax)
    if kind == ElementKind.TRIANGLE:
        return hit_triangle(geo.triangle_v0e1e2, idx, ray, tmin, tmax), 0
    if kind == ElementKind.POLYGON:
        return hit_polygon(geo.polygon_offsets, geo.polygon_vertices, geo.polygon_normal, geo.polygon_even_odd_axis,
                           idx, ray, tmin, tmax), 0
    if kind == ElementKind.PATCH:
        return hit_polygon(geo.patch_offsets, geo.patch_vertices, geo.patch_normal, geo.patch_even_odd_axis,
                           idx, ray, tmin, tmax), 0
    return hit_cone(geo, idx, ray, tmin, tmax)


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def _patch_normal(offsets, vertices, vnormals, plane, i, hx, hy, hz):
    # Fan-triangulate from vertex 0 and interpolate the normals of the fan
    # triangle holding the point (barycentric in the plane).
    a = offsets[i]
    b = offsets[i + 1]
    nx, ny, nz = plane[i, 0], plane[i, 1], plane[i, 2]
    best = 0.0
    bx, by, bz = nx, ny, nz
    first = True
    for k in range(a + 1, b - 1):
        v0x, v0y, v0z = vertices[a, 0], vertices[a, 1], vertices[a, 2]
        e1x, e1y, e1z = vertices[k, 0] - v0x, vertices[k, 1] - v0y, vertices[k, 2] - v0z
        e2x, e2y, e2z = vertices[k + 1, 0] - v0x, vertices[k + 1, 1] - v0y, vertices[k + 1, 2] - v0z
        wx, wy, wz = hx - v0x, hy - v0y, hz - v0z
        cx = e1y * e2z - e1z * e2y
        cy = e1z * e2x - e1x * e2z
        cz = e1x * e2y - e1y * e2x
        area = cx * nx + cy * ny + cz * nz
        if area == 0.0:
            continue
        # barycentric (u on e1, v on e2)
        u = ((wy * e2z - wz * e2y) * nx + (wz * e2x - wx * e2z) * ny + (wx * e2y - wy * e2x) * nz) / area
        v = ((e1y * wz - e1z * wy) * nx + (e1z * wx - e1x * wz) * ny + (e1x * wy - e1y * wx) * nz) / area
        w = 1.0 - u - v
        inside = min(u, min(v, w))
        if first or inside > best:
            first = False
            best = inside
            bx = w * vnormals[a, 0] + u * vnormals[k, 0] + v * vnormals[k + 1, 0]
            by = w * vnormals[a, 1] + u * vnormals[k, 1] + v * vnormals[k + 1, 1]
            bz = w * vnormals[a, 2] + u * vnormals[k, 2] + v * vnormals[k + 1, 2]
            if inside >= 0.0:
                break
    ln = math.sqrt(bx * bx + by * by + bz * bz)
    if ln == 0.0:
        return nx, ny, nz
    return bx / ln, by / ln, bz / ln


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def element_normal(kind, idx, geo, hx, hy, hz):
    """Unit shading normal (one-sided, see module notes) at hit point ``h``."""
    if kind == ElementKind.SPHERE:
        c = geo.sphere_center
        r = geo.sphere_radius[idx]
        return (hx - c[idx, 0]) / r, (hy - c[idx, 1]) / r, (hz - c[idx, 2]) / r
    if kind == ElementKind.TRIANGLE:
        n = geo.triangle_normal
        return n[idx, 0], n[idx, 1], n[idx, 2]
    if kind == ElementKind.POLYGON:
        n = geo.polygon_normal
        return n[idx, 0], n[idx, 1], n[idx, 2]
    if kind == ElementKind.PATCH:
        return _patch_normal(geo.patch_offsets, geo.patch_vertices, geo.patch_vnormals, geo.patch_normal,
                             idx, hx, hy, hz)
    base = geo.cone_base
    axis = geo.cone_axis
    h = geo.cone_height[idx]
    k = (geo.cone_r1[idx] - geo.cone_r0[idx]) / h
    ax, ay, az = axis[idx, 0], axis[idx, 1], axis[idx, 2]
    qx, qy, qz = hx - base[idx, 0], hy - base[idx, 1], hz - base[idx, 2]
    z = qx * ax + qy * ay + qz * az
    wx, wy, wz = qx - z * ax, qy - z * ay, qz - z * az
    lw = math.sqrt(wx * wx + wy * wy + wz * wz)
    if lw == 0.0:
        return ax, ay, az
    # gradient of |w| - (r0 + k z): w/|w| - k a
    nx, ny, nz = wx / lw - k * ax, wy / lw - k * ay, wz / lw - k * az
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    s = geo.cone_sign[idx] / ln
    return nx * s, ny * s, nz * s
