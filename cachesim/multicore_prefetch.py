"""Prefetchers on a machine of shared levels: the walk of :func:`cachesim.multicore.simulate_threads`
for a hierarchy whose levels have prefetchers.

A separate entry kernel, so the walk without prefetchers
(:func:`cachesim.multicore.simulate_threads_stream`) is unchanged. The rules
are those of :mod:`cachesim.multicore` for the demand accesses and
coherence, and those of :mod:`cachesim.prefetch` for the prefetchers, with
these additions for sharing:

- every instance of a level with a prefetcher has a prefetcher of its own
  (its own stride table and counts), which sees the demand accesses of the
  threads it serves that reach it;
- the PC-like id of an access is its record kind (``kinds``; kind 0 for all
  without them);
- a prefetch triggered by thread ``t`` is looked up in and fills the
  instances that serve ``t``, from the level below the prefetching one
  down, like a demand fill of ``t`` (the line's own ghost in the set goes,
  and so does a ghost in the way it takes; an inclusive fill
  back-invalidates the instances above it serves, counted under the kind of
  the access that triggered the prefetch); it is a read, so it invalidates
  nothing in other instances;
- a prefetched line that a coherence invalidation removes left unused: it
  counts as useless;
- the repeat of a thread's previous line is looked up like any access (a
  prefetch in between may have moved it).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.multicore import _count_hit, _count_miss
from cachesim.multicore_sets import (_back_invalidate, _byte_range, _drop_ghost, _filter_slot, _invalidate_others,
                                     _set_of)
from cachesim.prefetch import ISSUED, NO_PREFETCH, USEFUL, _candidates
from cachesim.prefetch_config import MAX_DEGREE
from cachesim.sets import (ACCESSES, EVICTIONS, HITS, INCLUSIVE, LRU, MISSES, WRITE_HITS, WRITE_MISSES, WRITES,
                           _find, _insert)
from rtcommon.jit import NO_REFCOUNTS


@njit(cache=True)
def simulate_threads_prefetching(stream, geometry, machine, state, clock, prefetch_geometry, prefetch):
    """:func:`cachesim.multicore.simulate_threads_stream` with the levels' prefetchers.

    Parameters
    ----------
    stream : ThreadStream
    geometry : CacheGeometry
    machine : MachineGeometry
    state : SharedArrays
        As for :func:`~cachesim.multicore.simulate_threads_stream`; updated in place.
    clock : int
        Access clock before the call; it advances once per access and once
        per issued prefetch.
    prefetch_geometry : PrefetchGeometry
        With the stride tables laid out per instance
        (:func:`cachesim.prefetch.prefetch_geometry` given the instances).
    prefetch : PrefetchArrays
        ``marks`` over the ways of all instances; ``counts`` of shape
        (L, G, N_PREFETCH_COUNTERS). Updated in place.

    Returns
    -------
    int
        The clock after the call.
    """
    n_levels = geometry.rel_shift.shape[0]
    work = (np.empty(n_levels, dtype=np.int64), np.empty(n_levels, dtype=np.int64),
            np.empty(MAX_DEGREE, dtype=np.int64))
    clock = _walk(stream, geometry, machine, state, clock, prefetch_geometry, prefetch, work)
    counts = state.counts
    counts[..., ACCESSES] = counts[..., HITS] + counts[..., MISSES]
    counts[..., WRITES] = counts[..., WRITE_HITS] + counts[..., WRITE_MISSES]
    return clock


class ThreadPrefetchers(NamedTuple):
    """The prefetchers of a machine of shared levels and the work buffers of :func:`prefetching_access`.

    Attributes
    ----------
    geometry : PrefetchGeometry
        With the stride tables laid out per instance.
    arrays : PrefetchArrays
        ``marks`` (W,) over the ways of all instances, ``counts`` (L, G, N_PREFETCH_COUNTERS); updated in place.
    lines, fetch_lines : ndarray of int64, shape (L,)
        A demand access's and a prefetch's line at each level.
    candidates : ndarray of int64, shape (MAX_DEGREE,)
        One trigger's candidate lines.
    """

    geometry: object
    arrays: object
    lines: np.ndarray
    fetch_lines: np.ndarray
    candidates: np.ndarray


def thread_prefetchers(state) -> ThreadPrefetchers | None:
    """The bundle :func:`prefetching_access` takes for a :class:`~cachesim.multicore_state.SharedState`: its
    prefetchers' geometry and arrays (shared with the state, so updated in place); None when it has none."""
    if state.prefetch is None:
        return None
    n_levels = state.geometry.rel_shift.shape[0]
    return ThreadPrefetchers(state.prefetch_geometry, state.prefetch, np.empty(n_levels, dtype=np.int64),
                             np.empty(n_levels, dtype=np.int64), np.empty(MAX_DEGREE, dtype=np.int64))


@njit(cache=True, **NO_REFCOUNTS)
def _walk(stream, geometry, machine, state, clock, prefetch_geometry, prefetch, work):
    """The loop of :func:`simulate_threads_prefetching`; ``work`` holds its buffers: the demand
    access's and a prefetch's line per level, and one trigger's candidates."""
    lines, fetch_lines, candidates = work
    prefetchers = ThreadPrefetchers(prefetch_geometry, prefetch, lines, fetch_lines, candidates)
    addresses, writes, sizes, kinds = stream.addresses, stream.writes, stream.sizes, stream.kinds
    has_writes = writes.shape[0] > 0
    has_sizes = sizes.shape[0] > 0
    has_kinds = kinds.shape[0] > 0
    for i in range(addresses.shape[0]):
        clock += 1
        is_write = has_writes and writes[i]
        kind = np.int64(kinds[i]) if has_kinds else np.int64(0)
        size = np.int64(sizes[i]) if has_sizes else np.int64(0)
        _, clock = prefetching_access(np.int64(stream.threads[i]), addresses[i], is_write, size, kind, geometry,
                                      machine, state, clock, prefetchers)
    return clock


@njit(cache=True, inline="always")
def prefetching_access(thread, address, is_write, size, kind, geometry, machine, state, clock, prefetchers):
    """One access of one hardware thread, with coherence and the prefetchers of the levels it reaches.

    :func:`cachesim.multicore.shared_access` with this module's rules: the
    demand walk and fills, then each level with a prefetcher that the access
    reached trains and issues its candidates (each issued prefetch advances
    the clock by one), then, for a write, the invalidation of the line in the
    instances that do not serve ``thread``. ``ACCESSES`` and ``WRITES`` are
    not counted here (a caller adds them once at the end).

    Parameters
    ----------
    thread : int
        Hardware thread making the access.
    address : uint64
        First byte of the access, below 2**63.
    is_write : bool
    size : int
        Bytes the access touches from ``address``; 0: its whole first-level line.
    kind : int
        Record kind, also the stride tables' PC-like id.
    geometry : CacheGeometry
    machine : MachineGeometry
    state : SharedArrays
        Updated in place, ``served[thread]`` included.
    clock : int
        The access clock of this access.
    prefetchers : ThreadPrefetchers
        Updated in place.

    Returns
    -------
    (int, int)
        The level that served the access (the number of levels: memory) and
        the clock after its prefetches.
    """
    lines = prefetchers.lines
    prefetch_geometry = prefetchers.geometry
    prefetch = prefetchers.arrays
    n_levels = geometry.rel_shift.shape[0]
    shift = geometry.line_shift
    marks = prefetch.marks
    kind_of = prefetch_geometry.kind
    signed = np.int64(address)
    line0 = signed >> shift
    first, end = _byte_range(signed, size, line0, shift)
    access = (thread, kind, first, end, np.int64(is_write))
    served = _walk_down(line0, 0, access, True, geometry, machine, state, clock, lines)
    state.served[thread, served] += 1
    first_use = False
    if served < n_levels and kind_of[served] != NO_PREFETCH:
        line = lines[served]
        instance = machine.instance_of[served, thread]
        base = _set_of(line, served, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                       machine.level_ways)
        slot = _find(state.tags, base, geometry.ways[served], line)
        if marks[slot] == line:
            marks[slot] = -1
            prefetch.counts[served, instance, USEFUL] += 1
            first_use = True
    _fill_up(served, 0, access, geometry, machine, state, clock, lines, marks, kind_of)
    for level in range(min(served + 1, n_levels)):
        if kind_of[level] == NO_PREFETCH:
            continue
        rows = prefetch.table[machine.instance_of[level, thread] * prefetch_geometry.table_size[level]:]
        n_candidates = _candidates(level, shift + geometry.rel_shift[level], signed, kind, level < served,
                                   first_use and level == served, prefetch_geometry, rows, prefetchers.candidates)
        for k in range(n_candidates):
            clock = _issue(prefetchers.candidates[k], level, access, geometry, machine, state, clock, prefetch,
                           prefetchers.fetch_lines, kind_of)
    if is_write:
        _invalidate_others(line0, thread, kind, first, end, np.int64(-1), geometry, machine, state)
    return served, clock


@njit(cache=True, inline="always")
def _walk_down(line0, first_level, access, demand, geometry, machine, state, clock, lines):
    """Look ``line0`` up in the instances serving the access's thread from ``first_level`` down;
    return the level that holds it (the number of levels: memory).

    ``access`` is (thread, kind, first byte, end byte, is_write). Leaves each
    level's line in ``lines``; stamps an LRU hit. A ``demand`` access also
    counts its hit, misses and coherence misses (a prefetch counts nothing).
    """
    thread, kind, first, end, is_write = access
    for level in range(first_level, geometry.rel_shift.shape[0]):
        line = line0 >> geometry.rel_shift[level]
        lines[level] = line
        instance = machine.instance_of[level, thread]
        base = _set_of(line, level, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                       machine.level_ways)
        slot = _find(state.tags, base, geometry.ways[level], line)
        if slot >= 0:
            if demand:
                _count_hit(slot, level, instance, kind, is_write, clock, geometry, state)
            elif geometry.policy[level] == LRU:
                state.stamps[slot] = clock
            return level
        if demand:
            _count_miss(line, level, instance, base, kind, is_write, (first, end), geometry, machine, state)
    return geometry.rel_shift.shape[0]


@njit(cache=True, inline="always")
def _fill_up(served, last_level, access, geometry, machine, state, clock, lines, marks, kind_of):
    """Fill ``lines[level]`` into the thread's instances of levels ``served - 1`` down to ``last_level``.

    Bottom-up; a write skips the levels that do not allocate on writes. The
    line's own ghost in the set goes, and a ghost in the way it takes; its way
    is no longer marked as prefetched; evictions are counted and, in an
    inclusive hierarchy, back-invalidate the instances above.
    """
    thread, kind, _, _, is_write = access
    for level in range(served - 1, last_level - 1, -1):
        if is_write and not geometry.write_allocate[level]:
            continue
        line = lines[level]
        instance = machine.instance_of[level, thread]
        base = _set_of(line, level, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                       machine.level_ways)
        number = machine.instance_base[level] + instance
        entry = _filter_slot(line, number, state.ghost_filter)
        if state.ghost_filter[entry] > 0:
            own = _find(state.ghosts, base, geometry.ways[level], line)
            if own >= 0:
                _drop_ghost(own, entry, state.ghosts, state.ghost_filter)
        evicted = _insert(state.tags, state.stamps, geometry.seeds[level], base, geometry.ways[level],
                          geometry.policy[level], line, clock)
        taken = _find(state.tags, base, geometry.ways[level], line)
        if kind_of[level] != NO_PREFETCH:
            marks[taken] = -1
        if evicted >= 0:
            state.counts[level, instance, kind, EVICTIONS] += 1
            if geometry.inclusion == INCLUSIVE and level > 0:
                _back_invalidate(evicted, level, instance, kind, geometry, machine, state)
        elif state.ghosts[taken] >= 0:
            _drop_ghost(taken, _filter_slot(state.ghosts[taken], number, state.ghost_filter), state.ghosts,
                        state.ghost_filter)


@njit(cache=True, inline="always")
def _issue(line, level, access, geometry, machine, state, clock, prefetch, fetch_lines, kind_of):
    """Prefetch ``line`` into the access's thread's instance of ``level`` unless it is there;
    return the clock after it."""
    instance = machine.instance_of[level, access[0]]
    base = _set_of(line, level, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                   machine.level_ways)
    if _find(state.tags, base, geometry.ways[level], line) >= 0:
        return clock
    clock += 1
    read = (access[0], access[1], access[2], access[3], np.int64(0))
    fetch_lines[level] = line
    served = _walk_down(line << geometry.rel_shift[level], level + 1, read, False, geometry, machine, state, clock,
                        fetch_lines)
    _fill_up(served, level, read, geometry, machine, state, clock, fetch_lines, prefetch.marks, kind_of)
    prefetch.marks[_find(state.tags, base, geometry.ways[level], line)] = line
    prefetch.counts[level, instance, ISSUED] += 1
    return clock


def pending_by_instance(prefetch, tags: np.ndarray, geometry, machine) -> np.ndarray:
    """Prefetched lines still unused in each instance (int64, (L, G))."""
    held = (prefetch.marks == tags) & (tags >= 0)
    n_levels = geometry.rel_shift.shape[0]
    pending = np.zeros((n_levels, int(machine.n_instances.max())), dtype=np.int64)
    for level in range(n_levels):
        ways = int(machine.level_ways[level])
        for instance in range(int(machine.n_instances[level])):
            start = int(geometry.offset[level]) + instance * ways
            pending[level, instance] = int(held[start:start + ways].sum())
    return pending
