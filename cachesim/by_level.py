"""The fast path for read-only streams through non-inclusive hierarchies.

In a non-inclusive hierarchy a level's contents depend only on the accesses
that reach it, so a chunk of accesses runs through level 0, its misses through
level 1, and so on. Streams with writes and inclusive or exclusive
hierarchies take :mod:`cachesim.by_access` instead.
"""
import numpy as np
from numba import njit

from cachesim.sets import ACCESSES, EVICTIONS, HITS, LRU, MISSES, RANDOM, _find, _insert
from rtcommon.jit import NO_REFCOUNTS


@njit(cache=True, inline="always")
def _search_ways(tags, stamps, base, n_ways, line):
    """The way of set ``base`` holding ``line`` (or -1), and the victim: the
    first empty way, else the one with the oldest stamp."""
    hit = np.int64(-1)
    victim = base
    oldest = np.int64(9223372036854775807)
    for slot in range(base, base + n_ways):
        held = tags[np.uint64(slot)]
        hit = slot if held == line else hit
        age = stamps[np.uint64(slot)] if held >= 0 else np.int64(-1)
        if age < oldest:
            oldest = age
            victim = slot
    return hit, victim


@njit(cache=True, inline="always")
def _search_three_ways(tags, stamps, base, line):
    """:func:`_search_ways` for three ways (the 21164's S-cache), unrolled and
    free of branches: each choice is a mask (all ones or zero) from a sign
    shift. An empty way's age is -1 (its tag's sign), and ties go to the
    lower way, as in :func:`_search_ways`. The comparisons subtract ages:
    stamps are access clocks, far from the 2**63 apart that would wrap."""
    first = np.uint64(base)
    held0 = tags[first]
    held1 = tags[first + np.uint64(1)]
    held2 = tags[first + np.uint64(2)]
    age0 = stamps[first] | (held0 >> 63)
    age1 = stamps[first + np.uint64(1)] | (held1 >> 63)
    age2 = stamps[first + np.uint64(2)] | (held2 >> 63)
    younger0 = (age1 - age0) >> 63  # all ones when way 1 is older than way 0
    oldest01 = age0 ^ ((age0 ^ age1) & younger0)
    victim = younger0 & 1
    older2 = (age2 - oldest01) >> 63
    victim = victim ^ ((victim ^ 2) & older2)
    found1 = np.int64(held1 == line)
    found2 = np.int64(held2 == line)
    found = np.int64(held0 == line) | found1 | found2
    hit = (base + found1 + 2 * found2) | (found - 1)
    return hit, base + victim


@njit(cache=True, inline="always")
def _ordered_pass(lines, clocks, n_in, level, shift, geometry, state, three_ways):
    """The loop of :func:`_level_pass` for LRU and FIFO levels; returns the
    misses (compacted as there) and the evictions.

    One pass over the set finds the line and the victim (the first empty
    way, else the oldest stamp) without early exits, which the host's branch
    predictor handles far better. A repeat of the line just looked up (a
    quarter of the second level's accesses when its lines are twice the
    first's) hits the way it left, since nothing else touches this level
    meanwhile. It takes no branch, which would mispredict on a quarter of
    the accesses: its search goes to the level's first set, whose result is
    discarded, rather than to its own, whose loads would wait on the stores
    just made. ``three_ways`` (a constant at each call, for a three-way level
    whose sets are a power of two) selects the unrolled search; each copy of
    the loop then has few enough live values to keep them in registers.
    """
    tags = state.tags
    stamps = state.stamps
    n_ways = 3 if three_ways else geometry.ways[level]
    mask = geometry.set_mask[level]
    sets = geometry.n_sets[level]
    base0 = geometry.offset[level]
    lru = geometry.policy[level] == LRU
    n_out = 0
    evictions = 0
    previous = np.int64(-1)
    previous_slot = np.int64(0)
    for j in range(n_in):
        at = np.uint64(j)
        line = lines[at]
        clock = clocks[at]
        repeat = -np.int64(line == previous)
        if three_ways:
            base = (base0 + (line & mask) * 3) & ~repeat | (base0 & repeat)
            hit, victim = _search_three_ways(tags, stamps, base, line)
        else:
            base = (base0 + (line & mask if mask >= 0 else line % sets) * n_ways) & ~repeat | (base0 & repeat)
            hit, victim = _search_ways(tags, stamps, base, n_ways, line)
        hit = hit ^ ((hit ^ previous_slot) & repeat)
        miss = hit < 0
        target = np.uint64(victim if miss else hit)
        evictions += miss & (tags[target] >= 0)
        tags[target] = line
        stamps[target] = clock if (lru or miss) else stamps[target]
        lines[np.uint64(n_out)] = line >> shift
        clocks[np.uint64(n_out)] = clock
        n_out += miss
        previous = line
        previous_slot = np.int64(target)
    return n_out, evictions


@njit(cache=True, inline="always")
def _direct_pass(lines, clocks, n_in, level, shift, geometry, state, compact):
    """The loop of :func:`_level_pass` for a direct-mapped level: one compare,
    no ordering to keep; returns the misses and the evictions. The misses are
    compacted as there only when ``compact`` (a constant at each call)."""
    tags = state.tags
    mask = geometry.set_mask[level]
    sets = geometry.n_sets[level]
    base0 = geometry.offset[level]
    n_out = 0
    evictions = 0
    for j in range(n_in):
        at = np.uint64(j)
        line = lines[at]
        slot = np.uint64(base0 + (line & mask if mask >= 0 else line % sets))
        held = tags[slot]
        miss = held != line
        evictions += miss & (held >= 0)
        tags[slot] = line
        if compact:
            lines[np.uint64(n_out)] = line >> shift
            clocks[np.uint64(n_out)] = clocks[at]
        n_out += miss
    return n_out, evictions


@njit(cache=True, inline="always")
def _level_pass(lines, clocks, n_in, level, shift, geometry, state, served_by, record, first_clock):
    """Run ``lines[:n_in]`` (with their access clocks) through one level.

    The misses are compacted in place to the front of ``lines`` and
    ``clocks`` (shifted to the next level's line size by ``shift``);
    returns their number. In a non-inclusive hierarchy a level's contents
    depend only on the accesses that reach it, so each level can run on the
    misses of the one above, in order. The loops index with unsigned
    integers: numba fixes up every signed index that might be negative
    (7-17% of this pass on the benchmark's streams). Inlined into
    :func:`_simulate_by_level`, which runs without reference counting: a
    schedule replays one pixel at a time, and a call per level and pixel
    that passed the bundles cost 8% of bench_study.
    """
    tags = state.tags
    stamps = state.stamps
    n_ways = geometry.ways[level]
    mask = geometry.set_mask[level]
    sets = geometry.n_sets[level]
    base0 = geometry.offset[level]
    level_policy = geometry.policy[level]
    seed = geometry.seeds[level]
    n_out = 0
    evictions = 0
    if n_ways == 1:
        # Direct-mapped (see _direct_pass). The last level's misses go to
        # memory, and without served_by nothing reads them: only counted.
        if level == geometry.rel_shift.shape[0] - 1 and not record:
            n_out, evictions = _direct_pass(lines, clocks, n_in, level, shift, geometry, state, False)
        else:
            n_out, evictions = _direct_pass(lines, clocks, n_in, level, shift, geometry, state, True)
    elif level_policy != RANDOM:
        # LRU and FIFO (see _ordered_pass).
        if n_ways == 3 and mask >= 0:
            n_out, evictions = _ordered_pass(lines, clocks, n_in, level, shift, geometry, state, True)
        else:
            n_out, evictions = _ordered_pass(lines, clocks, n_in, level, shift, geometry, state, False)
    else:
        for j in range(n_in):
            line = lines[j]
            base = base0 + (line & mask if mask >= 0 else line % sets) * n_ways
            if _find(tags, base, n_ways, line) >= 0:  # random replacement keeps no recency
                continue
            if _insert(tags, stamps, seed, base, n_ways, level_policy, line, clocks[j]) >= 0:
                evictions += 1
            lines[n_out] = line >> shift
            clocks[n_out] = clocks[j]
            n_out += 1
    if record:
        # The misses, compacted in order, go on to the next level; marking
        # them here keeps the loops above short of live values.
        for k in range(n_out):
            served_by[clocks[k] - first_clock] = level + 1
    counts = state.counts
    counts[level, ACCESSES] += n_in
    counts[level, HITS] += n_in - n_out
    counts[level, MISSES] += n_out
    counts[level, EVICTIONS] += evictions
    return n_out


@njit(cache=True, **NO_REFCOUNTS)
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
    shifts = work.level_shifts
    shifts[n_levels - 1] = 0
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
            line = np.int64(addresses[np.uint64(i)] >> shift)
            lines[np.uint64(kept)] = line
            clocks[np.uint64(kept)] = clock + 1 + i
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
