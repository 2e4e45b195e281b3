"""Closest-hit queries for arbitrary rays: through the kd-tree, or by brute force.

The brute-force version tests every element and is the slow reference the
tests compare the tree against; both use the renderer's intersection code.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from rtcommon.jit import NO_REFCOUNTS
from tracer.rendering.geometry import Ray, prepare_geometry
from tracer.kd.tree import KdTree
from tracer.scenes.model import Scene
from tracer.trace.records import N_COUNTERS, Counter
from tracer.kd.traverse import RecordLog, brute_force, new_stack, traverse, tree_arrays
from rtcommon.validate import InputError


class RayBatch(NamedTuple):
    """Rays of a closest-hit query: unit directions and search intervals."""

    origins: np.ndarray     #: (R, 3) float64
    directions: np.ndarray  #: (R, 3) float64 unit vectors
    tmin: np.ndarray        #: (R,) float64
    tmax: np.ndarray        #: (R,) float64


class HitArrays(NamedTuple):
    """Per-ray outputs of the closest-hit kernels."""

    t: np.ndarray            #: (R,) float64, ``inf`` on a miss
    element: np.ndarray      #: (R,) int64, -1 on a miss
    node_visits: np.ndarray  #: (R,) int64 (kd-tree query only)


@njit(cache=True, error_model="numpy", inline="always")
def _batch_ray(rays, r):
    o, d = rays.origins, rays.directions
    return Ray(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2])


#: rays per parallel work item of the closest-hit kernel (its counters and stack are allocated once per item)
RAY_CHUNK = 256


@njit(cache=True, error_model="numpy")
def _closest_chunk(rays, first, stop, tree, geo, out):
    # rays first..stop-1 with one counter array and one stack between them
    _closest_rays(rays, first, stop, tree, geo, out, RecordLog(np.empty(0, np.uint32), 0),
                  np.zeros(N_COUNTERS, np.int64), new_stack())


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def _closest_rays(rays, first, stop, tree, geo, out, no_log, cnt, stack):
    # the loop over the rays, the traversal inlined, without reference counting (rtcommon.jit.NO_REFCOUNTS)
    out_t = out.t
    out_element = out.element
    out_nodes = out.node_visits
    for r in range(first, stop):
        before = cnt[Counter.NODE_VISITS]
        t, e, _ = traverse(tree, geo, _batch_ray(rays, r), rays.tmin[r], rays.tmax[r], False,
                           no_log, 0, cnt, stack)
        out_t[r] = t
        out_element[r] = e
        out_nodes[r] = cnt[Counter.NODE_VISITS] - before


@njit(parallel=True, cache=True, error_model="numpy")
def _closest_kernel(rays, tree, geo, out):
    n = rays.origins.shape[0]
    for k in prange((n + RAY_CHUNK - 1) // RAY_CHUNK):
        _closest_chunk(rays, k * RAY_CHUNK, min(n, (k + 1) * RAY_CHUNK), tree, geo, out)


@njit(parallel=True, cache=True, error_model="numpy")
def _brute_kernel(rays, geo, out):
    out_t = out.t
    out_element = out.element
    for r in prange(rays.origins.shape[0]):
        t, e = brute_force(geo, _batch_ray(rays, r), rays.tmin[r], rays.tmax[r])
        out_t[r] = t
        out_element[r] = e


def _ray_batch(origins, directions, tmin, tmax) -> RayBatch:
    o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise InputError(f"origins and directions must both be (R, 3), got {o.shape} and {d.shape}")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0.0):
        raise InputError("directions must be non-zero")
    r = len(o)
    return RayBatch(o, np.ascontiguousarray(d / norm[:, None]), _bounds(tmin, r), _bounds(tmax, r))


def _bounds(value, n):
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,))
    return np.ascontiguousarray(a)


def _hit_arrays(n) -> HitArrays:
    return HitArrays(np.empty(n), np.empty(n, np.int64), np.empty(n, np.int64))


def closest_hit(scene: Scene, tree: KdTree | None, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hit of each ray through the kd-tree.

    Parameters
    ----------
    scene : Scene
    tree : KdTree or None
        Built with :func:`~tracer.kd.tree.build_kdtree` if None.
    origins, directions : array_like, shape (R, 3)
        Directions are normalised here (``t`` is a distance).
    tmin, tmax : float or array_like (R,)

    Returns
    -------
    t : ndarray, shape (R,) float64, ``inf`` on a miss
    element : ndarray, shape (R,) int64, -1 on a miss
    node_visits : ndarray, shape (R,) int64
    """
    rays = _ray_batch(origins, directions, tmin, tmax)
    _, tree_arr = tree_arrays(scene, tree, None)
    out = _hit_arrays(len(rays.tmin))
    _closest_kernel(rays, tree_arr, prepare_geometry(scene), out)
    return out


def closest_hit_bruteforce(scene: Scene, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hit of each ray by testing every element (the slow reference).

    Returns
    -------
    t : ndarray, shape (R,) float64
    element : ndarray, shape (R,) int64
    """
    rays = _ray_batch(origins, directions, tmin, tmax)
    out = _hit_arrays(len(rays.tmin))
    _brute_kernel(rays, prepare_geometry(scene), out)
    return out.t, out.element
