"""Treelet queues: rays suspended where they enter another part of the kd-tree, and run treelet by treelet.

Treelets
--------
:func:`treelets` cuts the kd-tree into *treelets*, connected subtrees of at
most ``treelet_bytes`` of nodes (``treelet_bytes // node_bytes`` nodes, the
node's bytes those of the memory layout), top-down: the root's treelet takes
the first nodes of a breadth-first walk from the root, and every node the
walk reaches once the treelet is full starts a treelet of its own, grown
the same way; treelets are numbered in the order they are started (the
root's is 0), so a parent's treelet has a lower number than its children's.

Cutting
-------
:func:`cut_segments` cuts each ray's segment before every kd-node record
whose treelet differs from that of the node record before it (the ray
enters another treelet, going down or popping back up its stack). A piece
runs from such a node record to the next cut; the records before a
segment's first node record (there are none in the tracer's traces) and the
shading reads after its last belong to the piece around them. A piece's
treelet is that of its first node record (treelet 0 when it has none).

Queue discipline
----------------
The rays run in the wavefront's phases (:mod:`coherence.ray_order_base`:
extension rays of bounce ``k``, then their shadow rays), so every ray runs
after its parent. Within a phase:

1. the phase's rays are taken off the phase queue in the order they were
   queued, and each is queued on the treelet of its first piece;
2. then sweeps over the treelets in number order (top-down), repeated
   until no ray is left: a treelet's turn runs each ray queued on it when
   the turn starts, first in, first out, for one piece; a ray with pieces
   left is queued on the next piece's treelet (a later treelet of the same
   sweep may take it at once), a finished ray queues its children on their
   phase queues as in the wavefront.

Each ray keeps its pieces in its own order. Treelet queues are intrusive
linked lists: a ray's entry is its own queue slot (``3 C`` plus its position
in the phase, after the three phase queues of ``C`` slots), written when it
is queued on a treelet and read when it is taken off. A ray's path state
is read before each piece and written after it. Nothing is sorted.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from rtcommon.validate import InputError, require_int
from tracer.kd.nodes import above_child, below_child, is_leaf
from tracer.trace.records import AUX_INDEX_MASK, INDEX_MASK, KIND_SHIFT, AuxKind, RecordKind, make_aux_record, record_id, record_kind
from tracer.trace.segments import SegmentColumn

from .ray_order_base import OrderedPieces, RayOrder, path_structure

#: Treelet bytes of the ``treelet`` order by default: the Alpha 21164's 8 KB L1 data cache.
DEFAULT_TREELET_BYTES = 8192


@njit(cache=True, nogil=True)
def _treelets(nodes, max_nodes):
    """Treelet of every node (int64 (N,)) and the number of treelets (module docstring)."""
    n = nodes.shape[0]
    treelet = np.full(n, -1, dtype=np.int64)
    roots = np.empty(n, dtype=np.int64)
    walk = np.empty(n, dtype=np.int64)
    roots[0] = 0
    n_roots, next_root, n_treelets = 1, 0, 0
    while next_root < n_roots:
        head, tail, taken = 0, 1, 0
        walk[0] = roots[next_root]
        next_root += 1
        while head < tail:
            node = walk[head]
            head += 1
            if taken == max_nodes:
                roots[n_roots] = node
                n_roots += 1
                continue
            treelet[node] = n_treelets
            taken += 1
            if not is_leaf(nodes, node):
                walk[tail] = below_child(node)
                walk[tail + 1] = above_child(nodes, node)
                tail += 2
        n_treelets += 1
    return treelet, n_treelets


@njit(cache=True, nogil=True)
def _cut(records, firsts, stops, node_treelet):
    """Pieces of each segment ``firsts[s] .. stops[s] - 1`` of ``records`` (module docstring).

    Returns (piece_offsets (S + 1,), piece_first, piece_stop, piece_treelet), int64.
    """
    n = firsts.shape[0]
    total = 0
    for s in range(n):
        total += stops[s] - firsts[s] + 1
    first_out = np.empty(total, dtype=np.int64)
    stop_out = np.empty(total, dtype=np.int64)
    treelet_out = np.empty(total, dtype=np.int64)
    offsets = np.zeros(n + 1, dtype=np.int64)
    k = 0
    for s in range(n):
        start = firsts[s]
        current = -1
        for i in range(firsts[s], stops[s]):
            if record_kind(records[i]) != RecordKind.KD_NODE:
                continue
            t = node_treelet[record_id(records[i])]
            if current >= 0 and t != current:
                first_out[k], stop_out[k], treelet_out[k] = start, i, current
                k += 1
                start = i
            current = t
        first_out[k], stop_out[k], treelet_out[k] = start, stops[s], max(current, 0)
        k += 1
        offsets[s + 1] = k
    return offsets, first_out[:k], stop_out[:k], treelet_out[:k]


def treelets(nodes, treelet_bytes: int, node_bytes: int) -> tuple[np.ndarray, int]:
    """Cut a kd-tree into treelets of at most ``treelet_bytes`` of nodes (module docstring).

    Parameters
    ----------
    nodes : ndarray of uint32, shape (N, 2)
        The kd-tree's nodes (``KdTree.nodes``).
    treelet_bytes : int
        Bytes of nodes a treelet may hold (at least one node's).
    node_bytes : int
        Bytes of a node in the memory layout (``layout.record("kd_node").size``).

    Returns
    -------
    treelet : ndarray of int64, shape (N,)
        The treelet of every node.
    n_treelets : int
    """
    nodes = _checked_nodes(nodes)
    node_bytes = require_int("node_bytes", node_bytes, 1)
    treelet_bytes = require_int("treelet_bytes", treelet_bytes, node_bytes)
    treelet, n_treelets = _treelets(nodes, treelet_bytes // node_bytes)
    return treelet, int(n_treelets)


def cut_segments(records, segments, rows, node_treelet) -> tuple:
    """Cut the segments ``rows`` where their rays enter another treelet (module docstring).

    Parameters
    ----------
    records : ndarray of uint32, shape (R,)
        The trace's records.
    segments : RaySegments
    rows : ndarray of int64, shape (S,)
    node_treelet : ndarray of int64, shape (N,)
        Treelet of every kd node (:func:`treelets`).

    Returns
    -------
    piece_offsets : ndarray of int64, shape (S + 1,)
        Segment ``rows[s]``'s pieces are ``piece_offsets[s] .. piece_offsets[s + 1] - 1``.
    piece_first, piece_stop, piece_treelet : ndarray of int64, shape (Q,)
    """
    ints = segments.ints[rows]
    records = np.asarray(records)
    if ints.shape[0] and int(ints[:, SegmentColumn.STOP].max()) > records.shape[0]:
        raise InputError(f"records: the segments reach record {int(ints[:, SegmentColumn.STOP].max())}, "
                         f"but the trace has {records.shape[0]}")
    node_treelet = np.ascontiguousarray(node_treelet, dtype=np.int64)
    kd = records[(records >> KIND_SHIFT) == int(RecordKind.KD_NODE)]
    if kd.size and int((kd & INDEX_MASK).max()) >= node_treelet.shape[0]:
        raise InputError(f"tree: the records visit kd node {int((kd & INDEX_MASK).max())}, but the tree has "
                         f"{node_treelet.shape[0]} nodes; give the tree the trace was rendered with")
    return _cut(records, np.ascontiguousarray(ints[:, SegmentColumn.FIRST]),
                np.ascontiguousarray(ints[:, SegmentColumn.STOP]), node_treelet)


def _checked_nodes(nodes) -> np.ndarray:
    nodes = getattr(nodes, "nodes", nodes)
    if not isinstance(nodes, np.ndarray) or nodes.dtype != np.uint32 or nodes.ndim != 2 or nodes.shape[1] != 2 \
            or nodes.shape[0] == 0:
        raise InputError("tree must be a KdTree or its nodes, a non-empty (N, 2) uint32 array")
    return np.ascontiguousarray(nodes)


@njit(cache=True, inline="always")
def _push(queues, t, i):
    """Queue ray ``i`` on treelet ``t``: ``queues`` = (head, tail, size per treelet, next ray per ray)."""
    head, tail, size, link = queues
    if tail[t] < 0:
        head[t] = i
    else:
        link[tail[t]] = i
    tail[t] = i
    size[t] += 1


@njit(cache=True, nogil=True)
def _walk(structure, pieces, n_treelets, capacity):
    """The treelet queues' replay (module docstring).

    ``structure`` = (path, phase, parent, extension, child_stop) per ray
    (positions of the depth-first rows); ``pieces`` = (piece_offsets,
    piece_treelet). Returns the pieces in replay order (indices), and the
    auxiliary records with how many pieces precede each.
    """
    path, phase, parent, extension, child_stop = structure
    piece_offsets, piece_treelet = pieces
    n = path.shape[0]
    n_pieces = piece_treelet.shape[0]
    n_phases = 0
    for i in range(n):
        n_phases = max(n_phases, phase[i] + 1)
    order = np.empty(n_pieces, dtype=np.int64)
    aux = np.empty(4 * n_pieces + 4 * n, dtype=np.uint32)
    after = np.empty(4 * n_pieces + 4 * n, dtype=np.int64)
    queued = np.zeros(max(n_phases, 1), dtype=np.int64)
    queue_pos = np.zeros(n, dtype=np.int64)
    gen_seq = np.full(n, -1, dtype=np.int64)
    next_piece = piece_offsets[:-1].copy()
    head = np.full(n_treelets, -1, dtype=np.int64)
    tail = np.full(n_treelets, -1, dtype=np.int64)
    size = np.zeros(n_treelets, dtype=np.int64)
    link = np.full(n, -1, dtype=np.int64)
    queues = (head, tail, size, link)
    state, queue = AuxKind.RAY_STATE, AuxKind.QUEUE_ENTRY
    n_aux, done, generated = 0, 0, 0
    for i in range(n):
        if parent[i] < 0:
            queue_pos[i] = queued[0]
            queued[0] += 1
            gen_seq[i] = generated
            generated += 1
            aux[n_aux], after[n_aux] = make_aux_record(queue, queue_pos[i], True), 0
            aux[n_aux + 1], after[n_aux + 1] = make_aux_record(state, path[i], True), 0
            n_aux += 2
    for p in range(n_phases):
        members = np.flatnonzero(phase == p)
        members = members[np.argsort(gen_seq[members], kind="mergesort")]
        base = (p % 3) * capacity
        for i in members:
            t = piece_treelet[next_piece[i]]
            aux[n_aux], after[n_aux] = make_aux_record(queue, base + queue_pos[i], False), done
            aux[n_aux + 1], after[n_aux + 1] = make_aux_record(queue, 3 * capacity + queue_pos[i], True), done
            n_aux += 2
            _push(queues, t, i)
        left = members.shape[0]
        while left > 0:
            for t in range(n_treelets):
                for _ in range(size[t]):
                    i = head[t]
                    head[t] = link[i]
                    if head[t] < 0:
                        tail[t] = -1
                    link[i] = -1
                    size[t] -= 1
                    aux[n_aux], after[n_aux] = make_aux_record(queue, 3 * capacity + queue_pos[i], False), done
                    aux[n_aux + 1], after[n_aux + 1] = make_aux_record(state, path[i], False), done
                    n_aux += 2
                    order[done] = next_piece[i]
                    done += 1
                    next_piece[i] += 1
                    aux[n_aux], after[n_aux] = make_aux_record(state, path[i], True), done
                    n_aux += 1
                    if next_piece[i] < piece_offsets[i + 1]:
                        u = piece_treelet[next_piece[i]]
                        aux[n_aux], after[n_aux] = make_aux_record(queue, 3 * capacity + queue_pos[i], True), done
                        n_aux += 1
                        _push(queues, u, i)
                        continue
                    left -= 1
                    if extension[i]:
                        for c in range(i + 1, child_stop[i]):
                            queue_pos[c] = queued[phase[c]]
                            queued[phase[c]] += 1
                            gen_seq[c] = generated
                            generated += 1
                            slot = (phase[c] % 3) * capacity + queue_pos[c]
                            aux[n_aux], after[n_aux] = make_aux_record(queue, slot, True), done
                            n_aux += 1
    return order, aux[:n_aux], after[:n_aux]


def treelet_pieces(records, segments, rows, nodes, treelet_bytes: int, node_bytes: int) -> OrderedPieces:
    """The treelet-queue order of a process's segments ``rows`` (module docstring)."""
    node_treelet, n_treelets = treelets(nodes, treelet_bytes, node_bytes)
    offsets, first, stop, piece_treelet = cut_segments(records, segments, rows, node_treelet)
    path, phase, parent, extension = path_structure(segments.ints[rows])
    n = rows.shape[0]
    capacity = int(np.bincount(phase).max(initial=0)) if n else 0
    if 4 * capacity > AUX_INDEX_MASK + 1 or (n and path.max() > AUX_INDEX_MASK):
        raise InputError(f"a phase of {capacity} rays (or {int(path.max(initial=0)) + 1} paths) is more than the "
                         f"auxiliary records' {AUX_INDEX_MASK + 1} slots hold: give the process fewer rays")
    # an extension ray's children follow it up to the next extension ray of its path (inclusive)
    position = np.arange(n)
    next_extension = np.where(extension, position, n)
    next_extension = np.minimum.accumulate(next_extension[::-1])[::-1] if n else next_extension
    after_me = np.append(next_extension[1:], n) if n else next_extension
    path_end = np.searchsorted(path, path, side="right")
    child_stop = np.where(extension, np.minimum(after_me + 1, path_end), position + 1)
    order, aux, after = _walk((path, phase, parent, extension, child_stop.astype(np.int64)),
                              (offsets, piece_treelet), n_treelets, capacity)
    owner = np.repeat(rows, np.diff(offsets))
    return OrderedPieces(first[order], stop[order], owner[order], aux, after, 0.0)


@dataclass(frozen=True)
class TreeletQueues(RayOrder):
    """Rays cut where they enter another treelet and run treelet by treelet (module docstring).

    Parameters
    ----------
    treelet_bytes : int
        Bytes of nodes per treelet, sized to a cache level (>= 1; at least
        one node's when used).
    node_bytes : int
        Bytes of a kd node in the memory layout (8 in ``compact``, 40 in ``alpha1997``).
    """

    treelet_bytes: int = DEFAULT_TREELET_BYTES
    node_bytes: int = 8
    name = "treelet"
    needs_tree = True
    needs_records = True

    def __post_init__(self):
        require_int("TreeletQueues.treelet_bytes", self.treelet_bytes, 1)
        require_int("TreeletQueues.node_bytes", self.node_bytes, 1)
        if self.treelet_bytes < self.node_bytes:
            raise InputError(f"TreeletQueues.treelet_bytes must be >= node_bytes ({self.node_bytes}), "
                             f"got {self.treelet_bytes}")

    def sized(self, cache_bytes: int, node_bytes: int) -> "TreeletQueues":
        """This order with treelets of ``cache_bytes`` (a cache level's size; at least one node) of nodes of
        ``node_bytes`` (the placed layout's kd-node size): how a run sizes the registered ``treelet``."""
        node_bytes = require_int("TreeletQueues.sized: node_bytes", node_bytes, 1)
        cache_bytes = require_int("TreeletQueues.sized: cache_bytes", cache_bytes, 1)
        return replace(self, treelet_bytes=max(node_bytes, cache_bytes), node_bytes=node_bytes)

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        return treelet_pieces(records, segments, rows, tree, self.treelet_bytes, self.node_bytes)
