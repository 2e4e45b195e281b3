"""Compiled cache-simulation kernels: the public entry points for compiled code.

Python callers use :func:`cachesim.simulate` and :class:`cachesim.CacheState`.
Other packages' ``@njit`` code that feeds many short streams to one state (a
schedule simulation replaying one pixel's reads at a time, say) calls these
kernels directly:

- :func:`simulate_stream` runs an address array through one state;
- :func:`simulate_into` does the same with caller-owned work buffers
  (:class:`ChunkBuffers`, from :func:`chunk_buffers`), so that a loop over
  many short streams allocates nothing;
- :func:`simulate_streams` runs independent streams on stacked states in
  parallel.

Each takes the hierarchy's :class:`CacheGeometry` (from
:attr:`CacheState.geometry <cachesim.CacheState.geometry>`) and its
:class:`CacheArrays` (from :attr:`CacheState.arrays
<cachesim.CacheState.arrays>`), and returns the access clock after the call,
to be passed to the next one.

State layout of one hierarchy of ``L`` levels (:class:`CacheArrays`):

- ``tags`` int64 (W,): the line number held by each way, or -1.
  Level ``l`` owns ``tags[offset[l] : offset[l] + n_sets[l] * ways[l]]``;
  set ``s`` of that level is the ``ways[l]`` entries from
  ``offset[l] + s * ways[l]``.
- ``stamps`` int64 (W,): the access clock of the last use (LRU) or
  of the fill (FIFO); unused for random replacement.
- ``counts`` int64 (L, N_COUNTERS): columns :data:`ACCESSES`, :data:`HITS`,
  :data:`MISSES`, :data:`EVICTIONS`, :data:`INVALIDATIONS` per level.

Line numbers are byte addresses shifted right by the first level's line shift
(``CacheGeometry.line_shift``), then by ``rel_shift[l]`` for level ``l``.
"""
from typing import NamedTuple

import numpy as np
from numba import njit, prange

# Replacement policies (CacheGeometry.policy).
LRU, FIFO, RANDOM = 0, 1, 2
# Inclusion policies (CacheGeometry.inclusion).
NON_INCLUSIVE, INCLUSIVE, EXCLUSIVE = 0, 1, 2
# Counter columns of CacheArrays.counts.
ACCESSES, HITS, MISSES, EVICTIONS, INVALIDATIONS = 0, 1, 2, 3, 4
N_COUNTERS = 5
# The level that served an access, in served_by, is its index; memory is L.

# Accesses handled per chunk by the level-by-level path: the chunk's two
# buffers (256 KB) stay in the host's second-level cache.
CHUNK = 16384


class CacheGeometry(NamedTuple):
    """A hierarchy's fixed parameters, as the kernels read them.

    Attributes
    ----------
    line_shift : int
        log2 of the first level's line size: byte address to line number.
    rel_shift : ndarray of int64, shape (L,)
        log2 of each level's line size relative to the first level's.
    n_sets : ndarray of int64, shape (L,)
        Sets per level (any count, not only powers of two).
    set_mask : ndarray of int64, shape (L,)
        ``n_sets - 1`` where it is a power of two, else -1 (use a modulo).
    ways : ndarray of int64, shape (L,)
        Associativity per level.
    policy : ndarray of int64, shape (L,)
        :data:`LRU`, :data:`FIFO` or :data:`RANDOM` per level.
    offset : ndarray of int64, shape (L,)
        First way of each level in the state arrays.
    inclusion : int
        :data:`NON_INCLUSIVE`, :data:`INCLUSIVE` or :data:`EXCLUSIVE`.
    seeds : ndarray of uint64, shape (L,)
        Per-level seed of random replacement, whose victim is a hash of the
        seed and the access clock (no generator state).
    """

    line_shift: int
    rel_shift: np.ndarray
    n_sets: np.ndarray
    set_mask: np.ndarray
    ways: np.ndarray
    policy: np.ndarray
    offset: np.ndarray
    inclusion: int
    seeds: np.ndarray


class CacheArrays(NamedTuple):
    """The mutable contents and counters of a hierarchy (updated in place).

    Attributes
    ----------
    tags : ndarray of int64, shape (W,) or (S, W)
        Line held by each way, or -1; ``W`` is the total ways of all levels.
    stamps : ndarray of int64, shape (W,) or (S, W)
        Access clock of the last use (LRU) or fill (FIFO) of each way.
    counts : ndarray of int64, shape (L, N_COUNTERS) or (S, L, N_COUNTERS)
        Cumulative counters per level (columns :data:`ACCESSES` ...).

    The stacked shapes hold ``S`` independent states, for
    :func:`simulate_streams`.
    """

    tags: np.ndarray
    stamps: np.ndarray
    counts: np.ndarray


class ChunkBuffers(NamedTuple):
    """Work buffers of :func:`simulate_into`.

    Attributes
    ----------
    lines, clocks : ndarray of int64, shape (CHUNK,)
        A chunk's line numbers and their access clocks.
    """

    lines: np.ndarray
    clocks: np.ndarray


@njit(cache=True)
def chunk_buffers():
    """Fresh :class:`ChunkBuffers` (also callable from compiled code)."""
    return ChunkBuffers(np.empty(CHUNK, dtype=np.int64), np.empty(CHUNK, dtype=np.int64))


# The helpers below take the geometry's arrays, not the bundle: a field read
# from a bundle inside a per-access loop costs a reference-count update each
# time, so the kernels unpack their bundles once, on entry.
@njit(cache=True, inline="always")
def _set_base(line, level, n_sets, set_mask, ways, offset):
    """First way of the set of ``line`` in ``level``."""
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


@njit(cache=True, inline="always")
def _random_way(seed, clock, n_ways):
    # A stateless draw: a strong 64-bit mix (splitmix64 finaliser) of the
    # access clock and the level's seed, reduced to [0, n_ways) by a
    # multiply-shift on its top 32 bits. No state to write and no division
    # keeps the other policies' inserts fast; the clock makes it a fresh
    # draw at every access and reproducible after copy or continuation.
    x = np.uint64(clock) ^ seed
    x ^= x >> np.uint64(30)
    x *= np.uint64(0xBF58476D1CE4E5B9)
    x ^= x >> np.uint64(27)
    x *= np.uint64(0x94D049BB133111EB)
    x ^= x >> np.uint64(31)
    return np.int64(((x >> np.uint64(32)) * np.uint64(n_ways)) >> np.uint64(32))


@njit(cache=True, inline="always")
def _insert(tags, stamps, seed, base, n_ways, policy, line, clock):
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
        victim = base + _random_way(seed, clock, n_ways)
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
def simulate_stream(addresses, geometry, state, clock, served_by, record):
    """Run a stream of byte addresses through one hierarchy's state.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
        Byte addresses in access order.
    geometry : CacheGeometry
    state : CacheArrays
        One state (unstacked shapes); updated in place.
    clock : int
        Access clock before the call (0 for a fresh state).
    served_by : ndarray of uint8, shape (N,) or (0,)
        When ``record`` is true, receives the level that served each access
        (``L`` for memory).
    record : bool

    Returns
    -------
    int
        The clock after the last access.
    """
    return simulate_into(addresses, geometry, state, clock, served_by, record, chunk_buffers())


@njit(cache=True)
def simulate_into(addresses, geometry, state, clock, served_by, record, work):
    """:func:`simulate_stream` with caller-owned work buffers.

    Parameters are those of :func:`simulate_stream`, plus ``work``
    (:class:`ChunkBuffers`), reused across calls: the entry point for other
    packages' compiled code that feeds many short streams (one pixel's reads,
    say) to one state. Both paths below give identical states and counts for
    a non-inclusive hierarchy; the level-by-level one is faster.
    """
    if geometry.inclusion == NON_INCLUSIVE:
        return _simulate_by_level(addresses, geometry, state, clock, served_by, record, work)
    return _simulate_by_access(addresses, geometry, state, clock, served_by, record)


@njit(cache=True)
def _level_pass(lines, clocks, n_in, level, shift, geometry, state, served_by, record, first_clock):
    """Run ``lines[:n_in]`` (with their access clocks) through one level.

    The misses are compacted in place to the front of ``lines`` and
    ``clocks`` (shifted to the next level's line size by ``shift``);
    returns their number. In a non-inclusive hierarchy a level's contents
    depend only on the accesses that reach it, so each level can run on the
    misses of the one above, in order.
    """
    tags = state.tags
    stamps = state.stamps
    n_ways = geometry.ways[level]
    mask = geometry.set_mask[level]
    sets = geometry.n_sets[level]
    base0 = geometry.offset[level]
    level_policy = geometry.policy[level]
    seed = geometry.seeds[level]
    lru = level_policy == LRU
    n_out = 0
    evictions = 0
    if n_ways == 1:
        # Direct-mapped: one compare, no ordering to keep.
        for j in range(n_in):
            line = lines[j]
            slot = base0 + (line & mask if mask >= 0 else line % sets)
            held = tags[slot]
            miss = held != line
            evictions += miss & (held >= 0)
            tags[slot] = line
            lines[n_out] = line >> shift
            clocks[n_out] = clocks[j]
            n_out += miss
            if record and miss:
                served_by[clocks[j] - first_clock] = level + 1
    elif level_policy != RANDOM:
        # LRU and FIFO: one pass over the set finds the line and the victim
        # (the first empty way, else the oldest stamp) without early exits,
        # which the host's branch predictor handles far better.
        for j in range(n_in):
            line = lines[j]
            clock = clocks[j]
            base = base0 + (line & mask if mask >= 0 else line % sets) * n_ways
            hit = -1
            victim = base
            oldest = np.int64(9223372036854775807)
            for slot in range(base, base + n_ways):
                held = tags[slot]
                hit = slot if held == line else hit
                age = stamps[slot] if held >= 0 else np.int64(-1)
                if age < oldest:
                    oldest = age
                    victim = slot
            # Hit or miss, write the same way: the hit way keeps its line
            # (and, under FIFO, its stamp); the victim takes the new line.
            miss = hit < 0
            target = victim if miss else hit
            evictions += miss & (tags[target] >= 0)
            tags[target] = line
            stamps[target] = clock if (miss or lru) else stamps[target]
            lines[n_out] = line >> shift
            clocks[n_out] = clock
            n_out += miss
            if record and miss:
                served_by[clock - first_clock] = level + 1
    else:
        for j in range(n_in):
            line = lines[j]
            base = base0 + (line & mask if mask >= 0 else line % sets) * n_ways
            slot = _find(tags, base, n_ways, line)
            if slot >= 0:
                if lru:
                    stamps[slot] = clocks[j]
                continue
            if _insert(tags, stamps, seed, base, n_ways, level_policy, line, clocks[j]) >= 0:
                evictions += 1
            lines[n_out] = line >> shift
            clocks[n_out] = clocks[j]
            n_out += 1
            if record:
                served_by[clocks[j] - first_clock] = level + 1
    counts = state.counts
    counts[level, ACCESSES] += n_in
    counts[level, HITS] += n_in - n_out
    counts[level, MISSES] += n_out
    counts[level, EVICTIONS] += evictions
    return n_out


@njit(cache=True)
def _simulate_by_level(addresses, geometry, state, clock, served_by, record, work):
    """Non-inclusive hierarchy: each chunk runs through level 0, its misses
    through level 1, and so on. Clocks are the global access clock, so stamps
    and random draws are those of :func:`_simulate_by_access`."""
    rel_shift = geometry.rel_shift
    counts = state.counts
    lines = work.lines
    clocks = work.clocks
    n_levels = rel_shift.shape[0]
    n = addresses.shape[0]
    shifts = np.zeros(n_levels, dtype=np.int64)
    for level in range(n_levels - 1):
        shifts[level] = rel_shift[level + 1] - rel_shift[level]
    shift = np.uint64(geometry.line_shift)
    previous = np.int64(-1)
    chunk = lines.shape[0]
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        # Collapse repeats of the previous line: the previous access left it
        # in level 0 as its set's most recent entry, so a repeat is a hit
        # that changes nothing.
        kept = 0
        for i in range(start, stop):
            line = np.int64(addresses[i] >> shift)
            lines[kept] = line
            clocks[kept] = clock + 1 + i
            kept += line != previous
            previous = line
        counts[0, ACCESSES] += (stop - start) - kept
        counts[0, HITS] += (stop - start) - kept
        if record:
            served_by[start:stop] = 0
        first_clock = clock + 1
        for level in range(n_levels):
            if kept == 0:
                break
            kept = _level_pass(lines, clocks, kept, level, shifts[level], geometry, state, served_by,
                               record, first_clock)
    return clock + n


@njit(cache=True)
def _simulate_by_access(addresses, geometry, state, clock, served_by, record):
    """Any inclusion policy: every access walks down the levels in turn."""
    rel_shift = geometry.rel_shift
    n_sets = geometry.n_sets
    set_mask = geometry.set_mask
    ways = geometry.ways
    policy = geometry.policy
    offset = geometry.offset
    seeds = geometry.seeds
    inclusion = geometry.inclusion
    tags = state.tags
    stamps = state.stamps
    counts = state.counts
    n_levels = rel_shift.shape[0]
    lines = np.empty(n_levels, dtype=np.int64)
    # The first level serves most accesses: keep its geometry in scalars and
    # its counters local, and leave the general loop to the misses.
    mask0 = set_mask[0]
    n_sets0 = n_sets[0]
    ways0 = ways[0]
    track0 = policy[0] == LRU and ways0 > 1  # one way: nothing to order
    shift = np.uint64(geometry.line_shift)
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
                line = _insert(tags, stamps, seeds[level], base, ways[level], policy[level], line, clock)
                if line < 0:
                    break
                counts[level, EVICTIONS] += 1
        else:
            # Fill bottom-up so that back-invalidations of lower levels never
            # remove the line just placed above them.
            for level in range(served - 1, -1, -1):
                base = _set_base(lines[level], level, n_sets, set_mask, ways, offset)
                evicted = _insert(tags, stamps, seeds[level], base, ways[level], policy[level],
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
def simulate_streams(addresses, starts, geometry, states, clocks, served_by, record):
    """Run stream ``s`` = ``addresses[starts[s]:starts[s+1]]`` on state ``s``.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
        The streams one after another.
    starts : ndarray of int64, shape (S + 1,)
        Where each stream starts, and the end.
    geometry : CacheGeometry
    states : CacheArrays
        ``S`` stacked states (shapes (S, W) and (S, L, N_COUNTERS)).
    clocks : ndarray of int64, shape (S,)
        Each state's clock; updated in place.
    served_by : ndarray of uint8, shape (N,) or (0,)
    record : bool

    Streams are independent, so they run in parallel.
    """
    for stream in prange(starts.shape[0] - 1):
        start = starts[stream]
        stop = starts[stream + 1]
        out = served_by[start:stop] if record else served_by[:0]
        state = CacheArrays(states.tags[stream], states.stamps[stream], states.counts[stream])
        clocks[stream] = simulate_stream(addresses[start:stop], geometry, state, clocks[stream], out, record)
