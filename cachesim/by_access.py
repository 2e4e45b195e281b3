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

from cachesim.sets import EVICTIONS, EXCLUSIVE, INCLUSIVE, LRU, _add_counts, _back_invalidate, _find, _insert, _set_base
from rtcommon.jit import NO_REFCOUNTS


@njit(cache=True, **NO_REFCOUNTS)
def _simulate_by_access(addresses, writes, geometry, state, clock, served_by, record, work):
    """Run ``addresses`` (uint64, (N,)) through one state, one access at a time.

    ``writes`` is bool (N,), true where the access is a write, or (0,) for a
    stream of reads only; ``work`` (:class:`~cachesim.sets.ChunkBuffers`)
    lends its per-level buffers, so that a call allocates nothing. Other
    parameters and the returned clock are those of
    :func:`cachesim.kernels.simulate_stream`.
    """
    rel_shift = geometry.rel_shift
    n_sets = geometry.n_sets
    set_mask = geometry.set_mask
    ways = geometry.ways
    policy = geometry.policy
    offset = geometry.offset
    seeds = geometry.seeds
    write_allocate = geometry.write_allocate
    inclusion = geometry.inclusion
    tags = state.tags
    stamps = state.stamps
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
    allocate0 = write_allocate[0]
    shift = np.uint64(geometry.line_shift)
    previous = np.int64(-1)  # a line known to be in the first level as its set's most recent
    first_hits = np.int64(0)
    first_write_hits = np.int64(0)
    n_writes = np.int64(0)
    level_hits = work.level_hits
    level_write_hits = work.level_write_hits
    invalidations = work.level_invalidations
    level_hits[:n_levels] = 0
    level_write_hits[:n_levels] = 0
    invalidations[:n_levels] = 0
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
        base0 = (line0 & mask0 if mask0 >= 0 else line0 % n_sets0) * ways0
        slot = _find(tags, base0, ways0, line0)
        if slot >= 0:
            first_hits += 1
            if is_write:
                first_write_hits += 1
            if track0:
                stamps[slot] = clock
            if record:
                served_by[i] = 0
            previous = line0
            continue
        lines[0] = line0
        served = n_levels
        for level in range(1, n_levels):
            line = line0 >> rel_shift[level]
            lines[level] = line
            base = _set_base(line, level, n_sets, set_mask, ways, offset)
            slot = _find(tags, base, ways[level], line)
            if slot >= 0:
                level_hits[level] += 1
                if is_write:
                    level_write_hits[level] += 1
                if policy[level] == LRU:
                    stamps[slot] = clock
                served = level
                if inclusion == EXCLUSIVE:
                    tags[slot] = -1  # the line moves up to the first level
                break
        if record:
            served_by[i] = served
        if inclusion == EXCLUSIVE:
            # Exclusive hierarchies allocate writes everywhere (checked by
            # Hierarchy), so a write moves lines as a read does.
            line = line0
            for level in range(n_levels):
                base = _set_base(line, level, n_sets, set_mask, ways, offset)
                line = _insert(tags, stamps, seeds[level], base, ways[level], policy[level], line, clock)
                if line < 0:
                    break
                counts[level, EVICTIONS] += 1
            previous = line0
            continue
        # Fill bottom-up so that back-invalidations of lower levels never
        # remove the line just placed above them.
        for level in range(served - 1, -1, -1):
            if is_write and not write_allocate[level]:
                continue
            base = _set_base(lines[level], level, n_sets, set_mask, ways, offset)
            if ways[level] == 1:
                # Direct-mapped: no choice and no order to keep (no stamp).
                evicted = tags[base]
                tags[base] = lines[level]
            else:
                evicted = _insert(tags, stamps, seeds[level], base, ways[level], policy[level], lines[level],
                                  clock)
            if evicted >= 0:
                counts[level, EVICTIONS] += 1
                if inclusion == INCLUSIVE and level > 0:
                    _back_invalidate(tags, evicted, level, rel_shift, set_mask, n_sets, ways, offset, invalidations)
        previous = line0 if (allocate0 or not is_write) else np.int64(-1)
    level_hits[0] = first_hits
    level_write_hits[0] = first_write_hits
    _add_counts(counts, addresses.shape[0], n_writes, level_hits, level_write_hits, invalidations)
    return clock
