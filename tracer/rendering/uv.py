"""Texture coordinates of surface points, and how many (u, v) a unit of surface spans.

* Spheres: latitude and longitude about +z (SPD's up), from the unit
  normal ``n``: ``u = 1/2 + atan2(n_y, n_x) / 2 pi``, ``v = 1/2 + asin(n_z) / pi``.
* Triangles, polygons, patches: the affine map of the plane that takes the
  vertices to their (u, v), fitted by least squares. On a triangle that is
  barycentric interpolation; on a polygon whose (u, v) are an affine image
  of its vertices (a rectangle's corners, a planar projection) it is exact.

The *uv density* of an element is the (u, v) area per unit of surface area:
``|det|`` of the plane map's 2 x 2 part, and ``1 / (4 pi r^2)`` on a sphere
(its whole (u, v) square over its area, a mean over latitudes). The level of
detail of a lookup uses it (:mod:`tracer.rendering.render`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.rendering.geometry import newell_normal
from tracer.scenes.model import ElementKind, Scene, vertices_and_uv
from rtcommon.validate import InputError


class UvMaps(NamedTuple):
    """Per-element (u, v) data, as the kernels read it.

    Attributes
    ----------
    plane_map : ndarray of float64, shape (n, 2, 4)
        For planar elements: ``u = plane_map[e, 0, :3] . p + plane_map[e, 0, 3]``
        and likewise ``v`` (row 1); NaN where the element has no (u, v).
    density : ndarray of float64, shape (n,)
        (u, v) area per unit of surface area; NaN without (u, v).
    """

    plane_map: np.ndarray
    density: np.ndarray


def uv_maps(scene: Scene, elements=None) -> UvMaps:
    """The :class:`UvMaps` of ``scene``, worked out for ``elements`` (ids;
    default all) and NaN elsewhere.

    Raises
    ------
    ValueError
        An element in ``elements`` without (u, v) (a triangle, polygon or
        patch whose file gave none), or a cone (not texturable).
    """
    n = scene.n_elements
    plane_map = np.full((n, 2, 4), np.nan)
    density = np.full(n, np.nan)
    chosen = np.arange(n) if elements is None else np.asarray(elements, dtype=np.int64)
    kinds = scene.element_kind.astype(np.int64)
    for e in chosen:
        kind, index = ElementKind(int(kinds[e])), int(scene.element_index[e])
        if kind == ElementKind.SPHERE:
            density[e] = 1.0 / (4.0 * math.pi * float(scene.sphere_radius[index]) ** 2)
            continue
        if kind == ElementKind.CONE:
            raise InputError(f"element {e} is a cone: textures on cones are not supported")
        vertices, uv = vertices_and_uv(scene, kind, index)
        if not np.isfinite(uv).all():
            raise InputError(f"element {e} ({kind.name.lower()} {index}) has a textured material "
                             "but no (u, v) at its vertices")
        plane_map[e], density[e] = _plane_map(vertices, uv)
    return UvMaps(plane_map, density)


def _plane_map(vertices: np.ndarray, uv: np.ndarray):
    """The affine (u, v) map of a planar element's plane, (2, 4), and its density."""
    origin = vertices[0]
    edges = vertices - origin
    normal = newell_normal(vertices)
    first = edges[np.argmax(np.linalg.norm(edges, axis=1))]
    e1 = first / np.linalg.norm(first)
    e2 = np.cross(normal, e1)
    local = np.column_stack([edges @ e1, edges @ e2, np.ones(len(vertices))])
    solution, *_ = np.linalg.lstsq(local, uv, rcond=None)  # (3, 2): rows d/de1, d/de2, constant
    gradients = np.outer(solution[0], e1) + np.outer(solution[1], e2)  # (2, 3): rows grad u, grad v
    out = np.empty((2, 4))
    out[:, :3] = gradients
    out[:, 3] = solution[2] - gradients @ origin
    return out, abs(float(np.linalg.det(solution[:2])))


@njit(cache=True, inline="always")
def surface_uv(kind, element, index, geo, maps, hx, hy, hz):
    """(u, v) at hit point ``h`` of ``element`` (of ``kind``, row ``index``).

    Parameters
    ----------
    kind : int
        The element's :class:`~tracer.scenes.model.ElementKind`.
    element, index : int
        Element id and its row in that kind's arrays.
    geo : tracer.rendering.geometry.Geometry
    maps : UvMaps
    hx, hy, hz : float
    """
    if kind == ElementKind.SPHERE:
        c = geo.sphere_center
        r = geo.sphere_radius[index]
        nx = (hx - c[index, 0]) / r
        ny = (hy - c[index, 1]) / r
        nz = min(max((hz - c[index, 2]) / r, -1.0), 1.0)
        return 0.5 + math.atan2(ny, nx) / (2.0 * math.pi), 0.5 + math.asin(nz) / math.pi
    m = maps.plane_map[element]
    return (m[0, 0] * hx + m[0, 1] * hy + m[0, 2] * hz + m[0, 3],
            m[1, 0] * hx + m[1, 1] * hy + m[1, 2] * hz + m[1, 3])
