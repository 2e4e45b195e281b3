"""Closest-hit queries for arbitrary rays: through the kd-tree, or by brute force.

The brute-force version tests every element and is the slow reference the
tests compare the tree against; both use the renderer's intersection code.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from tracer.geometry import prepare_geometry
from tracer.kdtree import KdTree
from tracer.scene import Scene
from tracer.records import COUNTER_NAMES, Counter
from tracer.traverse import _scene_arrays, _tree_arrays, brute_force, traverse


@njit(parallel=True, cache=True, error_model="numpy")
def _closest_kernel(orig, dirs, tmin, tmax, nodes, fnodes, pidx, blo, bhi, ekind, eidx, geo,
                    n_counters, out_t, out_e, out_nodes):
    dummy = np.empty(0, np.uint32)
    for r in prange(orig.shape[0]):
        cnt = np.zeros(n_counters, np.int64)
        st_node = np.empty(64, np.int64)
        st_t0 = np.empty(64)
        st_t1 = np.empty(64)
        t, e, _ = traverse(nodes, fnodes, pidx, ekind, eidx, geo, blo, bhi,
                           orig[r, 0], orig[r, 1], orig[r, 2], dirs[r, 0], dirs[r, 1], dirs[r, 2],
                           tmin[r], tmax[r], False, dummy, 0, 0, cnt, st_node, st_t0, st_t1)
        out_t[r] = t
        out_e[r] = e
        out_nodes[r] = cnt[Counter.NODE_VISITS]


@njit(parallel=True, cache=True, error_model="numpy")
def _brute_kernel(orig, dirs, tmin, tmax, ekind, eidx, geo, out_t, out_e):
    for r in prange(orig.shape[0]):
        t, e = brute_force(ekind, eidx, geo, orig[r, 0], orig[r, 1], orig[r, 2],
                           dirs[r, 0], dirs[r, 1], dirs[r, 2], tmin[r], tmax[r])
        out_t[r] = t
        out_e[r] = e


def _rays(origins, directions):
    o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins and directions must both be (R, 3), got {o.shape} and {d.shape}")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0.0):
        raise ValueError("directions must be non-zero")
    return o, np.ascontiguousarray(d / norm[:, None])


def _bounds(value, n):
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,))
    return np.ascontiguousarray(a)


def closest_hit(scene: Scene, tree: KdTree | None, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hit of each ray through the kd-tree.

    Parameters
    ----------
    scene : Scene
    tree : KdTree or None
        Built with :func:`~tracer.kdtree.build_kdtree` if None.
    origins, directions : array_like, shape (R, 3)
        Directions are normalised here (``t`` is a distance).
    tmin, tmax : float or array_like (R,)

    Returns
    -------
    t : ndarray, shape (R,) float64, ``inf`` on a miss
    element : ndarray, shape (R,) int64, -1 on a miss
    node_visits : ndarray, shape (R,) int64
    """
    o, d = _rays(origins, directions)
    tree, nodes, fnodes, pidx, blo, bhi = _tree_arrays(scene, tree, None)
    ekind, eidx, _, _ = _scene_arrays(scene)
    geo = prepare_geometry(scene)
    r = len(o)
    out_t = np.empty(r)
    out_e = np.empty(r, np.int64)
    out_n = np.empty(r, np.int64)
    _closest_kernel(o, d, _bounds(tmin, r), _bounds(tmax, r), nodes, fnodes, pidx,
                    blo, bhi, ekind, eidx, geo, len(COUNTER_NAMES), out_t, out_e, out_n)
    return out_t, out_e, out_n


def closest_hit_bruteforce(scene: Scene, origins, directions, tmin=0.0, tmax=np.inf):
    """Closest hit of each ray by testing every element (the slow reference).

    Returns
    -------
    t : ndarray, shape (R,) float64
    element : ndarray, shape (R,) int64
    """
    o, d = _rays(origins, directions)
    ekind, eidx, _, _ = _scene_arrays(scene)
    geo = prepare_geometry(scene)
    r = len(o)
    out_t = np.empty(r)
    out_e = np.empty(r, np.int64)
    _brute_kernel(o, d, _bounds(tmin, r), _bounds(tmax, r), ekind, eidx, geo, out_t, out_e)
    return out_t, out_e
