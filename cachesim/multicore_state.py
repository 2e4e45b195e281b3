"""The shared-cache simulator's state, results and kernel bundles (:mod:`cachesim.multicore`).

:class:`SharedState` holds the contents and cumulative counters of every
cache instance of a :class:`~cachesim.sharing.SharedHierarchy`;
:class:`SharedResult` is the counts of one :func:`cachesim.multicore.simulate_threads`
call. The named tuples are what the compiled kernels read: the stream
(:class:`ThreadStream`), the machine (:class:`MachineGeometry`) and the
mutable arrays (:class:`SharedArrays`). The counter columns are those of
:mod:`cachesim.kernels` plus the coherence counts.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd

from cachesim import prefetch as P
from cachesim.sets import ACCESSES, EVICTIONS, HITS, MISSES, WRITE_HITS, WRITE_MISSES, WRITES, CacheGeometry
from cachesim.sharing import SharedHierarchy
from cachesim.simulate import cache_geometry
from rtcommon.validate import InputError

__all__ = ["BACK_INVALIDATIONS", "COHERENCE_INVALIDATIONS", "COHERENCE_MISSES", "FALSE_SHARING_MISSES",
           "GHOST_FILTER_SIZE", "N_KINDS", "N_SHARED_COUNTERS", "OWNERS_SIZE",
           "MachineGeometry", "SharedArrays", "SharedResult", "SharedState", "ThreadStream"]

# Counter columns of SharedArrays.counts: the first eight are those of
# cachesim.kernels (accesses ... write misses, back-invalidations at 4).
BACK_INVALIDATIONS = 4
COHERENCE_INVALIDATIONS, COHERENCE_MISSES, FALSE_SHARING_MISSES = 8, 9, 10
N_SHARED_COUNTERS = 11
#: Record kinds are integers below this (the trace's four-bit kinds).
N_KINDS = 16

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
    ghosts : ndarray of int64, shape (W,)
        Per way emptied by a coherence invalidation, the line it held (its
        tag kept, marked invalid), until a fill takes the way or the line
        comes back to the set; -1 elsewhere.
    ghost_bytes : ndarray of int64, shape (W, 2)
        The first byte and the end of the bytes of the write that invalidated each ghost.
    ghost_filter : ndarray of int32, shape (F,)
        How many ghosts hash (:func:`cachesim.multicore_sets._filter_slot`) to each entry: a miss
        or fill looks for a ghost in its set only where this is nonzero.
        ``F`` is a power of two, :data:`GHOST_FILTER_SIZE` in a
        :class:`SharedState`: small enough to stay in the host's first-level cache.
    counts : ndarray of int64, shape (L, G, N_KINDS, N_SHARED_COUNTERS)
        Per level, instance (``G`` the most instances of a level), record
        kind and counter column (:data:`COHERENCE_MISSES` ...).
    served : ndarray of int64, shape (T, L + 1)
        Accesses of each hardware thread served by each level (``L``: memory).
    owners : ndarray of int64, shape (D, 2) or (0, 2)
        The sharers of lately written lines, so that a write searches for
        copies only where they may be: entry ``e`` (a hash of the
        first-level line, :func:`cachesim.multicore_sets._owner_slot`) is
        ``(line, mask)`` after a write by ``t`` removed the line from every
        instance that does not serve ``t`` (``mask`` then holds ``t``'s
        bit alone), and every fill of the line by a thread ``u`` since
        adds ``u``'s bit (bit ``u mod 64``): every instance holding the
        line serves a thread whose bit is in ``mask``. ``(-1, -1)``:
        unused; a line without an entry may be anywhere. Only a write's
        look-up and fills read or change it. ``D`` is a power of two,
        :data:`OWNERS_SIZE` in a :class:`SharedState`; (0, 2), every write
        searches every instance: levels with lines of different sizes (a
        fill there covers several first-level lines) or prefetchers (whose
        fills are not noted).
    """

    tags: np.ndarray
    stamps: np.ndarray
    ghosts: np.ndarray
    ghost_bytes: np.ndarray
    ghost_filter: np.ndarray
    counts: np.ndarray
    served: np.ndarray
    owners: np.ndarray


#: Entries of SharedArrays.ghost_filter (a power of two).
GHOST_FILTER_SIZE = 1 << 13
#: Entries of SharedArrays.owners (a power of two; 16 bytes each): 32 KB, as every fill of a first-level
#: line reads an entry and a small table stays in the host's nearer caches; a collision only makes a
#: write search the other instances, so the counts do not depend on the size.
OWNERS_SIZE = 1 << 11


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
        self.prefetch_geometry = P.prefetch_geometry(machine.hierarchy, self.machine_geometry.n_instances)
        self.reset()

    def reset(self) -> None:
        """Empty every instance and zero the counters."""
        machine = self.machine
        n_levels = len(machine.hierarchy.levels)
        total_ways = int(np.sum(self.machine_geometry.level_ways * self.machine_geometry.n_instances))
        try:
            self.tags = np.full(total_ways, -1, dtype=np.int64)
            self.stamps = np.zeros(total_ways, dtype=np.int64)
            self.ghosts = np.full(total_ways, -1, dtype=np.int64)
            self.ghost_bytes = np.zeros((total_ways, 2), dtype=np.int64)
        except MemoryError:
            raise MemoryError(f"shared hierarchy {machine.name!r}: the {total_ways:,} cache lines of its instances "
                              f"need {40 * total_ways / 2**30:,.1f} GiB of simulator state (40 bytes each), more "
                              "than this machine can allocate") from None
        most = int(self.machine_geometry.n_instances.max())
        self.counts = np.zeros((n_levels, most, N_KINDS, N_SHARED_COUNTERS), dtype=np.int64)
        self.served = np.zeros((machine.n_threads, n_levels + 1), dtype=np.int64)
        self.ghost_filter = np.zeros(GHOST_FILTER_SIZE, dtype=np.int32)
        uniform = not self.geometry.rel_shift.any() and self.prefetch_geometry is None
        self.owners = np.full((OWNERS_SIZE if uniform else 0, 2), -1, dtype=np.int64)
        self.clock = 0
        self.prefetch = None if self.prefetch_geometry is None else P.empty_prefetch_arrays(
            self.prefetch_geometry, total_ways, self.machine_geometry.n_instances)

    @property
    def arrays(self) -> SharedArrays:
        """The contents and counters as one bundle for :func:`simulate_threads_stream` (updated in place)."""
        return SharedArrays(self.tags, self.stamps, self.ghosts, self.ghost_bytes, self.ghost_filter, self.counts,
                            self.served, self.owners)

    def copy(self) -> "SharedState":
        """An independent clone: continuing either leaves the other untouched."""
        clone = SharedState.__new__(SharedState)
        clone.machine, clone.geometry, clone.machine_geometry = self.machine, self.geometry, self.machine_geometry
        for name in ("tags", "stamps", "ghosts", "ghost_bytes", "ghost_filter", "counts", "served", "owners"):
            setattr(clone, name, getattr(self, name).copy())
        clone.prefetch_geometry = self.prefetch_geometry
        clone.prefetch = None if self.prefetch is None else P.PrefetchArrays(*(array.copy() for array in self.prefetch))
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
    prefetch_counts : ndarray of int64, shape (L, G, 3), or None
        With prefetchers: per level and instance, the prefetches issued,
        useful and useless in this call (:mod:`cachesim.prefetch`).
    prefetch_pending : ndarray of int64, shape (L, G), or None
        Prefetched lines still unused in each instance after the call.
    """

    machine: SharedHierarchy
    counts: np.ndarray
    served: np.ndarray
    by_kind: bool
    state: SharedState
    prefetch_counts: np.ndarray | None = None
    prefetch_pending: np.ndarray | None = None

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

    def level_frame(self) -> pd.DataFrame:
        """One row per level, summed over its instances and kinds: level, instances, then the
        counts of :meth:`to_frame`."""
        machine = self.machine
        totals = self.level_counts()
        frame = pd.DataFrame({
            "level": pd.Series(machine.hierarchy.level_names, dtype="string"),
            "instances": np.array([machine.n_instances(level) for level in range(len(totals))], dtype=np.int64),
        })
        for column, index in _COLUMNS:
            frame[column] = totals[:, index].astype(np.int64)
        return frame

    def to_dict(self) -> dict:
        """Plain JSON-ready numbers: the machine, per level totals, per instance (and kind) rows,
        and each thread's accesses by serving level (``served``, the last entry memory)."""
        def records(frame):
            return [{key: (value.item() if hasattr(value, "item") else value) for key, value in row.items()}
                    for row in frame.astype(object).to_dict(orient="records")]

        return {"machine": self.machine.to_dict(), "levels": records(self.level_frame()),
                "instances": records(self.to_frame()), "served": self.served.tolist()}
