"""Simulation of one interleaved stream of several hardware threads through shared caches.

>>> from cachesim.multicore import simulate_threads          # doctest: +SKIP
>>> result = simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes)
>>> result.to_frame()                                          # doctest: +SKIP

The stream is replayed access by access in the order given: access ``i`` is
made by hardware thread ``thread_ids[i]`` and goes through the instances of
the levels that serve that thread (:class:`~cachesim.sharing.SharedHierarchy`).
Within those instances the rules are those of :func:`cachesim.simulate`
(:mod:`cachesim.by_access`): lookups from the first level down, fills from
the lowest level that missed up to the first, writes served like reads where
they hit and filling only levels that allocate on writes, inclusion by
back-invalidation of the levels above. With one thread and private levels
the counts are exactly those of :func:`cachesim.simulate`.

Coherence (write-invalidate, like MESI without its states): every write by
thread ``t``, wherever it was served, removes the line from every instance,
at every level, that does not serve ``t`` (a read removes nothing). As a
MESI cache keeps an invalidated line's tag in state I, the emptied way keeps
the line as a *ghost*, with the bytes of the write, until a fill takes that
way (a fill takes an empty way first, the lowest, as everywhere in
cachesim) or the line itself is filled into the set again. Each instance
counts, per record kind:

- **coherence invalidations**: lines it lost so (attributed to the kind of
  the write);
- **coherence misses**: misses on a line that has a ghost in its set
  (attributed to the kind of the missing access): the line was lost to an
  invalidation and not evicted since. A miss that does not fill (a write in
  a level that does not allocate on writes) leaves the ghost, so the next
  miss on it counts again. A lost line whose way a fill took before its
  next use counts as an ordinary miss, so the count is a lower bound of the
  misses that invalidations caused;
- **false-sharing misses**: those coherence misses where the bytes the
  invalidating write touched and the bytes of the missing access are
  disjoint. Later writes by other threads find no copy to remove and change
  nothing.

A write looks for copies to remove in every other instance unless a table
of lately written lines (``SharedArrays.owners``) knows which threads have
filled the line since the last write removed the other copies: it then
searches only the instances serving those threads, and none when they all
share the writer's first-level instance. The counts are the same either way.

Supported: every replacement policy (random draws use the global access
clock and the level's seed, the same for every instance), non-inclusive and
inclusive hierarchies, prefetchers (:mod:`cachesim.multicore_prefetch`, a
walk of its own). Refused with a clear error: exclusive hierarchies and
hierarchies with a data TLB.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from cachesim import prefetch as P
from cachesim.inputs import as_addresses, as_writes, small_integers
from cachesim.multicore_state import (BACK_INVALIDATIONS, COHERENCE_INVALIDATIONS, COHERENCE_MISSES,
                                      FALSE_SHARING_MISSES, N_KINDS, SharedResult, SharedState,
                                      ThreadStream)
from cachesim.multicore_sets import (_back_invalidate, _byte_range, _drop_ghost, _filter_slot, _note_fill, _place,
                                     _probe, _set_of, _write_invalidate, set_index)
from cachesim.sets import (ACCESSES, EVICTIONS, HITS, INCLUSIVE, LRU, MISSES, WRITE_HITS, WRITE_MISSES, WRITES,
                           _find)
from cachesim.sharing import SharedHierarchy
from cachesim.simulate import _check_line_range
from rtcommon.jit import NO_REFCOUNTS
from rtcommon.validate import InputError

__all__ = ["shared_access", "simulate_threads", "simulate_threads_stream"]


@njit(cache=True)
def simulate_threads_stream(stream, geometry, machine, state, clock):
    """Replay an interleaved stream through the instances of a shared hierarchy.

    Parameters
    ----------
    stream : ThreadStream
    geometry : CacheGeometry
        One thread's hierarchy, with ``offset`` the first way of each
        level's first instance.
    machine : MachineGeometry
    state : SharedArrays
        Updated in place.
    clock : int
        Access clock before the call (0 for fresh caches).

    Returns
    -------
    int
        The clock after the last access.
    """
    clock = _replay(stream, geometry, machine, state, clock, np.empty((3, geometry.rel_shift.shape[0]), np.int64),
                    np.zeros((machine.instance_of.shape[1], N_KINDS), np.int64))
    # Every access is a hit or a miss: the totals follow.
    counts = state.counts
    counts[..., ACCESSES] = counts[..., HITS] + counts[..., MISSES]
    counts[..., WRITES] = counts[..., WRITE_HITS] + counts[..., WRITE_MISSES]
    return clock


#: The level number :func:`shared_access` returns for an access that memory served is the
#: number of levels ``L`` (levels are 0 ... L - 1 from the first).


@njit(cache=True, inline="always")
def shared_access(thread, address, is_write, size, kind, geometry, machine, state, clock, scratch):
    """One access of one hardware thread through the instances that serve it, with coherence.

    The rules are those of this module's docstring: the lookup from the
    thread's first-level instance down, a hit's LRU stamp, the fills of the
    levels that missed (levels that do not allocate on writes skip a
    write's fill), inclusion's back-invalidations, ghosts and their filter,
    and for a write the invalidation of the line in every instance that does
    not serve ``thread``. The totals ``ACCESSES`` and ``WRITES`` are not
    counted here: a caller adds them once at the end (``ACCESSES = HITS +
    MISSES``, ``WRITES = WRITE_HITS + WRITE_MISSES``), as
    :func:`simulate_threads_stream` does.

    Parameters
    ----------
    thread : int
        Hardware thread making the access, in [0, T).
    address : uint64
        First byte of the access.
    is_write : bool
    size : int
        Bytes the access touches from ``address``; 0: its whole first-level line.
    kind : int
        Record kind, in [0, :data:`N_KINDS`).
    geometry : CacheGeometry
        As for :func:`simulate_threads_stream`.
    machine : MachineGeometry
    state : SharedArrays
        Updated in place: tags, stamps, ghosts, ghost bytes and filter,
        ``counts`` (hits, misses, write hits and misses, evictions,
        back-invalidations, coherence counters) and ``served[thread]``.
    clock : int
        The access clock of this access (the previous access's plus one;
        random replacement draws from it, LRU stamps with it).
    scratch : ndarray of int64, shape (3, L)
        Work space (the line, instance and set of each level).

    Returns
    -------
    int
        The level that served the access: 0 for the first level ... ``L``
        (the number of levels) for memory.
    """
    n_levels = geometry.rel_shift.shape[0]
    line0 = np.int64(address >> np.uint64(geometry.line_shift))
    touched = _byte_range(address, size, line0, geometry.line_shift)
    instance0, base0, hit = _look_up(line0, 0, thread, kind, is_write, touched, clock, geometry, machine, state)
    if hit:
        served = 0
    else:
        served = n_levels
        if n_levels > 1 and _look_up(line0 >> geometry.rel_shift[1], 1, thread, kind, is_write, touched, clock,
                                     geometry, machine, state)[2]:
            served = 1
        if served == 1:
            # The usual miss, in a path of its own: the second level holds the line (or, with one level,
            # memory serves it), the first alone is filled.
            if not is_write or geometry.write_allocate[0]:
                _fill_level(line0, 0, instance0, base0, kind, clock, geometry, machine, state)
        else:
            served = _walk_below(line0, thread, kind, is_write, touched, geometry, machine, state, clock, scratch)
            scratch[0, 0] = line0
            scratch[1, 0] = instance0
            scratch[2, 0] = base0
            _fill(served, is_write, kind, geometry, machine, state, clock, scratch)
        _note_fill(line0, thread, state.owners)
    state.served[thread, served] += 1
    if is_write:
        _write_invalidate(line0, thread, kind, touched[0], touched[1], geometry, machine, state)
    return served


@njit(cache=True, inline="always")
def _look_up(line, level, thread, kind, is_write, touched, clock, geometry, machine, state):
    """Look ``line`` up in the instance of ``level`` that serves ``thread`` and count the hit
    (:func:`_count_hit`) or the miss (:func:`_count_miss`); return the instance, its set's first way
    and whether it hit."""
    instance = machine.instance_of[level, thread]
    base = _set_of(line, level, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                   machine.level_ways)
    slot = _probe(state.tags, base, geometry.ways[level], line)
    if slot >= 0:
        _count_hit(slot, level, instance, kind, is_write, clock, geometry, state)
    else:
        _count_miss(line, level, instance, base, kind, is_write, touched, geometry, machine, state)
    return instance, base, slot >= 0


@njit(cache=True, inline="always")
def _count_hit(slot, level, instance, kind, is_write, clock, geometry, state):
    """Count a hit in way ``slot`` of ``instance`` of ``level``; an LRU level stamps the way with ``clock``."""
    state.counts[level, instance, kind, HITS] += 1
    if is_write:
        state.counts[level, instance, kind, WRITE_HITS] += 1
    if geometry.policy[level] == LRU:
        state.stamps[slot] = clock


@njit(cache=True, inline="always")
def _count_miss(line, level, instance, base, kind, is_write, touched, geometry, machine, state):
    """Count a miss of ``line`` (its set's first way ``base``) in ``instance`` of ``level``: also a
    coherence miss when the line has a ghost in the set, and a false-sharing one when the ghost's bytes
    and the access's ``touched`` (first byte, end) are disjoint."""
    counts = state.counts
    counts[level, instance, kind, MISSES] += 1
    if is_write:
        counts[level, instance, kind, WRITE_MISSES] += 1
    if state.ghost_filter[_filter_slot(line, machine.instance_base[level] + instance, state.ghost_filter)] > 0:
        ghost = _find(state.ghosts, base, geometry.ways[level], line)
        if ghost >= 0:
            counts[level, instance, kind, COHERENCE_MISSES] += 1
            first, end = touched
            if end <= state.ghost_bytes[ghost, 0] or state.ghost_bytes[ghost, 1] <= first:
                counts[level, instance, kind, FALSE_SHARING_MISSES] += 1


@njit(cache=True, inline="always")
def _walk_below(line0, thread, kind, is_write, touched, geometry, machine, state, clock, scratch):
    """The lookup below first and second levels that missed (their misses counted): from the third
    level down until one holds the line; return that level (the number of levels: memory). Leaves the
    line, instance and set of the levels from the second down in ``scratch``."""
    n_levels = geometry.rel_shift.shape[0]
    for level in range(1, n_levels):
        line = line0 >> geometry.rel_shift[level]
        if level == 1:
            instance = machine.instance_of[1, thread]
            base = _set_of(line, 1, instance, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                           machine.level_ways)
            hit = False
        else:
            instance, base, hit = _look_up(line, level, thread, kind, is_write, touched, clock, geometry, machine,
                                           state)
        scratch[0, level] = line
        scratch[1, level] = instance
        scratch[2, level] = base
        if hit:
            return level
    return n_levels


@njit(cache=True, inline="always")
def _fill(served, is_write, kind, geometry, machine, state, clock, scratch):
    """Fill the line into the levels above ``served`` that missed, lowest first (``scratch`` holds each
    level's line, instance and set)."""
    for level in range(served - 1, -1, -1):
        if is_write and not geometry.write_allocate[level]:
            continue
        _fill_level(scratch[0, level], level, scratch[1, level], scratch[2, level], kind, clock, geometry, machine,
                    state)


@njit(cache=True, inline="always")
def _fill_level(line, level, instance, base, kind, clock, geometry, machine, state):
    """Fill ``line`` into its set (first way ``base``) of ``instance`` of ``level``: the line's own
    ghost in the set goes, the victim is counted and, in an inclusive hierarchy, removed from the
    instances above, and a ghost in an empty way the fill takes goes too."""
    tags = state.tags
    ghosts = state.ghosts
    ghost_filter = state.ghost_filter
    n_ways = geometry.ways[level]
    number = machine.instance_base[level] + instance
    entry = _filter_slot(line, number, ghost_filter)
    if ghost_filter[entry] > 0:
        ghost = _find(ghosts, base, n_ways, line)
        if ghost >= 0:  # the line is back: its ghost goes
            _drop_ghost(ghost, entry, ghosts, ghost_filter)
    evicted = _place(tags, state.stamps, geometry.seeds[level], base, n_ways, geometry.policy[level], line, clock)
    if evicted >= 0:
        state.counts[level, instance, kind, EVICTIONS] += 1
        if geometry.inclusion == INCLUSIVE and level > 0:
            _back_invalidate(evicted, level, instance, kind, geometry, machine, state)
    else:
        # The fill took an empty way, which may hold another line's ghost: evicted now.
        taken = _find(tags, base, n_ways, line)
        if ghosts[taken] >= 0:
            _drop_ghost(taken, _filter_slot(ghosts[taken], number, ghost_filter), ghosts, ghost_filter)


@njit(cache=True, **NO_REFCOUNTS)
def _replay(stream, geometry, machine, state, clock, scratch, first_hits):
    """The loop of :func:`simulate_threads_stream`, which counts hits and misses only;
    ``scratch`` (3, L) holds one access's line, instance and set at each level, ``first_hits`` (T,
    :data:`N_KINDS`), zeros on entry, the first-level read hits of the loop's own path by thread and
    kind until they are added to the counts at the end."""
    addresses = stream.addresses
    threads = stream.threads
    writes = stream.writes
    sizes = stream.sizes
    kinds = stream.kinds
    has_writes = writes.shape[0] > 0
    has_sizes = sizes.shape[0] > 0
    has_kinds = kinds.shape[0] > 0
    counts = state.counts
    tags = state.tags
    instance_of = machine.instance_of
    shift = np.uint64(geometry.line_shift)
    allocate0 = geometry.write_allocate[0]
    mask0 = geometry.set_mask[0]
    n_sets0 = geometry.n_sets[0]
    ways0 = geometry.ways[0]
    stamps0 = geometry.policy[0] == LRU
    previous_line = np.int64(-1)  # a line the previous access left in its thread's first level
    previous_thread = np.int64(-1)
    first_way = np.int64(0)  # the first way of the first-level instance of thread previous_thread
    for i in range(addresses.shape[0]):
        clock += 1
        address = addresses[i]
        thread = threads[i]
        line0 = np.int64(address >> shift)
        is_write = has_writes and writes[i]
        kind = np.int64(kinds[i]) if has_kinds else np.int64(0)
        if thread != previous_thread:
            first_way = geometry.offset[0] + instance_of[0, thread] * machine.level_ways[0]
        if not is_write:
            # A read that hits the first level changes nothing but the hit's
            # stamp and the counts. When the previous access, by the same
            # thread, left the line there as the set's most recent entry, not
            # even the stamp (the order in the set stays the same).
            slot = np.int64(-1)
            if line0 != previous_line or thread != previous_thread:
                slot = _probe(tags, first_way + set_index(line0, mask0, n_sets0) * ways0, ways0, line0)
            if slot >= 0 or line0 == previous_line and thread == previous_thread:
                if slot >= 0 and stamps0:
                    state.stamps[slot] = clock
                first_hits[np.uint64(thread), np.uint64(kind)] += 1
                previous_line = line0
                previous_thread = thread
                continue
        elif line0 == previous_line and thread == previous_thread:
            instance0 = instance_of[0, thread]
            counts[0, instance0, kind, HITS] += 1
            counts[0, instance0, kind, WRITE_HITS] += 1
            state.served[thread, 0] += 1
            first, end = _byte_range(address, sizes[i] if has_sizes else np.int64(0), line0, geometry.line_shift)
            _write_invalidate(line0, thread, kind, first, end, geometry, machine, state)
            continue
        served = shared_access(thread, address, is_write, sizes[i] if has_sizes else np.int64(0), kind, geometry,
                               machine, state, clock, scratch)
        resident = served == 0 or not (is_write and not allocate0)
        previous_line = line0 if resident else np.int64(-1)
        previous_thread = thread
    for thread in range(first_hits.shape[0]):
        instance0 = instance_of[0, thread]
        for kind in range(first_hits.shape[1]):
            counts[0, instance0, kind, HITS] += first_hits[thread, kind]
            state.served[thread, 0] += first_hits[thread, kind]
    return clock


def _stream(addresses, thread_ids, machine: SharedHierarchy, writes, sizes, kinds) -> ThreadStream:
    """Validate and convert the per-access arrays of :func:`simulate_threads`."""
    addresses = as_addresses(addresses)
    n = addresses.size
    threads = small_integers(thread_ids, n, "thread_ids", machine.n_threads,
                             f"the machine's hardware threads (n_cores * smt = {machine.n_threads})")
    flags = as_writes(writes, n)
    kind_codes = np.zeros(0, dtype=np.uint8) if kinds is None else \
        small_integers(kinds, n, "kinds", N_KINDS, "the record kinds", dtype=np.uint8)
    if sizes is None:
        byte_counts = np.zeros(0, dtype=np.int64)
    else:
        byte_counts = small_integers(sizes, n, "sizes", 1 << 20, "bytes, below a megabyte", lowest=1)
    _check_line_range(addresses, machine.hierarchy)
    return ThreadStream(addresses, threads, flags, byte_counts, kind_codes)


def simulate_threads(addresses, thread_ids, machine: SharedHierarchy | SharedState, *, writes=None, sizes=None,
                     kinds=None) -> SharedResult:
    """Replay one interleaved stream of hardware threads through a machine's shared caches.

    Parameters
    ----------
    addresses : array_like of int, shape (N,)
        First byte of each access, in access order (non-negative, below 2**64).
    thread_ids : array_like of int, shape (N,)
        Hardware thread of each access, in ``[0, n_cores * smt)``.
    machine : SharedHierarchy or SharedState
        A configuration (empty caches) or a state to continue (updated in place).
    writes : array_like of bool, shape (N,), optional
        True where the access is a write; omitted: all reads.
    sizes : array_like of int, shape (N,), optional
        Bytes each access touches from its address, in [1, 2**20); omitted:
        each touches its whole first-level line (no false sharing can then show).
    kinds : array_like of int, shape (N,), optional
        Record kind of each access, in [0, :data:`N_KINDS`); counts are then
        reported per kind. Stride prefetchers take it as the access's PC-like id.

    Returns
    -------
    SharedResult
        Counts of this call only, and the state after it. The rules are in
        this module's docstring, and for prefetchers in
        :mod:`cachesim.multicore_prefetch`.
    """
    state = machine if isinstance(machine, SharedState) else SharedState(machine)
    stream = _stream(addresses, thread_ids, state.machine, writes, sizes, kinds)
    counts_before, served_before = state.counts.copy(), state.served.copy()
    if state.prefetch is None:
        state.clock = int(simulate_threads_stream(stream, state.geometry, state.machine_geometry, state.arrays,
                                                  state.clock))
        return SharedResult(state.machine, state.counts - counts_before, state.served - served_before,
                            kinds is not None, state)
    from cachesim import multicore_prefetch as MP

    if stream.addresses.size and stream.addresses.max() >= 2**63:
        raise InputError("with prefetchers, addresses must be below 2**63")
    prefetch_before = state.prefetch.counts.copy()
    pending_before = MP.pending_by_instance(state.prefetch, state.tags, state.geometry, state.machine_geometry)
    state.clock = int(MP.simulate_threads_prefetching(stream, state.geometry, state.machine_geometry, state.arrays,
                                                      state.clock, state.prefetch_geometry, state.prefetch))
    pending = MP.pending_by_instance(state.prefetch, state.tags, state.geometry, state.machine_geometry)
    issued_useful = state.prefetch.counts - prefetch_before
    useless = issued_useful[..., P.ISSUED] - issued_useful[..., P.USEFUL] - (pending - pending_before)
    return SharedResult(state.machine, state.counts - counts_before, state.served - served_before,
                        kinds is not None, state, np.concatenate([issued_useful, useless[..., None]], axis=-1),
                        pending)
