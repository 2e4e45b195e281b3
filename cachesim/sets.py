"""Shared pieces of the compiled cache kernels: constants, bundles, set helpers.

:mod:`cachesim.kernels` is the public face (it re-exports everything here);
:mod:`cachesim.by_level` and :mod:`cachesim.by_access` hold the two
simulation paths. See :mod:`cachesim.kernels` for the state layout.
"""
from typing import NamedTuple

import numpy as np
from numba import njit

# Replacement policies (CacheGeometry.policy).
LRU, FIFO, RANDOM = 0, 1, 2
# Inclusion policies (CacheGeometry.inclusion).
NON_INCLUSIVE, INCLUSIVE, EXCLUSIVE = 0, 1, 2
# Counter columns of CacheArrays.counts. ACCESSES, HITS and MISSES count
# reads and writes together; WRITES, WRITE_HITS and WRITE_MISSES the writes
# among them (reads are the difference).
ACCESSES, HITS, MISSES, EVICTIONS, INVALIDATIONS = 0, 1, 2, 3, 4
WRITES, WRITE_HITS, WRITE_MISSES = 5, 6, 7
N_COUNTERS = 8
# The level that served an access, in served_by, is its index; memory is L.

# Accesses handled per chunk by the level-by-level path: the chunk's two
# buffers (256 KB) stay in the host's second-level cache.
CHUNK = 16384
# Levels a hierarchy may have (the per-level work buffers' length).
MAX_LEVELS = 8


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
    write_allocate : ndarray of bool, shape (L,)
        Whether a write miss fills the level (False: the write passes on to
        the next level and leaves this one unchanged).
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
    write_allocate: np.ndarray


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
    """Work buffers of the simulation kernels, reused across calls.

    A caller that feeds many short streams (one pixel's reads) to one state
    passes the same buffers each time, so that no call allocates.

    Attributes
    ----------
    lines, clocks : ndarray of int64, shape (CHUNK,)
        A chunk's line numbers and their access clocks (level-by-level path).
    level_lines : ndarray of int64, shape (MAX_LEVELS,)
        One access's line number at each level (per-access path).
    level_hits, level_write_hits, level_invalidations : ndarray of int64, shape (MAX_LEVELS,)
        A call's counts per level before they are added to the state's
        counters (per-access path).
    level_shifts : ndarray of int64, shape (MAX_LEVELS,)
        Line shift from each level to the next (level-by-level path).
    """

    lines: np.ndarray
    clocks: np.ndarray
    level_lines: np.ndarray
    level_hits: np.ndarray
    level_write_hits: np.ndarray
    level_invalidations: np.ndarray
    level_shifts: np.ndarray


@njit(cache=True)
def chunk_buffers():
    """Fresh :class:`ChunkBuffers` (also callable from compiled code)."""
    return ChunkBuffers(np.empty(CHUNK, dtype=np.int64), np.empty(CHUNK, dtype=np.int64),
                        np.empty(MAX_LEVELS, dtype=np.int64), np.empty(MAX_LEVELS, dtype=np.int64),
                        np.empty(MAX_LEVELS, dtype=np.int64), np.empty(MAX_LEVELS, dtype=np.int64),
                        np.empty(MAX_LEVELS, dtype=np.int64))


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


@njit(cache=True, inline="always")
def _zeroed_counts(work, n_levels):
    """``work``'s per-level hits, write hits and invalidations, zeroed for ``n_levels`` levels, to
    count one call of a per-access walk before :func:`_add_counts` adds them up."""
    work.level_hits[:n_levels] = 0
    work.level_write_hits[:n_levels] = 0
    work.level_invalidations[:n_levels] = 0
    return work.level_hits, work.level_write_hits, work.level_invalidations


@njit(cache=True, inline="always")
def _add_counts(counts, n_accesses, n_writes, level_hits, level_write_hits, invalidations):
    """Add one call's per-level hits, write hits and invalidations to
    ``counts``: only misses go down a level, so the accesses of level
    ``l + 1`` are the misses of ``l``, for reads and writes alike."""
    entering = np.int64(n_accesses)
    entering_writes = np.int64(n_writes)
    for level in range(counts.shape[0]):
        counts[level, ACCESSES] += entering
        counts[level, HITS] += level_hits[level]
        counts[level, MISSES] += entering - level_hits[level]
        counts[level, WRITES] += entering_writes
        counts[level, WRITE_HITS] += level_write_hits[level]
        counts[level, WRITE_MISSES] += entering_writes - level_write_hits[level]
        counts[level, INVALIDATIONS] += invalidations[level]
        entering -= level_hits[level]
        entering_writes -= level_write_hits[level]
