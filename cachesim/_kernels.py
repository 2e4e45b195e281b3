"""Compiled cache-simulation kernels. Arguments only: arrays and scalars.

State layout for one hierarchy of ``L`` levels (see :mod:`cachesim.state`):

- ``tags`` int64 (total_ways,): the line number held by each way, or -1.
  Level ``l`` owns ``tags[offset[l] : offset[l] + n_sets[l] * ways[l]]``;
  set ``s`` of that level is the ``ways[l]`` entries from
  ``offset[l] + s * ways[l]``.
- ``stamps`` int64 (total_ways,): the access clock of the last use (LRU) or
  of the fill (FIFO); unused for random replacement.
- ``rng`` uint64 (L,): xorshift64* state per level (random replacement).
- ``counts`` int64 (L, 5): accesses, hits, misses, evictions,
  back-invalidations per level.

Line numbers are byte addresses shifted right by the first level's line shift
(``shift0``), then by ``rel_shift[l]`` for level ``l``.
"""
import numpy as np
from numba import njit, prange

LRU, FIFO, RANDOM = 0, 1, 2
NON_INCLUSIVE, INCLUSIVE, EXCLUSIVE = 0, 1, 2
ACCESSES, HITS, MISSES, EVICTIONS, INVALIDATIONS = 0, 1, 2, 3, 4
N_COUNTERS = 5


@njit(cache=True, inline="always")
def _set_base(line, level, n_sets, set_mask, ways, offset):
    mask = set_mask[level]
    if mask >= 0:
        set_index = line & mask
    else:
        set_index = line % n_sets[level]
    return offset[level] + set_index * ways[level]


@njit(cache=True, inline="always")
def _find(tags, base, n_ways, line):
    for way in range(n_ways):
        if tags[base + way] == line:
            return base + way
    return -1


@njit(cache=True)
def _random_way(rng, level, n_ways):
    # xorshift64*: small, fast and reproducible from the level's seed. Kept
    # out of line: inlined, it slows every insert of the other policies.
    x = rng[level]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    rng[level] = x
    return np.int64((x * np.uint64(2685821657736338717)) % np.uint64(n_ways))


@njit(cache=True, inline="always")
def _insert(tags, stamps, rng, level, base, n_ways, policy, line, clock):
    """Place ``line`` in its set; return the evicted line or -1."""
    victim = base
    oldest = np.int64(9223372036854775807)
    full = True
    for way in range(n_ways):
        slot = base + way
        if tags[slot] < 0:
            victim = slot
            full = False
            break
        if stamps[slot] < oldest:
            oldest = stamps[slot]
            victim = slot
    if full and policy == RANDOM:
        victim = base + _random_way(rng, level, n_ways)
    evicted = tags[victim]
    tags[victim] = line
    stamps[victim] = clock
    return evicted


@njit(cache=True)
def _back_invalidate(tags, counts, level, evicted, rel_shift, n_sets, set_mask, ways, offset):
    """Remove every line of the levels above ``level`` that lies in ``evicted``."""
    for upper in range(level):
        spread = rel_shift[level] - rel_shift[upper]
        first = evicted << spread
        for line in range(first, first + (np.int64(1) << spread)):
            base = _set_base(line, upper, n_sets, set_mask, ways, offset)
            slot = _find(tags, base, ways[upper], line)
            if slot >= 0:
                tags[slot] = -1
                counts[upper, INVALIDATIONS] += 1


@njit(cache=True)
def simulate_stream(addresses, shift0, rel_shift, n_sets, set_mask, ways, policy, offset,
                    inclusion, tags, stamps, rng, counts, clock, served_by, record):
    """Run ``addresses`` (uint64, (N,)) through one hierarchy's state.

    Returns the clock after the last access. When ``record`` is true,
    ``served_by[i]`` receives the level that served access ``i`` (``L`` for
    memory).
    """
    n_levels = rel_shift.shape[0]
    lines = np.empty(n_levels, dtype=np.int64)
    # The first level serves most accesses: keep its geometry in scalars and
    # its counters local, and leave the general loop to the misses.
    mask0 = set_mask[0]
    n_sets0 = n_sets[0]
    ways0 = ways[0]
    track0 = policy[0] == LRU and ways0 > 1  # one way: nothing to order
    shift = np.uint64(shift0)
    previous = np.int64(-1)
    first_hits = np.int64(0)
    level_hits = np.zeros(n_levels, dtype=np.int64)
    for i in range(addresses.shape[0]):
        line0 = np.int64(addresses[i] >> shift)
        clock += 1
        if line0 == previous:
            # The previous access left this line in the first level as its
            # set's most recent entry; a repeat is a hit that changes nothing.
            first_hits += 1
            if record:
                served_by[i] = 0
            continue
        previous = line0
        base0 = (line0 & mask0 if mask0 >= 0 else line0 % n_sets0) * ways0
        slot = _find(tags, base0, ways0, line0)
        if slot >= 0:
            first_hits += 1
            if track0:
                stamps[slot] = clock
            if record:
                served_by[i] = 0
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
                if policy[level] == LRU:
                    stamps[slot] = clock
                served = level
                if inclusion == EXCLUSIVE:
                    tags[slot] = -1  # the line moves up to the first level
                break
        if record:
            served_by[i] = served
        if inclusion == EXCLUSIVE:
            line = line0
            for level in range(n_levels):
                base = _set_base(line, level, n_sets, set_mask, ways, offset)
                line = _insert(tags, stamps, rng, level, base, ways[level], policy[level], line, clock)
                if line < 0:
                    break
                counts[level, EVICTIONS] += 1
        else:
            # Fill bottom-up so that back-invalidations of lower levels never
            # remove the line just placed above them.
            for level in range(served - 1, -1, -1):
                base = _set_base(lines[level], level, n_sets, set_mask, ways, offset)
                evicted = _insert(tags, stamps, rng, level, base, ways[level], policy[level],
                                  lines[level], clock)
                if evicted >= 0:
                    counts[level, EVICTIONS] += 1
                    if inclusion == INCLUSIVE and level > 0:
                        _back_invalidate(tags, counts, level, evicted, rel_shift, n_sets,
                                         set_mask, ways, offset)
    # Only misses go down a level: accesses of level l + 1 are the misses of l.
    level_hits[0] = first_hits
    entering = np.int64(addresses.shape[0])
    for level in range(n_levels):
        counts[level, ACCESSES] += entering
        counts[level, HITS] += level_hits[level]
        counts[level, MISSES] += entering - level_hits[level]
        entering -= level_hits[level]
    return clock


@njit(cache=True, parallel=True)
def simulate_streams(addresses, starts, shift0, rel_shift, n_sets, set_mask, ways, policy,
                     offset, inclusion, tags, stamps, rng, counts, clocks, served_by, record):
    """Run stream ``s`` = ``addresses[starts[s]:starts[s+1]]`` on state row ``s``.

    ``tags``, ``stamps`` (S, total_ways), ``rng`` (S, L), ``counts`` (S, L, 5),
    ``clocks`` (S,). Streams are independent, so they run in parallel.
    """
    for stream in prange(starts.shape[0] - 1):
        start = starts[stream]
        stop = starts[stream + 1]
        out = served_by[start:stop] if record else served_by[:0]
        clocks[stream] = simulate_stream(
            addresses[start:stop], shift0, rel_shift, n_sets, set_mask, ways, policy, offset,
            inclusion, tags[stream], stamps[stream], rng[stream], counts[stream],
            clocks[stream], out, record)
