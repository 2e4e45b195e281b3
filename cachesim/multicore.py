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
at every level, that does not serve ``t`` (a read removes nothing). Each
instance counts, per record kind:

- **coherence invalidations**: lines it lost so (attributed to the kind of
  the write);
- **coherence misses**: misses on a line it lost to an invalidation and has
  not filled again since (attributed to the kind of the missing access); a
  miss that does not fill (a write in a level that does not allocate on
  writes) leaves the line lost, so the next miss on it counts again;
- **false-sharing misses**: those coherence misses where the bytes the
  invalidating write touched and the bytes of the missing access are
  disjoint. The invalidating write is the one that removed the line; later
  writes by other threads find nothing to remove and change nothing.

An access touches bytes ``[address, address + size)``; without ``sizes`` it
touches its whole first-level line, so no miss is counted as false sharing.
Lines are not held in states (modified, shared ...): a read of a line
another thread has written costs no write-back, and a write to a line no one
else holds costs nothing more than the access itself.

Supported: every replacement policy (random draws use the global access
clock and the level's seed, the same for every instance), non-inclusive and
inclusive hierarchies. Refused with a clear error: exclusive hierarchies and
hierarchies with a data TLB.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd
from numba import njit, types
from numba.typed import Dict

from cachesim.inputs import as_addresses, as_writes
from cachesim.sets import (ACCESSES, EVICTIONS, HITS, INCLUSIVE, LRU, MISSES, WRITE_HITS, WRITE_MISSES, WRITES,
                           CacheGeometry, _find, _insert, _set_base)
from cachesim.sharing import SharedHierarchy
from cachesim.simulate import cache_geometry
from rtcommon.validate import InputError

__all__ = ["BACK_INVALIDATIONS", "COHERENCE_INVALIDATIONS", "COHERENCE_MISSES", "FALSE_SHARING_MISSES",
           "N_KINDS", "N_SHARED_COUNTERS", "MachineGeometry", "SharedArrays", "SharedResult", "SharedState",
           "ThreadStream", "interleave", "simulate_threads", "simulate_threads_stream"]

# Counter columns of SharedArrays.counts: the first eight are those of
# cachesim.kernels (accesses ... write misses, back-invalidations at 4).
BACK_INVALIDATIONS = 4
COHERENCE_INVALIDATIONS, COHERENCE_MISSES, FALSE_SHARING_MISSES = 8, 9, 10
N_SHARED_COUNTERS = 11
#: Record kinds are integers below this (the trace's four-bit kinds).
N_KINDS = 16
#: Line numbers times instances must stay below 2**63: the key of a lost line.
_KEY_LIMIT = 1 << 63

_COLUMNS = (("accesses", ACCESSES), ("hits", HITS), ("misses", MISSES), ("evictions", EVICTIONS),
            ("back_invalidations", BACK_INVALIDATIONS), ("write_accesses", WRITES), ("write_hits", WRITE_HITS),
            ("write_misses", WRITE_MISSES), ("coherence_invalidations", COHERENCE_INVALIDATIONS),
            ("coherence_misses", COHERENCE_MISSES), ("false_sharing_misses", FALSE_SHARING_MISSES))


class ThreadStream(NamedTuple):
    """One interleaved stream of accesses, as the kernel reads it.

    Attributes
    ----------
    addresses : ndarray of uint64, shape (N,)
        First byte of each access.
    threads : ndarray of int64, shape (N,)
        Hardware thread of each access.
    writes : ndarray of bool, shape (N,) or (0,)
        True where the access is a write; (0,): all reads.
    sizes : ndarray of int64, shape (N,) or (0,)
        Bytes each access touches from its address; (0,): its whole first-level line.
    kinds : ndarray of uint8, shape (N,) or (0,)
        Record kind of each access, below :data:`N_KINDS`; (0,): all kind 0.
    """

    addresses: np.ndarray
    threads: np.ndarray
    writes: np.ndarray
    sizes: np.ndarray
    kinds: np.ndarray


class MachineGeometry(NamedTuple):
    """Where each level's instances live and which threads they serve.

    Attributes
    ----------
    instance_of : ndarray of int64, shape (L, T)
        The instance of each level that serves each hardware thread.
    n_instances : ndarray of int64, shape (L,)
    level_ways : ndarray of int64, shape (L,)
        Ways of one instance of each level; instance ``g`` of level ``l``
        holds ``tags[offset[l] + g * level_ways[l] :][:level_ways[l]]``,
        with ``offset`` that of the :class:`~cachesim.sets.CacheGeometry`.
    threads_per_instance : ndarray of int64, shape (L,)
    instance_base : ndarray of int64, shape (L,)
        Number of the first instance of each level among all instances.
    n_all_instances : int
        Instances of all levels.
    """

    instance_of: np.ndarray
    n_instances: np.ndarray
    level_ways: np.ndarray
    threads_per_instance: np.ndarray
    instance_base: np.ndarray
    n_all_instances: int


class SharedArrays(NamedTuple):
    """The mutable contents and counters of every instance (updated in place).

    Attributes
    ----------
    tags, stamps : ndarray of int64, shape (W,)
        As in :class:`~cachesim.sets.CacheArrays`, for the instances of all levels.
    counts : ndarray of int64, shape (L, G, N_KINDS, N_SHARED_COUNTERS)
        Per level, instance (``G`` the most instances of a level), record
        kind and counter column (:data:`COHERENCE_MISSES` ...).
    served : ndarray of int64, shape (T, L + 1)
        Accesses of each hardware thread served by each level (``L``: memory).
    lost : numba typed Dict of int64 to (int64, int64)
        Lines lost to an invalidation and not filled again: key
        ``line * n_all_instances + instance_base[level] + instance``, value
        the first byte and the end of the bytes of the invalidating write.
    lost_filter : ndarray of int32, shape (F,)
        How many of ``lost``'s keys hash (:func:`_filter_slot`) to each
        entry: a miss or fill looks ``lost`` up only where this is nonzero.
        ``F`` is a power of two, :data:`LOST_FILTER_SIZE` in a
        :class:`SharedState`: small enough to stay in the host's first-level cache.
    """

    tags: np.ndarray
    stamps: np.ndarray
    counts: np.ndarray
    served: np.ndarray
    lost: object
    lost_filter: np.ndarray


#: Entries of SharedArrays.lost_filter (a power of two).
LOST_FILTER_SIZE = 1 << 13


@njit(cache=True, inline="always")
def _filter_slot(key, lost_filter):
    """The entry of ``lost_filter`` that counts ``key`` (bits 40 up of a Fibonacci hash)."""
    mixed = (np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return np.int64(mixed & np.uint64(lost_filter.shape[0] - 1))


# The helpers take arrays, not bundles: a bundle's field read in the
# per-access loop costs a reference-count update each time.
@njit(cache=True, inline="always")
def _set_of(line, level, instance, n_sets, set_mask, ways, offset, level_ways):
    """First way of ``line``'s set in instance ``instance`` of ``level``."""
    mask = set_mask[level]
    set_index = line & mask if mask >= 0 else line % n_sets[level]
    return offset[level] + instance * level_ways[level] + set_index * ways[level]


@njit(cache=True, inline="always")
def _note_miss(key, level, instance, kind, first, end, lost, counts):
    """Count a coherence (and false-sharing) miss when ``key``'s line was lost to an invalidation."""
    if key in lost:
        written_first, written_end = lost[key]
        counts[level, instance, kind, COHERENCE_MISSES] += 1
        if end <= written_first or written_end <= first:
            counts[level, instance, kind, FALSE_SHARING_MISSES] += 1


@njit(cache=True, inline="always")
def _forget(key, lost):
    """Remove ``key`` from the lost lines; whether it was there."""
    if key in lost:
        del lost[key]
        return True
    return False


@njit(cache=True)
def _back_invalidate(evicted, level, instance, kind, geometry, machine, state):
    """Inclusion: remove the evicted line from the instances above that ``instance`` serves."""
    width = machine.threads_per_instance[level]
    for upper in range(level):
        spread = geometry.rel_shift[level] - geometry.rel_shift[upper]
        per_upper = machine.threads_per_instance[upper]
        first_line = evicted << spread
        for above in range(instance * width // per_upper, (instance + 1) * width // per_upper):
            for sub in range(first_line, first_line + (np.int64(1) << spread)):
                base = _set_of(sub, upper, above, geometry.n_sets, geometry.set_mask, geometry.ways,
                               geometry.offset, machine.level_ways)
                slot = _find(state.tags, base, geometry.ways[upper], sub)
                if slot >= 0:
                    state.tags[slot] = -1
                    state.counts[upper, above, kind, BACK_INVALIDATIONS] += 1


@njit(cache=True)
def _invalidate_others(line0, thread, kind, first, end, geometry, machine, state):
    """A write by ``thread``: remove its line from every instance that does not serve the thread."""
    for level in range(geometry.rel_shift.shape[0]):
        line = line0 >> geometry.rel_shift[level]
        own = machine.instance_of[level, thread]
        for other in range(machine.n_instances[level]):
            if other == own:
                continue
            base = _set_of(line, level, other, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                           machine.level_ways)
            slot = _find(state.tags, base, geometry.ways[level], line)
            if slot >= 0:
                state.tags[slot] = -1
                state.counts[level, other, kind, COHERENCE_INVALIDATIONS] += 1
                key = line * machine.n_all_instances + machine.instance_base[level] + other
                state.lost[key] = (first, end)
                state.lost_filter[_filter_slot(key, state.lost_filter)] += 1


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
    addresses = stream.addresses
    threads = stream.threads
    writes = stream.writes
    sizes = stream.sizes
    kinds = stream.kinds
    has_writes = writes.shape[0] > 0
    has_sizes = sizes.shape[0] > 0
    has_kinds = kinds.shape[0] > 0
    tags = state.tags
    stamps = state.stamps
    counts = state.counts
    served_counts = state.served
    lost = state.lost
    lost_filter = state.lost_filter
    instance_of = machine.instance_of
    level_ways = machine.level_ways
    instance_base = machine.instance_base
    n_all = machine.n_all_instances
    rel_shift = geometry.rel_shift
    n_sets = geometry.n_sets
    set_mask = geometry.set_mask
    ways = geometry.ways
    offset = geometry.offset
    policy = geometry.policy
    seeds = geometry.seeds
    write_allocate = geometry.write_allocate
    inclusive = geometry.inclusion == INCLUSIVE
    n_levels = rel_shift.shape[0]
    shift = np.uint64(geometry.line_shift)
    line_bytes = np.int64(1) << geometry.line_shift
    lines = np.empty(n_levels, dtype=np.int64)
    instances = np.empty(n_levels, dtype=np.int64)
    bases = np.empty(n_levels, dtype=np.int64)
    # The first level serves most accesses: its geometry in scalars.
    mask0 = set_mask[0]
    sets0 = n_sets[0]
    ways0 = ways[0]
    per_instance0 = level_ways[0]
    track0 = policy[0] == LRU and ways0 > 1
    allocate0 = write_allocate[0]
    previous_line = np.int64(-1)  # a line the previous access left in its thread's first level
    previous_thread = np.int64(-1)
    for i in range(addresses.shape[0]):
        clock += 1
        address = addresses[i]
        thread = threads[i]
        line0 = np.int64(address >> shift)
        is_write = has_writes and writes[i]
        kind = np.int64(kinds[i]) if has_kinds else np.int64(0)
        instance0 = instance_of[0, thread]
        first = np.int64(0)
        end = np.int64(0)
        if line0 == previous_line and thread == previous_thread:
            # The previous access, by the same thread, left the line in its
            # first level as the set's most recent entry: a hit that changes nothing.
            slot = np.int64(0)
        else:
            base0 = instance0 * per_instance0 + (line0 & mask0 if mask0 >= 0 else line0 % sets0) * ways0
            slot = _find(tags, base0, ways0, line0)
            if slot >= 0 and track0:
                stamps[slot] = clock
        if slot >= 0:
            counts[0, instance0, kind, HITS] += 1
            if is_write:
                counts[0, instance0, kind, WRITE_HITS] += 1
            served_counts[thread, 0] += 1
            previous_line = line0
            previous_thread = thread
        else:
            if has_sizes:
                first = np.int64(address)
                end = first + sizes[i]
            else:
                first = line0 << geometry.line_shift
                end = first + line_bytes
            served = n_levels
            for level in range(n_levels):
                line = line0 >> rel_shift[level]
                instance = instance_of[level, thread]
                base = _set_of(line, level, instance, n_sets, set_mask, ways, offset, level_ways)
                lines[level] = line
                instances[level] = instance
                bases[level] = base
                if level > 0:
                    slot = _find(tags, base, ways[level], line)
                    if slot >= 0:
                        counts[level, instance, kind, HITS] += 1
                        if is_write:
                            counts[level, instance, kind, WRITE_HITS] += 1
                        if policy[level] == LRU:
                            stamps[slot] = clock
                        served = level
                        break
                counts[level, instance, kind, MISSES] += 1
                if is_write:
                    counts[level, instance, kind, WRITE_MISSES] += 1
                key = line * n_all + instance_base[level] + instance
                if lost_filter[_filter_slot(key, lost_filter)] > 0:
                    _note_miss(key, level, instance, kind, first, end, lost, counts)
            served_counts[thread, served] += 1
            for level in range(served - 1, -1, -1):
                if is_write and not write_allocate[level]:
                    continue
                line = lines[level]
                instance = instances[level]
                base = bases[level]
                evicted = _insert(tags, stamps, seeds[level], base, ways[level], policy[level], line, clock)
                key = line * n_all + instance_base[level] + instance
                if lost_filter[_filter_slot(key, lost_filter)] > 0 and _forget(key, lost):
                    lost_filter[_filter_slot(key, lost_filter)] -= 1
                if evicted >= 0:
                    counts[level, instance, kind, EVICTIONS] += 1
                    if inclusive and level > 0:
                        _back_invalidate(evicted, level, instance, kind, geometry, machine, state)
            previous_line = line0 if (allocate0 or not is_write) else np.int64(-1)
            previous_thread = thread
        if is_write:
            if not has_sizes:
                first = line0 << geometry.line_shift
                end = first + line_bytes
            elif slot >= 0:
                first = np.int64(address)
                end = first + sizes[i]
            _invalidate_others(line0, thread, kind, first, end, geometry, machine, state)
    # Every access is a hit or a miss: the totals follow.
    counts[..., ACCESSES] = counts[..., HITS] + counts[..., MISSES]
    counts[..., WRITES] = counts[..., WRITE_HITS] + counts[..., WRITE_MISSES]
    return clock


def _machine_geometry(machine: SharedHierarchy, geometry: CacheGeometry) -> tuple[CacheGeometry, MachineGeometry]:
    """The kernel's view: one thread's geometry with offsets over all instances, and the machine."""
    n_levels = len(machine.hierarchy.levels)
    n_instances = np.array([machine.n_instances(level) for level in range(n_levels)], dtype=np.int64)
    level_ways = geometry.n_sets * geometry.ways
    offset = np.concatenate(([0], np.cumsum(level_ways * n_instances)[:-1])).astype(np.int64)
    instance_of = np.array([[machine.instance_of(level, thread) for thread in range(machine.n_threads)]
                            for level in range(n_levels)], dtype=np.int64)
    per_instance = np.array([machine.threads_per_instance(level) for level in range(n_levels)], dtype=np.int64)
    instance_base = np.concatenate(([0], np.cumsum(n_instances)[:-1])).astype(np.int64)
    over_instances = CacheGeometry(geometry.line_shift, geometry.rel_shift, geometry.n_sets, geometry.set_mask,
                               geometry.ways, geometry.policy, offset, geometry.inclusion, geometry.seeds,
                               geometry.write_allocate)
    return (over_instances,
            MachineGeometry(instance_of, n_instances, level_ways.astype(np.int64), per_instance, instance_base,
                            int(n_instances.sum())))


def _empty_lost():
    return Dict.empty(key_type=types.int64, value_type=types.UniTuple(types.int64, 2))


class SharedState:
    """Contents and cumulative counters of every cache instance of a machine.

    Parameters
    ----------
    machine : SharedHierarchy
        Refused when its hierarchy is exclusive or has a data TLB.
    """

    def __init__(self, machine: SharedHierarchy):
        if not isinstance(machine, SharedHierarchy):
            raise InputError(f"SharedState needs a SharedHierarchy, got {type(machine).__name__}")
        if machine.hierarchy.inclusion == "exclusive":
            raise InputError(f"shared hierarchy {machine.name!r}: exclusive hierarchies are not simulated with "
                             "threads; use non-inclusive or inclusive")
        if machine.hierarchy.tlb is not None:
            raise InputError(f"shared hierarchy {machine.name!r}: a data TLB is not simulated with threads; "
                             "give the hierarchy without its tlb")
        self.machine = machine
        self.geometry, self.machine_geometry = _machine_geometry(machine, cache_geometry(machine.hierarchy))
        self.reset()

    def reset(self) -> None:
        """Empty every instance and zero the counters."""
        machine = self.machine
        n_levels = len(machine.hierarchy.levels)
        total_ways = int(np.sum(self.machine_geometry.level_ways * self.machine_geometry.n_instances))
        self.tags = np.full(total_ways, -1, dtype=np.int64)
        self.stamps = np.zeros(total_ways, dtype=np.int64)
        most = int(self.machine_geometry.n_instances.max())
        self.counts = np.zeros((n_levels, most, N_KINDS, N_SHARED_COUNTERS), dtype=np.int64)
        self.served = np.zeros((machine.n_threads, n_levels + 1), dtype=np.int64)
        self.lost = _empty_lost()
        self.lost_filter = np.zeros(LOST_FILTER_SIZE, dtype=np.int32)
        self.clock = 0

    @property
    def arrays(self) -> SharedArrays:
        """The contents and counters as one bundle for :func:`simulate_threads_stream` (updated in place)."""
        return SharedArrays(self.tags, self.stamps, self.counts, self.served, self.lost, self.lost_filter)

    def copy(self) -> "SharedState":
        """An independent clone: continuing either leaves the other untouched."""
        clone = SharedState.__new__(SharedState)
        clone.machine, clone.geometry, clone.machine_geometry = self.machine, self.geometry, self.machine_geometry
        clone.tags, clone.stamps = self.tags.copy(), self.stamps.copy()
        clone.counts, clone.served = self.counts.copy(), self.served.copy()
        clone.lost_filter = self.lost_filter.copy()
        clone.lost = _empty_lost()
        for key, value in self.lost.items():
            clone.lost[key] = value
        clone.clock = self.clock
        return clone

    def resident_lines(self, level: int, instance: int) -> np.ndarray:
        """Sorted line numbers held by one instance of one level (an index each)."""
        ways = int(self.machine_geometry.level_ways[level])
        start = int(self.geometry.offset[level]) + instance * ways
        held = self.tags[start:start + ways]
        return np.sort(held[held >= 0])


@dataclass(frozen=True)
class SharedResult:
    """Counts of one :func:`simulate_threads` call.

    Attributes
    ----------
    machine : SharedHierarchy
    counts : ndarray of int64, shape (L, G, N_KINDS, N_SHARED_COUNTERS)
        Per level, instance, record kind and column (see :class:`SharedArrays`);
        instances beyond a level's count stay zero.
    served : ndarray of int64, shape (T, L + 1)
        Accesses of each hardware thread served by each level (``L``: memory).
    by_kind : bool
        Whether the call was given record kinds (the frame then has a ``kind`` column).
    state : SharedState
        The state after the call, to continue from.
    """

    machine: SharedHierarchy
    counts: np.ndarray
    served: np.ndarray
    by_kind: bool
    state: SharedState

    def level_counts(self) -> np.ndarray:
        """Counts summed over instances and kinds, int64 (L, N_SHARED_COUNTERS)."""
        return self.counts.sum(axis=(1, 2))

    def to_frame(self) -> pd.DataFrame:
        """One row per level and instance (and record kind seen, when kinds were given).

        Columns: level, instance, threads (first and last hardware thread it
        serves, ``"0-1"``), [kind], then the counts: accesses, hits, misses,
        evictions, back_invalidations, write_accesses, write_hits,
        write_misses, coherence_invalidations, coherence_misses,
        false_sharing_misses.
        """
        machine = self.machine
        rows = []
        for level, name in enumerate(machine.hierarchy.level_names):
            width = machine.threads_per_instance(level)
            for instance in range(machine.n_instances(level)):
                threads = f"{instance * width}-{(instance + 1) * width - 1}" if width > 1 else str(instance)
                block = self.counts[level, instance]
                if self.by_kind:
                    kinds = [kind for kind in range(N_KINDS) if block[kind].any()]
                    rows.extend((name, instance, threads, kind, block[kind]) for kind in kinds)
                else:
                    rows.append((name, instance, threads, None, block.sum(axis=0)))
        frame = pd.DataFrame({
            "level": pd.Series([row[0] for row in rows], dtype="string"),
            "instance": np.array([row[1] for row in rows], dtype=np.int64),
            "threads": pd.Series([row[2] for row in rows], dtype="string"),
        })
        if self.by_kind:
            frame["kind"] = np.array([row[3] for row in rows], dtype=np.int64)
        values = np.array([row[4] for row in rows], dtype=np.int64).reshape(len(rows), N_SHARED_COUNTERS)
        for column, index in _COLUMNS:
            frame[column] = values[:, index]
        return frame


def _stream(addresses, thread_ids, machine: SharedHierarchy, writes, sizes, kinds) -> ThreadStream:
    """Validate and convert the per-access arrays of :func:`simulate_threads`."""
    addresses = as_addresses(addresses)
    n = addresses.size
    threads = _small_integers(thread_ids, n, "thread_ids", machine.n_threads,
                              f"the machine's hardware threads (n_cores * smt = {machine.n_threads})")
    flags = as_writes(writes, n)
    kind_codes = np.zeros(0, dtype=np.uint8) if kinds is None else \
        _small_integers(kinds, n, "kinds", N_KINDS, "the record kinds").astype(np.uint8)
    if sizes is None:
        byte_counts = np.zeros(0, dtype=np.int64)
    else:
        byte_counts = _small_integers(sizes, n, "sizes", 1 << 20, "a megabyte", lowest=1)
    line_shift = machine.hierarchy.levels[0].line_size.bit_length() - 1
    if n and (int(addresses.max()) >> line_shift) + 1 > _KEY_LIMIT // machine_instances(machine):
        raise InputError(f"addresses must be below {(_KEY_LIMIT // machine_instances(machine)) << line_shift:#x} "
                         f"on this machine (line numbers times its {machine_instances(machine)} cache "
                         f"instances must fit in 63 bits); found {int(addresses.max()):#x}")
    return ThreadStream(addresses, threads, flags, byte_counts, kind_codes)


def machine_instances(machine: SharedHierarchy) -> int:
    """Cache instances of all levels of a machine."""
    return sum(machine.n_instances(level) for level in range(len(machine.hierarchy.levels)))


def _small_integers(values, n: int, name: str, limit: int, what: str, lowest: int = 0) -> np.ndarray:
    """``values`` as int64 (N,), each in [lowest, limit), or a one-line error naming the first bad one."""
    array = np.asarray(values)
    if array.ndim != 1 or array.size != n:
        raise InputError(f"{name} must have shape ({n},), one per address; got {array.shape}")
    if n and array.dtype.kind not in "iu":
        raise InputError(f"{name} must be integers, got dtype {array.dtype}")
    array = np.ascontiguousarray(array, dtype=np.int64) if n else np.zeros(0, dtype=np.int64)
    bad = np.flatnonzero((array < lowest) | (array >= limit))
    if bad.size:
        raise InputError(f"{name}[{int(bad[0])}] is {int(array[bad[0]])}; expected an integer in "
                         f"[{lowest}, {limit}) ({what})")
    return array


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
        reported per kind.

    Returns
    -------
    SharedResult
        Counts of this call only, and the state after it. The rules are in
        this module's docstring.
    """
    state = machine if isinstance(machine, SharedState) else SharedState(machine)
    stream = _stream(addresses, thread_ids, state.machine, writes, sizes, kinds)
    counts_before, served_before = state.counts.copy(), state.served.copy()
    state.clock = int(simulate_threads_stream(stream, state.geometry, state.machine_geometry, state.arrays,
                                              state.clock))
    return SharedResult(state.machine, state.counts - counts_before, state.served - served_before,
                        kinds is not None, state)


def interleave(streams, quantum: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Interleave per-thread streams round-robin, ``quantum`` accesses of each thread at a time.

    Parameters
    ----------
    streams : sequence of array_like of int, length T
        Stream of hardware thread ``t`` at position ``t``; an exhausted
        stream drops out of the rotation.
    quantum : int
        Consecutive accesses a thread makes before the next thread's turn (>= 1).

    Returns
    -------
    addresses : ndarray of uint64, shape (N,)
    thread_ids : ndarray of int64, shape (N,)
        Which thread made each access; ``addresses[thread_ids == t]`` is
        stream ``t`` in its order.
    """
    if isinstance(quantum, bool) or not isinstance(quantum, (int, np.integer)) or quantum < 1:
        raise InputError(f"interleave: quantum must be an integer >= 1, got {quantum!r}")
    arrays = [as_addresses(stream, name=f"streams[{index}]") for index, stream in enumerate(streams)]
    if not arrays:
        return np.zeros(0, dtype=np.uint64), np.zeros(0, dtype=np.int64)
    # Access j of thread t runs in round j // quantum, after the earlier threads' turns of that round.
    rounds = np.concatenate([np.arange(array.size, dtype=np.int64) // quantum for array in arrays])
    threads = np.concatenate([np.full(array.size, thread, dtype=np.int64) for thread, array in enumerate(arrays)])
    order = np.lexsort((threads, rounds))
    return np.concatenate(arrays)[order], threads[order]
