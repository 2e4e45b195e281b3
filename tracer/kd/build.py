"""The per-node kd-tree builder (spatial median) and the per-node pieces every builder shares.

:func:`_build_median` halves each node's longest axis (or cycles the axes),
clipping the node's primitives to it. The O(N log N) SAH builder is in
:mod:`tracer.kd.sah`. Both emit the flat arrays described in
:mod:`tracer.kd.nodes` and take a :class:`~tracer.kd.split.BuildInputs` and
a :class:`~tracer.kd.split.BuildParams`. The per-node pieces of the median
builder (:class:`NodeStack`, :func:`_clip_members`, :func:`_partition`,
:func:`_emit_leaf`) are the ones a per-node SAH builder needs too.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.kd.nodes import NODE_WORDS, set_above_child, set_interior, set_leaf
from tracer.kd.split import (_area, _clipped_bounds, _grow_1d, _grow_nodes, _overlap_bounds, _root_area,
                             new_clip_scratch)


class NodeStack(NamedTuple):
    """Nodes still to build by a per-node builder: box, depth, parent and members.

    Entry ``i`` holds the members ``work[seg0[i]:seg1[i]]``; ``parent`` is
    the node to link as the entry's above parent, -1 for a below child.
    """

    lo: np.ndarray      #: (S, 3) float64
    hi: np.ndarray      #: (S, 3) float64
    depth: np.ndarray   #: (S,) int64
    parent: np.ndarray  #: (S,) int64
    seg0: np.ndarray    #: (S,) int64
    seg1: np.ndarray    #: (S,) int64


@njit(cache=True)
def new_node_stack(tree_depth):
    """A :class:`NodeStack` deep enough for trees of ``tree_depth`` levels."""
    size = tree_depth + 4
    return NodeStack(np.empty((size, 3)), np.empty((size, 3)), np.empty(size, np.int64),
                     np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64))


@njit(cache=True)
def push_node(stack, sp, lo, hi, depth, parent, seg0, seg1):
    """Put a node to build on ``stack`` at ``sp``; returns the new ``sp``."""
    stack.lo[sp, :] = lo
    stack.hi[sp, :] = hi
    stack.depth[sp] = depth
    stack.parent[sp] = parent
    stack.seg0[sp] = seg0
    stack.seg1[sp] = seg1
    return sp + 1


@njit(cache=True)
def open_node(stack, sp, lo, hi, nodes, n_nodes):
    """Take the top of ``stack`` (``sp`` entries) as node ``n_nodes``, linked to its parent.

    Copies its box into ``lo``/``hi``; returns ``(nodes, node, depth, seg0, seg1)``.
    """
    lo[:] = stack.lo[sp - 1]
    hi[:] = stack.hi[sp - 1]
    node = n_nodes
    nodes = _grow_nodes(nodes, n_nodes + 1)
    if stack.parent[sp - 1] >= 0:
        set_above_child(nodes, stack.parent[sp - 1], node)
    return nodes, node, stack.depth[sp - 1], stack.seg0[sp - 1], stack.seg1[sp - 1]


@njit(cache=True)
def _emit_leaf(nodes, node, pidx, n_pidx, members):
    # leaf node: the element ids ``members`` go to pidx[n_pidx:]
    m = members.shape[0]
    set_leaf(nodes, node, n_pidx, m)
    pidx = _grow_1d(pidx, n_pidx + m)
    for j in range(m):
        pidx[n_pidx + j] = members[j]
    return pidx, n_pidx + m


@njit(cache=True)
def new_per_node_build(n, tree_depth, root_lo, root_hi):
    """What a per-node builder of ``n`` elements starts from.

    Returns ``(nodes, pidx, work, stack, sp)``: node and leaf-index arrays
    (grown as needed), the member work array holding ``0 .. n-1``, and the
    :class:`NodeStack` holding the root (``sp`` = 1).
    """
    nodes = np.zeros((max(16, 2 * n + 1), NODE_WORDS), np.uint32)
    pidx = np.empty(max(16, 2 * n), np.int32)
    work = np.empty(max(16, 4 * n), np.int32)
    for j in range(n):
        work[j] = j
    stack = new_node_stack(tree_depth)
    sp = push_node(stack, 0, root_lo, root_hi, 0, -1, 0, n)
    return nodes, pidx, work, stack, sp


# Columns of a builder's leaf statistics (:func:`_close_leaf`).
LEAVES, EMPTY_LEAVES, DEEPEST = 0, 1, 2


@njit(cache=True, inline="always")
def _close_leaf(nodes, node, pidx, n_pidx, members, depth, stats):
    # make ``node`` a leaf of ``members`` and count it in stats (int64 (3,): LEAVES, EMPTY_LEAVES, DEEPEST)
    pidx, n_pidx = _emit_leaf(nodes, node, pidx, n_pidx, members)
    stats[LEAVES] += 1
    if members.shape[0] == 0:
        stats[EMPTY_LEAVES] += 1
    stats[DEEPEST] = max(stats[DEEPEST], depth)
    return pidx, n_pidx


@njit(cache=True)
def _clip_members(work, seg0, seg1, inputs, lo, hi, clip, boxes, scratch):
    # keeps, from seg0 on, the elements of work[seg0:seg1] that the box
    # lo/hi holds (clipped with ``clip``), with their clipped boxes in
    # boxes = (clo, chi) (m, 3) rows 0..m; returns m
    clo, chi = boxes
    prim_lo, prim_hi, spheres = inputs.prim_lo, inputs.prim_hi, inputs.spheres
    clip_off, clip_v = inputs.clip_offsets, inputs.clip_vertices
    m = 0
    for j in range(seg1 - seg0):
        p = work[seg0 + j]
        if clip:
            kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, lo, hi, scratch.out_lo,
                                   scratch.out_hi)
        else:
            kept = _overlap_bounds(p, prim_lo, prim_hi, lo, hi, scratch.out_lo, scratch.out_hi)[0]
        if kept:
            work[seg0 + m] = p
            clo[m, :] = scratch.out_lo
            chi[m, :] = scratch.out_hi
            m += 1
    return m


@njit(cache=True)
def _partition(work, seg0, m, boxes, axis, split, planar_left):
    # The members work[seg0:seg0 + m] (clipped boxes ``boxes``) of a node
    # split at ``split`` on ``axis``: the right list then the left list,
    # written after the segment and moved down to seg0 (the segment is on
    # top of the work stack). Returns (work, maybe grown; nl; nr).
    clo, chi = boxes
    nl = 0
    nr = 0
    for j in range(m):
        a = clo[j, axis]
        b = chi[j, axis]
        on_plane = a == b and a == split
        if a < split or (on_plane and planar_left):
            nl += 1
        if b > split or (on_plane and not planar_left):
            nr += 1
    work = _grow_1d(work, seg0 + m + nl + nr)
    w = seg0 + m
    for right in (True, False):
        for j in range(m):
            a = clo[j, axis]
            b = chi[j, axis]
            on_plane = a == b and a == split
            if right:
                side = b > split or (on_plane and not planar_left)
            else:
                side = a < split or (on_plane and planar_left)
            if side:
                work[w] = work[seg0 + j]
                w += 1
    for j in range(nl + nr):
        work[seg0 + j] = work[seg0 + m + j]
    return work, nl, nr


@njit(cache=True)
def _build_median(inputs, params):
    # Per-node build: each node's primitives are clipped to it, and its
    # longest axis (the first of equal ones), or with cycle_axes the axis
    # depth % 3, halved; a node becomes a leaf at
    # leaf_size primitives, at tree_depth, or (unless split_to_depth) where a
    # split separates nothing.
    n = inputs.prim_lo.shape[0]
    nn = max(n, 1)
    ci = params.intersection_cost
    root_lo, root_hi = inputs.root_lo, inputs.root_hi
    nodes, pidx, work, stack, sp = new_per_node_build(n, params.tree_depth, root_lo, root_hi)
    n_nodes = 0
    n_pidx = 0
    root_area = _root_area(root_lo, root_hi)
    stats = np.zeros(3, dtype=np.int64)
    sah_cost = 0.0
    lo = np.empty(3)
    hi = np.empty(3)
    boxes = (np.empty((nn, 3)), np.empty((nn, 3)))
    scratch = new_clip_scratch()
    split32 = np.empty(1, np.float32)
    while sp > 0:
        nodes, node, depth, seg0, seg1 = open_node(stack, sp, lo, hi, nodes, n_nodes)
        sp -= 1
        n_nodes += 1
        m = _clip_members(work, seg0, seg1, inputs, lo, hi, params.clip, boxes, scratch)
        area_frac = _area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / root_area
        axis = -1
        if m > params.leaf_size and depth < params.tree_depth:
            d0 = hi[0] - lo[0]
            d1 = hi[1] - lo[1]
            d2 = hi[2] - lo[2]
            axis = 0
            if params.cycle_axes:
                axis = depth % 3
            elif d1 > d0 and d1 >= d2:
                axis = 1
            elif d2 > d0 and d2 > d1:
                axis = 2
            split32[0] = 0.5 * (lo[axis] + hi[axis])
            if not (split32[0] > lo[axis] and split32[0] < hi[axis]):
                axis = -1
        nl = nr = m
        if axis >= 0:
            split = np.float64(split32[0])
            work, nl, nr = _partition(work, seg0, m, boxes, axis, split, True)
        if axis < 0 or (nl == m and nr == m and not params.split_to_depth):
            pidx, n_pidx = _close_leaf(nodes, node, pidx, n_pidx, work[seg0:seg0 + m], depth, stats)
            sah_cost += ci * m * area_frac
            continue
        sah_cost += params.traversal_cost * area_frac
        set_interior(nodes, node, split32.view(np.uint32)[0], axis)
        # above (right) child first, then below (left) child on top
        sp = push_node(stack, sp, lo, hi, depth + 1, node, seg0, seg0 + nr)
        stack.lo[sp - 1, axis] = split
        sp = push_node(stack, sp, lo, hi, depth + 1, -1, seg0 + nr, seg0 + nr + nl)
        stack.hi[sp - 1, axis] = split
    return (nodes[:n_nodes].copy(), pidx[:n_pidx].copy(), stats[LEAVES], stats[EMPTY_LEAVES], stats[DEEPEST],
            sah_cost)
