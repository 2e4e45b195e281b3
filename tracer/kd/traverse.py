"""kd-tree traversal shared by the renderer and the closest-hit API.

:func:`traverse` walks the flat tree of :mod:`tracer.kd.tree` front to back
and appends every record it reads to the access log; :func:`brute_force` is
the slow reference that tests every element. The kernels take their arrays
as bundles: :class:`TreeArrays` (the tree, prepared by :func:`tree_arrays`),
:class:`~tracer.rendering.geometry.Geometry` (elements), a
:class:`~tracer.rendering.geometry.Ray`, a :class:`RecordLog` and
:class:`TraversalStack` scratch.

Bundles passed to a ``parallel=True`` kernel are flat (no bundle inside a
bundle): numba cannot hand a nested tuple holding arrays to a prange body.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.rendering.geometry import hit_element
from tracer.kd.nodes import above_child, below_child, is_leaf, leaf_count, leaf_offset, node_axis, split_position
from tracer.kd.tree import KdTree, KdTreeConfig, build_kdtree
from tracer.trace.records import Counter, RecordKind, make_record
from tracer.scenes.model import Scene
from rtcommon.validate import InputError

#: entries of a traversal stack: the deepest tree (MAX_TREE_DEPTH) fits
STACK_DEPTH = 64


class TreeArrays(NamedTuple):
    """A kd-tree as the kernels read it (format in :mod:`tracer.kd.nodes`)."""

    nodes: np.ndarray              #: (N, 2) uint32
    splits: np.ndarray             #: (N, 2) float32 view of ``nodes`` (interior split planes)
    primitive_indices: np.ndarray  #: (E,) int32 element ids of the leaves
    lo: np.ndarray                 #: (3,) float64 root box corner
    hi: np.ndarray                 #: (3,) float64 root box corner


class RecordLog(NamedTuple):
    """Where a kernel stores records: ``records[pos]`` while ``pos < limit``.

    ``limit = 0`` logs nothing; a writer always advances ``pos``, so a caller
    whose slot overflows learns the size it needs.
    """

    records: np.ndarray  #: (R,) uint32 packed records (:mod:`tracer.trace.records`)
    limit: int


class TraversalStack(NamedTuple):
    """Scratch of :func:`traverse`: nodes still to visit and their ray intervals."""

    node: np.ndarray  #: (STACK_DEPTH,) int64
    t0: np.ndarray    #: (STACK_DEPTH,) float64
    t1: np.ndarray    #: (STACK_DEPTH,) float64


@njit(cache=True)
def new_stack():
    """An empty :class:`TraversalStack` (allocate once per thread, not per ray)."""
    return TraversalStack(np.empty(STACK_DEPTH, np.int64), np.empty(STACK_DEPTH), np.empty(STACK_DEPTH))


@njit(cache=True, error_model="numpy", inline="always")
def traverse(tree, geo, ray, tmin, tmax, anyhit, log, pos, cnt, stack):
    """Closest (or any, with ``anyhit``) hit of ``ray`` in ``(tmin, tmax)``.

    Parameters
    ----------
    tree : TreeArrays
    geo : Geometry
    ray : Ray
    tmin, tmax : float
    anyhit : bool
        Stop at the first hit found (shadow rays).
    log : RecordLog
    pos : int
        Position of the next record in ``log``.
    cnt : ndarray, shape (K,) int64
        Counters (:class:`~tracer.trace.records.Counter` columns): every node
        visit, leaf index-entry read and primitive test is counted and
        advances ``pos``; a test that took a square root is counted again
        in ``ROOT_TESTS`` (no record).
    stack : TraversalStack

    Returns
    -------
    t : float
        Hit distance or ``inf``.
    element : int
        Element id or -1.
    pos : int
        Next free record position.

    Inlined (numba IR) into its callers' ray loops, which are compiled
    without reference counting (:data:`rtcommon.jit.NO_REFCOUNTS`): a call
    per ray that passed these bundles cost more than most primary rays'
    traversal.
    """
    nodes, splits, pidx, blo, bhi = tree
    ekind = geo.element_kind
    eidx = geo.element_index
    rec, limit = log
    st_node, st_t0, st_t1 = stack
    ox, oy, oz, dx, dy, dz = ray
    best_t = tmax
    best_e = -1
    # root box: the root record is read (it holds the bounds) even when the
    # ray misses the box
    t0 = tmin
    t1 = tmax
    o3 = (ox, oy, oz)
    d3 = (dx, dy, dz)
    inv = (1.0 / dx if dx != 0.0 else np.inf,
           1.0 / dy if dy != 0.0 else np.inf,
           1.0 / dz if dz != 0.0 else np.inf)
    miss = False
    for a in range(3):
        if d3[a] == 0.0:
            if o3[a] < blo[a] or o3[a] > bhi[a]:
                miss = True
        else:
            ta = (blo[a] - o3[a]) * inv[a]
            tb = (bhi[a] - o3[a]) * inv[a]
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
    if miss or t0 > t1:
        if pos < limit:
            rec[pos] = make_record(RecordKind.KD_NODE, 0)
        pos += 1
        cnt[Counter.NODE_VISITS] += 1
        return np.inf, -1, pos
    sp = 0
    node = 0
    while True:
        if best_t < t0:
            break  # stacked nodes lie even farther along the ray
        if pos < limit:
            rec[pos] = make_record(RecordKind.KD_NODE, node)
        pos += 1
        cnt[Counter.NODE_VISITS] += 1
        if not is_leaf(nodes, node):
            axis = node_axis(nodes, node)
            split = split_position(splits, node)
            oa = o3[axis]
            da = d3[axis]
            below_first = oa < split or (oa == split and da <= 0.0)
            if below_first:
                first = below_child(node)
                second = above_child(nodes, node)
            else:
                first = above_child(nodes, node)
                second = below_child(node)
            if da != 0.0:
                tp = (split - oa) * inv[axis]
            else:
                tp = np.inf
            if tp > t1 or tp <= 0.0:
                node = first
            elif tp < t0:
                node = second
            else:
                st_node[sp] = second
                st_t0[sp] = tp
                st_t1[sp] = t1
                sp += 1
                node = first
                t1 = tp
            continue
        # leaf
        cnt[Counter.LEAF_VISITS] += 1
        count = leaf_count(nodes, node)
        off = leaf_offset(nodes, node)
        for j in range(off, off + count):
            e = pidx[j]
            k = np.int64(ekind[e])
            i = eidx[e]
            if pos + 1 < limit:
                rec[pos] = make_record(RecordKind.INDEX_ENTRY, j)
                rec[pos + 1] = make_record(RecordKind.SPHERE + k, i)
            elif pos < limit:
                rec[pos] = make_record(RecordKind.INDEX_ENTRY, j)
            pos += 2
            cnt[Counter.INDEX_READS] += 1
            cnt[Counter.TESTS_SPHERE + k] += 1
            t, roots = hit_element(k, i, geo, ray, tmin, best_t)
            cnt[Counter.ROOT_TESTS] += roots
            if t < best_t:
                best_t = t
                best_e = e
                if anyhit:
                    return best_t, best_e, pos
        if best_e >= 0 and best_t <= t1:
            break
        if sp == 0:
            break
        sp -= 1
        node = st_node[sp]
        t0 = st_t0[sp]
        t1 = st_t1[sp]
    if best_e < 0:
        return np.inf, -1, pos
    return best_t, best_e, pos


@njit(cache=True, error_model="numpy")
def brute_force(geo, ray, tmin, tmax):
    """Closest hit of ``ray`` over all elements of ``geo`` (Geometry) in id order.

    The reference :func:`traverse` is checked against; returns ``(t, element)``.
    """
    ekind = geo.element_kind
    eidx = geo.element_index
    best_t = tmax
    best_e = -1
    for e in range(ekind.shape[0]):
        t, _ = hit_element(np.int64(ekind[e]), eidx[e], geo, ray, tmin, best_t)
        if t < best_t:
            best_t = t
            best_e = e
    if best_e < 0:
        return np.inf, -1
    return best_t, best_e


def tree_arrays(scene: Scene, tree: KdTree | None, kd_config: KdTreeConfig | None) -> tuple[KdTree, TreeArrays]:
    """``tree`` (built from ``kd_config`` when None) and its :class:`TreeArrays`."""
    if tree is None:
        tree = build_kdtree(scene, kd_config)
    elif not isinstance(tree, KdTree):
        raise InputError(f"tree must be a KdTree, got {type(tree).__name__}")
    nodes = np.ascontiguousarray(tree.nodes, dtype=np.uint32)
    return tree, TreeArrays(nodes, nodes.view(np.float32), np.ascontiguousarray(tree.primitive_indices, dtype=np.int32),
                            np.ascontiguousarray(tree.bounds[0]), np.ascontiguousarray(tree.bounds[1]))
