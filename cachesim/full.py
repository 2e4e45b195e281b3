"""Level operations of the per-access walk, with an index for large fully associative levels.

A level of one set looks a line up by scanning all its ways, and an LRU or
FIFO insert scans them again for the oldest stamp: a 4 MB fully associative
level of 64-byte lines (65,536 ways) took some 60 microseconds an access.
For a long enough stream (:func:`uses_index`) passed whole to
:func:`cachesim.kernels.simulate_stream` or ``simulate_writes`` (so through
:func:`cachesim.simulate`; the ``_into`` kernels, for many short streams,
scan) each such level (one set of at least :data:`INDEXED_MIN_WAYS` ways)
gets, for the length of one call, an index (:class:`FullIndex`) built from
its ``tags`` and ``stamps``, which makes an access O(1):

- a hash table from line to way (open addressing, linear probing, at most
  half full; a removal shifts the probe chain back instead of leaving a
  marker, so lookups stay short however long the run);
- for LRU and FIFO, a doubly linked list of the filled ways in the order of
  their stamps (ties by way), oldest first: the victim is its head, a fill
  or an LRU hit moves a way to its tail;
- a min-heap of the empty ways: a fill takes the lowest empty way first, as
  the scan does (O(log ways) only while the level fills up, or after
  back-invalidations empty ways again).

The operations (lookup, place, serving level, fill levels ...) are written
once (:func:`level_operations`) and compiled in two forms: :data:`SCANNING`
takes ``index`` None and holds the scans alone, :data:`INDEXED` takes the
index. The walk of :mod:`cachesim.by_access` runs on either, so the
semantics (inclusion, writes, counters, ``served_by``, the clock and the
stamps left) are one. The state stays in ``tags`` and
``stamps`` only, so every other kernel, and other packages' compiled code,
continue from it unchanged.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.sets import EVICTIONS, EXCLUSIVE, INCLUSIVE, LRU, RANDOM, _find, _insert, _random_way, _set_base

#: Ways from which a level of one set is indexed: below it a scan of the ways costs less than a hash probe.
INDEXED_MIN_WAYS = 128
#: A call builds the index only when it has at least one access per this many indexed ways. Building
#: a full 65,536-way level costs about as much as 700 early-exit scans of it, and a level below
#: others sees a fraction of the call's accesses; shorter calls keep the scans.
WAYS_PER_ACCESS = 16
_GOLDEN = 0x9E3779B97F4A7C15  # 2**64 / golden ratio: Fibonacci hashing


class FullIndex(NamedTuple):
    """The index of a hierarchy's large fully associative levels, for one call.

    Attributes
    ----------
    indexed : ndarray of bool, shape (L,)
        Whether a level is indexed.
    hash_base : ndarray of int64, shape (L,)
        First entry of each indexed level's hash table in ``keys``/``ways``.
    hash_bits : ndarray of int64, shape (L,)
        log2 of each table's size: a line's home entry is that many top bits
        of its Fibonacci hash.
    entries : ndarray of int64, shape (2 H,)
        Per table entry ``e``: the line at ``2 e`` (-1: none), and at
        ``2 e + 1`` the way (an index into ``tags``) holding it; side by
        side, so that a lookup reads one host cache line.
    node_base : ndarray of int64, shape (L,)
        First entry of each indexed level's ways in ``older``, ``newer``
        and ``heap``, which hold the indexed levels' ways only (``F`` in all).
    node_shift : ndarray of int64, shape (L,)
        ``offset[l] - node_base[l]``: way ``w`` of level ``l`` (an index into
        ``tags``) is entry ``w - node_shift[l]``.
    older, newer : ndarray of int64, shape (F,)
        Per way, its neighbours (ways) in the recency list (-1: none).
    head, tail : ndarray of int64, shape (L,)
        Oldest and newest way of each indexed level's list (-1: empty).
    heap : ndarray of int64, shape (F,)
        Per indexed level, from ``node_base[l]``: a min-heap of its empty ways.
    heap_size : ndarray of int64, shape (L,)
    """

    indexed: np.ndarray
    hash_base: np.ndarray
    hash_bits: np.ndarray
    entries: np.ndarray
    node_base: np.ndarray
    node_shift: np.ndarray
    older: np.ndarray
    newer: np.ndarray
    head: np.ndarray
    tail: np.ndarray
    heap: np.ndarray
    heap_size: np.ndarray


@njit(cache=True, inline="always")
def uses_index(geometry, n_accesses):
    """Whether a call of ``n_accesses`` runs on :func:`_simulate_indexed`: the
    hierarchy has a level of one set with at least :data:`INDEXED_MIN_WAYS`
    ways, and the stream has an access per :data:`WAYS_PER_ACCESS` of them
    (the index then costs less than the scans it saves)."""
    indexed_ways = 0
    for level in range(geometry.ways.shape[0]):
        if geometry.n_sets[level] == 1 and geometry.ways[level] >= INDEXED_MIN_WAYS:
            indexed_ways += geometry.ways[level]
    return indexed_ways > 0 and n_accesses * WAYS_PER_ACCESS >= indexed_ways


# ----------------------------------------------------------------- hash table
@njit(cache=True, inline="always")
def _home(index, level, line):
    shift = np.uint64(64 - index.hash_bits[level])
    return np.int64((np.uint64(line) * np.uint64(_GOLDEN)) >> shift)


@njit(cache=True, inline="always")
def _probe(index, level, line):
    """The entry of an indexed level's table (from its ``hash_base``) that
    holds ``line``, or the empty one where its probe chain ends."""
    entries = index.entries
    base = index.hash_base[level]
    mask = (np.int64(1) << index.hash_bits[level]) - 1
    entry = _home(index, level, line)
    while True:
        key = entries[np.uint64(2 * (base + entry))]
        if key == line or key < 0:
            return entry
        entry = (entry + 1) & mask


@njit(cache=True, inline="always")
def _hash_find(index, level, line):
    """The way holding ``line`` in an indexed level, or -1."""
    at = np.uint64(2 * (index.hash_base[level] + _probe(index, level, line)))
    return index.entries[at + np.uint64(1)] if index.entries[at] == line else np.int64(-1)


@njit(cache=True, inline="always")
def _hash_add(index, level, line, slot):
    """Add ``line`` (absent), held by way ``slot``."""
    at = 2 * (index.hash_base[level] + _probe(index, level, line))
    index.entries[at] = line
    index.entries[at + 1] = slot


@njit(cache=True, inline="always")
def _hash_remove(index, level, line):
    """Remove ``line`` (present) and shift back the entries of its probe chain that may move."""
    entries = index.entries
    base = index.hash_base[level]
    mask = (np.int64(1) << index.hash_bits[level]) - 1
    hole = _probe(index, level, line)
    entry = hole
    while True:
        entry = (entry + 1) & mask
        key = entries[2 * (base + entry)]
        if key < 0:
            break
        home = _home(index, level, key)
        # The entry may fill the hole unless its home lies cyclically in (hole, entry].
        if (entry - home) & mask >= (entry - hole) & mask:
            entries[2 * (base + hole)] = key
            entries[2 * (base + hole) + 1] = entries[2 * (base + entry) + 1]
            hole = entry
    entries[2 * (base + hole)] = -1


# ---------------------------------------------------------------- recency list
@njit(cache=True, inline="always")
def _unlink(index, level, slot):
    shift = index.node_shift[level]
    older = index.older[slot - shift]
    newer = index.newer[slot - shift]
    if older >= 0:
        index.newer[older - shift] = newer
    else:
        index.head[level] = newer
    if newer >= 0:
        index.older[newer - shift] = older
    else:
        index.tail[level] = older


@njit(cache=True, inline="always")
def _append(index, level, slot):
    shift = index.node_shift[level]
    last = index.tail[level]
    index.older[slot - shift] = last
    index.newer[slot - shift] = -1
    if last >= 0:
        index.newer[last - shift] = slot
    else:
        index.head[level] = slot
    index.tail[level] = slot


# ------------------------------------------------------------ empty-way heap
@njit(cache=True, inline="always")
def _heap_push(index, level, base, slot):
    heap = index.heap
    at = index.heap_size[level]
    index.heap_size[level] = at + 1
    while at > 0:
        parent = (at - 1) >> 1
        if heap[base + parent] <= slot:
            break
        heap[base + at] = heap[base + parent]
        at = parent
    heap[base + at] = slot


@njit(cache=True, inline="always")
def _heap_pop(index, level, base):
    heap = index.heap
    lowest = heap[base]
    size = index.heap_size[level] - 1
    index.heap_size[level] = size
    last = heap[base + size]
    at = 0
    while True:
        child = 2 * at + 1
        if child >= size:
            break
        if child + 1 < size and heap[base + child + 1] < heap[base + child]:
            child += 1
        if heap[base + child] >= last:
            break
        heap[base + at] = heap[base + child]
        at = child
    heap[base + at] = last
    return lowest


# ------------------------------------------------------------ level operations
class LevelOperations(NamedTuple):
    """The per-access walk's operations on the levels, in one of two forms (:func:`level_operations`).

    Each function takes an ``index`` argument: None in the scanning form, a
    :class:`FullIndex` in the indexed one. All are inlined into their callers.
    """

    lookup: object
    touch: object
    place: object
    serving_level: object
    fill_levels: object


def level_operations(indexed):
    """The level operations, written once, compiled with the index's code or without.

    Parameters
    ----------
    indexed : bool
        True: the operations take a :class:`FullIndex` and use it on its
        indexed levels (and scan the others); False: they take ``index``
        None and scan every level.

    Returns
    -------
    LevelOperations

    Numba's ``inline="always"`` copies a callee's code, and that of all it
    calls, into the caller before the caller's types are known; a branch
    that tests ``index`` against None is dropped only after that, so every
    kernel that inlined the operations without an index would copy in, and
    then discard, all of the index's code, at each place an operation is
    inlined (several times the compile time of the scans alone). ``indexed``
    is a constant of each form, whose branches numba drops before it copies
    their callees.
    """

    @njit(inline="always")
    def lookup(line, level, geometry, state, index):
        """The way of ``level`` holding ``line``, or -1."""
        if indexed and index.indexed[level]:
            return _hash_find(index, level, line)
        base = _set_base(line, level, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset)
        return _find(state.tags, base, geometry.ways[level], line)

    @njit(inline="always")
    def touch(slot, level, state, index, clock):
        """A hit in an LRU level: stamp the way (and in an indexed level make it the newest)."""
        state.stamps[slot] = clock
        if indexed and index.indexed[level] and index.tail[level] != slot:
            _unlink(index, level, slot)
            _append(index, level, slot)

    @njit(inline="always")
    def empty(slot, level, geometry, state, index):
        """Empty a way (a back-invalidation, or an exclusive line moving up); its stamp stays."""
        if indexed and index.indexed[level]:
            _hash_remove(index, level, state.tags[slot])
            if geometry.policy[level] != RANDOM:
                _unlink(index, level, slot)
            _heap_push(index, level, index.node_base[level], slot)
        state.tags[slot] = -1

    @njit(inline="always")
    def place(line, level, geometry, state, index, clock):
        """:func:`cachesim.sets._insert` for any level: the lowest empty way, else
        the random draw or the oldest stamp; returns the evicted line or -1."""
        if indexed and index.indexed[level]:
            ordered = geometry.policy[level] != RANDOM
            if index.heap_size[level] > 0:
                victim = _heap_pop(index, level, index.node_base[level])
            elif ordered:
                victim = index.head[level]
            else:
                victim = geometry.offset[level] + _random_way(geometry.seeds[level], clock, geometry.ways[level])
            evicted = state.tags[victim]
            if evicted >= 0:
                _hash_remove(index, level, evicted)
                if ordered:
                    _unlink(index, level, victim)
            state.tags[victim] = line
            state.stamps[victim] = clock
            _hash_add(index, level, line, victim)
            if ordered:
                _append(index, level, victim)
            return evicted
        base = _set_base(line, level, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset)
        return _insert(state.tags, state.stamps, geometry.seeds[level], base, geometry.ways[level],
                       geometry.policy[level], line, clock)

    @njit(inline="always")
    def back_invalidate(evicted, level, geometry, state, index, invalidations):
        """Inclusion: remove every line of the levels above ``level`` that lies in
        its ``evicted`` line, counting them in ``invalidations`` per level."""
        for upper in range(level):
            spread = geometry.rel_shift[level] - geometry.rel_shift[upper]
            first = evicted << spread
            for sub in range(first, first + (np.int64(1) << spread)):
                slot = lookup(sub, upper, geometry, state, index)
                if slot >= 0:
                    empty(slot, upper, geometry, state, index)
                    invalidations[upper] += 1

    @njit(inline="always")
    def serving_level(line0, first_level, geometry, state, index, clock, is_write, work):
        """Look ``line0`` up from ``first_level`` down; return the level that holds it (the number of levels: memory).

        Leaves each level's line in ``work.level_lines``, counts the hit in
        ``work.level_hits`` (and ``level_write_hits``), stamps an LRU hit and,
        in an exclusive hierarchy, takes the line out of the level that held it
        (it moves up). The walk of :mod:`cachesim.by_access` and, below its
        first two levels, of :mod:`cachesim.direct_first`; their kernels run
        without reference counting, so reading the bundles here costs nothing
        per access.
        """
        n_levels = geometry.rel_shift.shape[0]
        for level in range(first_level, n_levels):
            line = line0 >> geometry.rel_shift[level]
            work.level_lines[level] = line
            slot = lookup(line, level, geometry, state, index)
            if slot >= 0:
                work.level_hits[level] += 1
                if is_write:
                    work.level_write_hits[level] += 1
                if geometry.policy[level] == LRU:
                    touch(slot, level, state, index, clock)
                if geometry.inclusion == EXCLUSIVE:
                    empty(slot, level, geometry, state, index)  # the line moves up to the first level
                return level
        return n_levels

    @njit(inline="always")
    def fill_levels(served, last_level, geometry, state, index, clock, is_write, work):
        """Place the line of ``serving_level`` in levels ``served - 1`` down to ``last_level``.

        Bottom-up, so that back-invalidations of lower levels never remove the
        line just placed above them; a write skips the levels that do not
        allocate writes. Counts evictions, and in an inclusive hierarchy
        back-invalidates the levels above an evicted line.
        """
        tags = state.tags
        for level in range(served - 1, last_level - 1, -1):
            if is_write and not geometry.write_allocate[level]:
                continue
            line = work.level_lines[level]
            if geometry.ways[level] == 1:
                # Direct-mapped: no choice and no order to keep (no stamp).
                base = _set_base(line, level, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset)
                evicted = tags[base]
                tags[base] = line
            else:
                evicted = place(line, level, geometry, state, index, clock)
            if evicted >= 0:
                state.counts[level, EVICTIONS] += 1
                if geometry.inclusion == INCLUSIVE and level > 0:
                    back_invalidate(evicted, level, geometry, state, index, work.level_invalidations)

    return LevelOperations(lookup, touch, place, serving_level, fill_levels)


#: The operations for ``index`` None: the scans alone.
SCANNING = level_operations(False)
#: The operations for a :class:`FullIndex`.
INDEXED = level_operations(True)
_lookup, _touch, _place, _serving_level, _fill_levels = SCANNING


# ------------------------------------------------------------------- building
@njit(cache=True)
def build_index(geometry, state, clock):
    """The :class:`FullIndex` of ``state``'s indexed levels, and whether it is exact.

    Not exact (then the caller keeps the scans) when a filled way of an
    ordered level has a stamp after ``clock``: the list would not stay in
    stamp order as new stamps are appended.
    """
    n_levels = geometry.ways.shape[0]
    tags = state.tags
    stamps = state.stamps
    indexed = np.zeros(n_levels, dtype=np.bool_)
    hash_base = np.zeros(n_levels, dtype=np.int64)
    hash_bits = np.zeros(n_levels, dtype=np.int64)
    node_base = np.zeros(n_levels, dtype=np.int64)
    entries = 0
    nodes = 0
    for level in range(n_levels):
        if geometry.n_sets[level] == 1 and geometry.ways[level] >= INDEXED_MIN_WAYS:
            indexed[level] = True
            bits = 1
            while (np.int64(1) << bits) < 2 * geometry.ways[level]:
                bits += 1
            hash_base[level] = entries
            hash_bits[level] = bits
            entries += np.int64(1) << bits
            node_base[level] = nodes
            nodes += geometry.ways[level]
    index = FullIndex(indexed, hash_base, hash_bits, np.full(2 * entries, -1, dtype=np.int64), node_base,
                      geometry.offset - node_base, np.full(nodes, -1, dtype=np.int64),
                      np.full(nodes, -1, dtype=np.int64), np.full(n_levels, -1, dtype=np.int64),
                      np.full(n_levels, -1, dtype=np.int64), np.zeros(nodes, dtype=np.int64),
                      np.zeros(n_levels, dtype=np.int64))
    exact = True
    for level in range(n_levels):
        if not indexed[level]:
            continue
        base = geometry.offset[level]
        filled = np.zeros(geometry.ways[level], dtype=np.int64)
        n_filled = 0
        for slot in range(base, base + geometry.ways[level]):
            if tags[slot] >= 0:
                _hash_add(index, level, tags[slot], slot)
                filled[n_filled] = slot
                n_filled += 1
                if stamps[slot] > clock:
                    exact = False
            else:
                # Rising ways: a sorted array is a min-heap as it stands.
                index.heap[node_base[level] + index.heap_size[level]] = slot
                index.heap_size[level] += 1
        if geometry.policy[level] != RANDOM:
            filled = filled[:n_filled]
            for slot in filled[np.argsort(stamps[filled], kind="mergesort")]:
                _append(index, level, slot)
    return index, exact
