"""The general path: every access walks down the levels in turn.

It serves every inclusion policy and streams with writes. Semantics of a
write (``writes[i]`` true), level by level:

- a write that hits a level is served there like a read: it updates the
  line's recency under LRU (a write is a use), leaves FIFO order alone, and
  does not go further down (write-through traffic to the next level is not
  counted: the 21164's write buffer absorbs it and, in an inclusive
  hierarchy, the line is already there);
- a write that misses a level goes on to the next one, like a read miss;
- on the way back, the levels that missed are filled as for a read, except
  those whose ``write_allocate`` is false (the 21164 D-cache: write-through,
  read-allocate), which stay unchanged.

Dirty lines and write-backs are not modelled: an eviction costs nothing
extra whether the line was written or not.
"""
import numpy as np
from numba import njit

from cachesim.full import INDEXED, SCANNING, _hash_find, build_index
from cachesim.sets import EVICTIONS, EXCLUSIVE, LRU, _add_counts, _find, _zeroed_counts
from rtcommon.jit import NO_REFCOUNTS, NOT_INLINED


@njit(cache=True, inline="always")
def _simulate_by_access(addresses, writes, geometry, state, clock, served_by, record, work):
    """Run ``addresses`` (uint64, (N,)) through one state, one access at a time.

    ``writes`` is bool (N,), true where the access is a write, or (0,) for a
    stream of reads only; ``work`` (:class:`~cachesim.sets.ChunkBuffers`)
    lends its per-level buffers, so that a call allocates nothing. Other
    parameters and the returned clock are those of
    :func:`cachesim.kernels.simulate_stream`.
    """
    return _walk(addresses, writes, geometry, state, None, clock, served_by, record, work)


@njit(cache=True, **NOT_INLINED)
def _simulate_indexed(addresses, writes, geometry, state, clock, served_by, record, work):
    """:func:`_simulate_by_access` (same parameters, same results) with the
    large fully associative levels indexed (:mod:`cachesim.full`): O(1) an
    access there instead of O(ways), after O(ways log ways) to build the index."""
    index, exact = build_index(geometry, state, clock)
    if not exact:
        return _walk(addresses, writes, geometry, state, None, clock, served_by, record, work)
    return _walk(addresses, writes, geometry, state, index, clock, served_by, record, work)


@njit(cache=True, **NO_REFCOUNTS)
def _walk(addresses, writes, geometry, state, index, clock, served_by, record, work):
    """The loop of :func:`_simulate_by_access`; ``index`` is None or a
    :class:`cachesim.full.FullIndex` built for this call.

    The loop is written once (:func:`_walk_on`) on the level operations of
    :func:`cachesim.full.level_operations`, in their scanning form for
    ``index`` None and in their indexed form for an index: numba drops the
    branch not taken here, by the type of ``index``, before it inlines
    either, so the walk without an index compiles the scans alone.
    """
    if index is None:
        return _scanning_walk(addresses, writes, geometry, state, index, clock, served_by, record, work)
    return _indexed_walk(addresses, writes, geometry, state, index, clock, served_by, record, work)


def _walk_on(indexed):
    """The walk's loop (inlined) on the level operations :data:`cachesim.full.INDEXED`
    (``indexed`` true: ``index`` is a FullIndex) or :data:`cachesim.full.SCANNING` (``index`` None)."""
    # numba inlines a callee it finds in a global or a closure's variable, not in an attribute of one
    _, touch, place, serving_level, fill_levels = INDEXED if indexed else SCANNING

    @njit(inline="always")
    def walk(addresses, writes, geometry, state, index, clock, served_by, record, work):
        rel_shift = geometry.rel_shift
        n_sets = geometry.n_sets
        set_mask = geometry.set_mask
        ways = geometry.ways
        policy = geometry.policy
        write_allocate = geometry.write_allocate
        inclusion = geometry.inclusion
        tags = state.tags
        counts = state.counts
        n_levels = rel_shift.shape[0]
        has_writes = writes.shape[0] > 0
        lines = work.level_lines
        # The first level serves most accesses: keep its geometry in scalars and
        # its counters local, and leave the general loop to the misses.
        mask0 = set_mask[0]
        n_sets0 = n_sets[0]
        ways0 = ways[0]
        track0 = policy[0] == LRU and ways0 > 1  # one way: nothing to order
        first_indexed = indexed and index.indexed[0]
        allocate0 = write_allocate[0]
        shift = np.uint64(geometry.line_shift)
        previous = np.int64(-1)  # a line known to be in the first level as its set's most recent
        first_hits = np.int64(0)
        first_write_hits = np.int64(0)
        n_writes = np.int64(0)
        level_hits, level_write_hits, invalidations = _zeroed_counts(work, n_levels)
        for i in range(addresses.shape[0]):
            line0 = np.int64(addresses[i] >> shift)
            clock += 1
            is_write = False
            if has_writes and writes[i]:
                is_write = True
                n_writes += 1
            if line0 == previous:
                # A repeat of a line the previous access left in the first level
                # as its set's most recent entry: a hit that changes nothing.
                first_hits += 1
                if is_write:
                    first_write_hits += 1
                if record:
                    served_by[i] = 0
                continue
            if indexed and first_indexed:
                slot = _hash_find(index, 0, line0)
            else:
                base0 = (line0 & mask0 if mask0 >= 0 else line0 % n_sets0) * ways0
                slot = _find(tags, base0, ways0, line0)
            if slot >= 0:
                first_hits += 1
                if is_write:
                    first_write_hits += 1
                if track0:
                    touch(slot, 0, state, index, clock)
                if record:
                    served_by[i] = 0
                previous = line0
                continue
            lines[0] = line0
            served = serving_level(line0, 1, geometry, state, index, clock, is_write, work)
            if record:
                served_by[i] = served
            if inclusion == EXCLUSIVE:
                # Exclusive hierarchies allocate writes everywhere (checked by
                # Hierarchy), so a write moves lines as a read does.
                line = line0
                for level in range(n_levels):
                    line = place(line, level, geometry, state, index, clock)
                    if line < 0:
                        break
                    counts[level, EVICTIONS] += 1
                previous = line0
                continue
            fill_levels(served, 0, geometry, state, index, clock, is_write, work)
            previous = line0 if (allocate0 or not is_write) else np.int64(-1)
        level_hits[0] = first_hits
        level_write_hits[0] = first_write_hits
        _add_counts(counts, addresses.shape[0], n_writes, level_hits, level_write_hits, invalidations)
        return clock

    return walk


_scanning_walk = _walk_on(False)
_indexed_walk = _walk_on(True)
