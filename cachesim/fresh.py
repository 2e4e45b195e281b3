"""A run of fresh consecutive lines, applied to a state without walking it access by access.

A stream of ``n`` consecutive first-level lines that no earlier access of the
state touched (another user's process streaming through new memory, say)
leaves each level in a state known in advance: every access misses the first
level; an access reaches level ``l`` when it is the first of its level
``l - 1`` line, and misses there when it is also the first of its level ``l``
line; each set of a level ends up holding, besides what it held before, the
last ``ways`` stream lines that map to it, each stamped with the clock of its
last access at that level, and loses the least recently used of its earlier
lines to them, as an access-by-access walk would.

:func:`skips_exactly` says when that shortcut is exact for a hierarchy and a
stream length: every level LRU or direct-mapped, not exclusive, and, for an
inclusive hierarchy, every level but the last overwritten in every set
(so no earlier line survives there that a back-invalidation would have
removed) and every line an upper level keeps still held by the levels below
(so no stream line is invalidated). :func:`skip_fresh_lines` applies it.

The counters kept are each level's accesses, hits and misses; evictions and
invalidations are not counted for such a stream (the schedule simulation
reports neither for the processes whose slices it skips).
"""
import numpy as np
from numba import njit

from cachesim.sets import ACCESSES, EXCLUSIVE, HITS, INCLUSIVE, LRU, MISSES, _insert, _set_base


def skips_exactly(geometry, n_lines: int) -> bool:
    """Whether :func:`skip_fresh_lines` of ``n_lines`` lines gives the state a walk would.

    Parameters
    ----------
    geometry : cachesim.sets.CacheGeometry
    n_lines : int
        First-level lines of every stream it will be asked to skip.
    """
    rel_shift = np.asarray(geometry.rel_shift, dtype=np.int64)
    ways = np.asarray(geometry.ways, dtype=np.int64)
    n_sets = np.asarray(geometry.n_sets, dtype=np.int64)
    n_levels = rel_shift.shape[0]
    if n_lines < 1 or geometry.inclusion == EXCLUSIVE or rel_shift[0] != 0 or np.any(np.diff(rel_shift) < 0):
        return False
    if not all(geometry.policy[level] == LRU or ways[level] == 1 for level in range(n_levels)):
        return False
    if geometry.inclusion != INCLUSIVE:
        return True
    for upper in range(n_levels - 1):
        fewest = n_lines >> rel_shift[upper]  # distinct lines of the shortest run, at this level
        if fewest // n_sets[upper] < ways[upper]:
            return False  # a set keeps earlier lines that a back-invalidation might have removed
        for lower in range(upper + 1, n_levels):
            # the lines the upper level keeps lie in the stream's last `tail` lines of the lower level
            kept = ways[upper] * n_sets[upper]
            tail = -(-(kept << rel_shift[upper]) // (1 << rel_shift[lower])) + 1
            if (tail - 1) // n_sets[lower] >= ways[lower]:
                return False  # a later stream line could push one of them out of the lower level
    return True


@njit(cache=True)
def skip_fresh_lines(first_line, n_lines, geometry, state, clock):
    """Apply the stream of first-level lines ``first_line .. first_line + n_lines - 1``.

    Parameters
    ----------
    first_line, n_lines : int
        Line numbers in the first level's lines (byte address >>
        ``geometry.line_shift``); none of them touched by the state before.
    geometry : CacheGeometry
        One for which :func:`skips_exactly` holds at ``n_lines``.
    state : CacheArrays
        Updated in place (tags, stamps; accesses, hits and misses).
    clock : int
        Access clock before the stream.

    Returns
    -------
    int
        The clock after it (``clock + n_lines``).
    """
    rel_shift = geometry.rel_shift
    n_sets = geometry.n_sets
    set_mask = geometry.set_mask
    ways = geometry.ways
    offset = geometry.offset
    policy = geometry.policy
    seeds = geometry.seeds
    tags = state.tags
    stamps = state.stamps
    counts = state.counts
    last_line = first_line + n_lines - 1
    entering = np.int64(n_lines)
    for level in range(rel_shift.shape[0]):
        shift = rel_shift[level]
        low = first_line >> shift
        high = last_line >> shift
        distinct = high - low + 1
        counts[level, ACCESSES] += entering
        counts[level, HITS] += entering - distinct
        counts[level, MISSES] += distinct
        # Consecutive lines take the sets in turn: the last ways x sets of them are every set's last ways.
        level_ways = ways[level]
        up = rel_shift[level - 1] if level > 0 else np.int64(0)
        spread = shift - up
        for line in range(max(low, high - n_sets[level] * level_ways + 1), high + 1):
            base = _set_base(line, level, n_sets, set_mask, ways, offset)
            if level_ways == 1:
                tags[base] = line
                continue
            # its last access here: the first access of its last line of the level above
            above = min(((line + 1) << spread) - 1, last_line >> up)
            index = max(above << up, first_line) - first_line
            _insert(tags, stamps, seeds[level], base, level_ways, policy[level], line, clock + 1 + index)
        entering = distinct
    return clock + n_lines
