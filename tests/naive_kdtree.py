"""The per-node SAH kd-tree builder: the slow peer of ``tracer.kd.sah._build_sah``.

Every node clips its primitives to its box and sorts their events there
(O(m log m) per node, O(N log^2 N) in all), which is how the SAH builder
worked before events were sorted once at the root. It builds the same
trees, so the tests compare the two and ``benchmarks/bench_kdtree.py`` times
them side by side. It is made of the package's per-node pieces (the ones
the median builder uses) and its SAH sweep and split rules.

    from naive_kdtree import build_per_node_sah   # tests/ on sys.path
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.kd.build import (_clip_members, _emit_leaf, _partition, new_per_node_build, open_node, push_node)
from tracer.kd.nodes import set_interior
from tracer.kd.split import _area, _axis_events, _sah_sweep, _settle_split, new_clip_scratch
from tracer.kd.tree import build_params, builder_inputs, resolve_config


class EventScratch(NamedTuple):
    """Scratch of :func:`_sah_split` for nodes of up to m primitives."""

    rows: np.ndarray    #: (m,) 0, 1, ... (box rows in node order)
    tpos: np.ndarray    #: (2 m,) one axis's events, unsorted
    ttyp: np.ndarray    #: (2 m,) int8
    tprim: np.ndarray   #: (2 m,) int32
    pos: np.ndarray     #: (6 m,) all axes' events, sorted per axis
    typ: np.ndarray     #: (6 m,) int8
    counts: np.ndarray  #: (3,) int64 events per axis


@njit(cache=True)
def _sah_split(boxes, m, lo, hi, params, events):
    # best plane (cost, axis, position, planar_left) of the m node-clipped
    # boxes: their events made, sorted here, then swept
    clo, chi = boxes
    rows, tpos, ttyp, tprim, pos, typ, counts = events.rows, events.tpos, events.ttyp, events.tprim, \
        events.pos, events.typ, events.counts
    w = 0
    for axis in range(3):
        ne = _axis_events(clo, chi, rows, m, axis, tpos, ttyp, tprim)
        order = np.argsort(tpos[:ne], kind="mergesort")
        for i in range(ne):
            pos[w] = tpos[order[i]]
            typ[w] = ttyp[order[i]]
            w += 1
        counts[axis] = ne
    return _sah_sweep(pos, typ, 0, counts, m, lo, hi, params)


@njit(cache=True)
def build_per_node_sah_kernel(inputs, params):
    """Per-node SAH build of ``inputs`` (BuildInputs) under ``params`` (BuildParams).

    Returns ``(nodes, primitive_indices, leaves, empty_leaves, deepest,
    sah_cost)`` like the package's builder kernels.
    """
    n = inputs.prim_lo.shape[0]
    nn = max(n, 1)
    nodes, pidx, work, stack, sp = new_per_node_build(n, params.tree_depth, inputs.root_lo, inputs.root_hi)
    n_nodes = 0
    n_pidx = 0
    size = inputs.root_hi - inputs.root_lo
    root_area = _area(size[0], size[1], size[2])
    if root_area <= 0.0:
        root_area = 1.0
    leaves = 0
    empty_leaves = 0
    deepest = 0
    sah_cost = 0.0
    lo = np.empty(3)
    hi = np.empty(3)
    boxes = (np.empty((nn, 3)), np.empty((nn, 3)))
    events = EventScratch(np.arange(nn), np.empty(2 * nn), np.empty(2 * nn, np.int8), np.empty(2 * nn, np.int32),
              np.empty(6 * nn), np.empty(6 * nn, np.int8), np.zeros(3, np.int64))
    scratch = new_clip_scratch()
    split32 = np.empty(1, np.float32)
    while sp > 0:
        nodes, node, depth, seg0, seg1 = open_node(stack, sp, lo, hi, nodes, n_nodes)
        sp -= 1
        n_nodes += 1
        m = _clip_members(work, seg0, seg1, inputs, lo, hi, params.clip, boxes, scratch)
        axis = -1
        planar_left = True
        if m > params.leaf_size and depth < params.tree_depth:
            best = _sah_split(boxes, m, lo, hi, params, events)
            axis, pos, planar_left = _settle_split(best, work[seg0:seg0 + m], inputs, lo, hi, params, scratch)
            if axis >= 0:
                split32[0] = pos
                if not (split32[0] > lo[axis] and split32[0] < hi[axis]):
                    axis = -1
        extent = hi - lo
        area_frac = _area(extent[0], extent[1], extent[2]) / root_area
        if axis < 0:
            pidx, n_pidx = _emit_leaf(nodes, node, pidx, n_pidx, work[seg0:seg0 + m])
            leaves += 1
            if m == 0:
                empty_leaves += 1
            deepest = max(deepest, depth)
            sah_cost += params.intersection_cost * m * area_frac
            continue
        sah_cost += params.traversal_cost * area_frac
        set_interior(nodes, node, split32.view(np.uint32)[0], axis)
        split = np.float64(split32[0])
        work, nl, nr = _partition(work, seg0, m, boxes, axis, split, planar_left)
        sp = push_node(stack, sp, lo, hi, depth + 1, node, seg0, seg0 + nr)
        stack.lo[sp - 1, axis] = split
        sp = push_node(stack, sp, lo, hi, depth + 1, -1, seg0 + nr, seg0 + nr + nl)
        stack.hi[sp - 1, axis] = split
    return nodes[:n_nodes].copy(), pidx[:n_pidx].copy(), leaves, empty_leaves, deepest, sah_cost


def build_per_node_sah(scene, config=None):
    """``(nodes, primitive_indices, sah_cost)`` of the per-node SAH tree of ``scene``.

    ``config`` is a ``KdTreeConfig`` with ``builder="sah"`` (default).
    """
    config = resolve_config(config, scene.n_elements)
    nodes, pidx, _, _, _, cost = build_per_node_sah_kernel(builder_inputs(scene), build_params(config))
    return nodes, pidx, float(cost)
