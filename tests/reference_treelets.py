"""Plain-Python references for coherence.treelet_orders: random kd-trees, treelets, cuts and the queue walk.

Trees are dicts here: ``children[node] = (below, above)`` or None for a leaf.
Events are those of tests/reference_ray_orders.py.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from reference_ray_orders import path_walk
from tracer.trace.records import RecordKind, pack
from tracer.trace.segments import SegmentColumn, SegmentRayType

LEAF, FLAG_BITS = 3, 2


def random_tree(seed, max_depth=6, leaf_chance=0.3):
    """A seeded random kd-tree in the node format: (N, 2) uint32, below child next, above child linked."""
    rng = np.random.default_rng(seed)
    words = []

    def build(depth):
        index = len(words)
        words.append([0, 0])
        if depth == max_depth or (depth > 0 and rng.random() < leaf_chance):
            words[index] = [0, LEAF]
            return index
        build(depth + 1)
        above = build(depth + 1)
        words[index] = [0, above << FLAG_BITS | int(rng.integers(0, 3))]
        return index

    build(0)
    return np.array(words, dtype=np.uint32)


def children_of(nodes):
    """``{node: (below, above) or None}`` of a node array."""
    out = {}
    for node in range(len(nodes)):
        link = int(nodes[node][1])
        out[node] = None if link & 3 == LEAF else (node + 1, link >> FLAG_BITS)
    return out


def treelets(nodes, max_nodes):
    """Treelets grown breadth-first from each root, roots started in the order the walks reach them."""
    children = children_of(nodes)
    treelet = {}
    roots = deque([0])
    number = 0
    while roots:
        walk = deque([roots.popleft()])
        taken = 0
        while walk:
            node = walk.popleft()
            if taken == max_nodes:
                roots.append(node)
                continue
            treelet[node] = number
            taken += 1
            if children[node] is not None:
                walk.extend(children[node])
        number += 1
    return [treelet[node] for node in range(len(nodes))], number


def cut(records, first, stop, treelet):
    """Pieces (first, stop, treelet) of one segment: a cut before every node record of another treelet."""
    pieces, start, current = [], first, None
    for i in range(first, stop):
        record = int(records[i])
        if record >> 28 != RecordKind.KD_NODE:
            continue
        t = treelet[record & ((1 << 27) - 1)]
        if current is not None and t != current:
            pieces.append((start, i, current))
            start = i
        current = t
    pieces.append((start, stop, 0 if current is None else current))
    return pieces


def random_records(segments, n_nodes, seed):
    """Records for seeded random segments: each a random mix of kd-node reads and sphere tests."""
    rng = np.random.default_rng(seed)
    n = int(segments.ints[:, SegmentColumn.STOP].max(initial=0))
    kinds = np.where(rng.random(n) < 0.7, RecordKind.KD_NODE, RecordKind.SPHERE)
    return pack(kinds, rng.integers(0, n_nodes, n))


def treelet_events(ints, records, treelet, n_treelets):
    """The treelet-queue walk, ray by ray with explicit queues (coherence.treelet_orders' docstring)."""
    path_of, extension, phase, children = path_walk(ints)
    pieces = [cut(records, int(row[SegmentColumn.FIRST]), int(row[SegmentColumn.STOP]), treelet) for row in ints]
    n = len(ints)

    capacity = max(phase.count(p) for p in set(phase))
    phase_queues = {p: [] for p in range(max(phase) + 1)}
    events = []
    for i in range(n):
        if int(ints[i][SegmentColumn.RAY_TYPE]) == SegmentRayType.CAMERA:
            phase_queues[0].append(i)
            events += [("queue", len(phase_queues[0]) - 1, True), ("state", path_of[i], True)]
    for p in range(max(phase) + 1):
        position = {i: k for k, i in enumerate(phase_queues[p])}
        queues = [deque() for _ in range(n_treelets)]
        next_piece = {}
        for i in phase_queues[p]:
            next_piece[i] = 0
            events += [("queue", (p % 3) * capacity + position[i], False), ("queue", 3 * capacity + position[i], True)]
            queues[pieces[i][0][2]].append(i)
        left = len(phase_queues[p])
        while left:
            for t in range(n_treelets):
                for _ in range(len(queues[t])):
                    i = queues[t].popleft()
                    first, stop, _ = pieces[i][next_piece[i]]
                    events += [("queue", 3 * capacity + position[i], False), ("state", path_of[i], False),
                               ("piece", first, stop), ("state", path_of[i], True)]
                    next_piece[i] += 1
                    if next_piece[i] < len(pieces[i]):
                        events.append(("queue", 3 * capacity + position[i], True))
                        queues[pieces[i][next_piece[i]][2]].append(i)
                        continue
                    left -= 1
                    if extension[i]:
                        for c in children(i):
                            phase_queues[phase[c]].append(c)
                            events.append(("queue", (phase[c] % 3) * capacity + len(phase_queues[phase[c]]) - 1, True))
    return events
