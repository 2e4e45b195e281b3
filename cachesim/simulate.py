"""Simulation of byte-address streams through a cache hierarchy.

>>> from cachesim import simulate, alpha21164
>>> result = simulate(addresses, alpha21164())           # doctest: +SKIP
>>> result.to_frame()                                    # doctest: +SKIP

A :class:`CacheState` holds the contents of every level. Passing a state
instead of a hierarchy continues it, so a stream run in pieces gives exactly
the totals of one run; :meth:`CacheState.copy` clones it (for what-if
branches) and :meth:`CacheState.reset` empties it. :func:`simulate_many` runs
independent states (one per simulated CPU) on many streams in one call.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cachesim import kernels as K
from cachesim import prefetch as P
from cachesim import tlb as T
from cachesim.config import Hierarchy
from cachesim.inputs import as_addresses, as_pcs, as_writes
from rtcommon.validate import InputError

__all__ = ["CacheState", "SimulationResult", "as_addresses", "as_writes", "cache_geometry", "simulate",
           "simulate_many", "tlb_geometry"]

_POLICY_CODES = {"lru": K.LRU, "fifo": K.FIFO, "random": K.RANDOM}
_INCLUSION_CODES = {"non-inclusive": K.NON_INCLUSIVE, "inclusive": K.INCLUSIVE, "exclusive": K.EXCLUSIVE}


def cache_geometry(hierarchy: Hierarchy) -> K.CacheGeometry:
    """The kernels' view of a hierarchy (see :class:`cachesim.kernels.CacheGeometry`)."""
    levels = hierarchy.levels
    shifts = np.array([level.line_size.bit_length() - 1 for level in levels], dtype=np.int64)
    n_sets = np.array([level.n_sets for level in levels], dtype=np.int64)
    ways = np.array([level.ways for level in levels], dtype=np.int64)
    sizes = n_sets * ways
    return K.CacheGeometry(
        line_shift=int(shifts[0]),
        rel_shift=shifts - shifts[0],
        n_sets=n_sets,
        set_mask=np.array([n - 1 if n & (n - 1) == 0 else -1 for n in n_sets], dtype=np.int64),
        ways=ways,
        policy=np.array([_POLICY_CODES[level.policy] for level in levels], dtype=np.int64),
        offset=np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64),
        inclusion=_INCLUSION_CODES[hierarchy.inclusion],
        seeds=np.array([_seed_state(level.seed, index) for index, level in enumerate(levels)],
                       dtype=np.uint64),
        write_allocate=np.array([level.write_allocate for level in levels], dtype=np.bool_),
    )


_TLB_POLICY_CODES = {"nlu": T.NLU, "lru": T.TLB_LRU, "fifo": T.TLB_FIFO}


def tlb_geometry(hierarchy: Hierarchy) -> T.TlbGeometry | None:
    """The kernels' view of a hierarchy's TLB (None when it has none)."""
    tlb = hierarchy.tlb
    if tlb is None:
        return None
    return T.TlbGeometry(page_shift=tlb.page_size.bit_length() - 1, entries=tlb.entries,
                         policy=_TLB_POLICY_CODES[tlb.policy])


def _seed_state(seed: int, level: int) -> int:
    # Mix the level in so that levels with one seed draw differently.
    value = (seed * 0x9E3779B97F4A7C15 + (level + 1) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    return value or 0x2545F4914F6CDD1D


class CacheState:
    """Contents and cumulative counters of one hierarchy (one CPU).

    Parameters
    ----------
    hierarchy : Hierarchy
        The configuration; fixed for the life of the state.
    """

    def __init__(self, hierarchy: Hierarchy):
        if not isinstance(hierarchy, Hierarchy):
            raise InputError(f"CacheState needs a Hierarchy, got {type(hierarchy).__name__}")
        self.hierarchy = hierarchy
        self._geometry = cache_geometry(hierarchy)
        self._tlb_geometry = tlb_geometry(hierarchy)
        self._prefetch_geometry = P.prefetch_geometry(hierarchy)
        self.reset()

    @property
    def geometry(self) -> K.CacheGeometry:
        """The hierarchy's parameters as the compiled kernels take them."""
        return self._geometry

    @property
    def arrays(self) -> K.CacheArrays:
        """``tags``, ``stamps`` and ``counts`` as one bundle for the kernels
        of :mod:`cachesim.kernels` (views: the kernels update this state)."""
        return K.CacheArrays(self.tags, self.stamps, self.counts)

    @property
    def tlb_geometry(self) -> T.TlbGeometry | None:
        """The TLB's parameters as :func:`cachesim.tlb.tlb_lookup` takes them (None: no TLB)."""
        return self._tlb_geometry

    @property
    def tlb_arrays(self) -> T.TlbArrays | None:
        """The TLB's contents and counters for :func:`cachesim.tlb.tlb_lookup` (None: no TLB)."""
        return self.tlb

    @property
    def prefetch_geometry(self) -> P.PrefetchGeometry | None:
        """The prefetchers' parameters as :func:`cachesim.prefetch.simulate_prefetching` takes them
        (None: no level has a prefetcher)."""
        return self._prefetch_geometry

    def reset(self) -> None:
        """Empty every level and zero the counters."""
        n_levels = len(self.hierarchy.levels)
        total_ways = int(np.sum(self._geometry.n_sets * self._geometry.ways))
        try:
            self.tags = np.full(total_ways, -1, dtype=np.int64)
            self.stamps = np.zeros(total_ways, dtype=np.int64)
        except MemoryError:
            raise MemoryError(f"hierarchy {self.hierarchy.name!r}: its {total_ways:,} cache lines need "
                              f"{16 * total_ways / 2**30:,.1f} GiB of simulator state (tags and stamps, "
                              "8 bytes each), more than this machine can allocate") from None
        self.counts = np.zeros((n_levels, K.N_COUNTERS), dtype=np.int64)
        self.clock = 0
        self.tlb = T.empty_tlb(self.hierarchy.tlb.entries) if self.hierarchy.tlb is not None else None
        self.prefetch = (None if self._prefetch_geometry is None
                         else P.empty_prefetch_arrays(self._prefetch_geometry, total_ways))

    def copy(self) -> "CacheState":
        """An independent clone: continuing either leaves the other untouched."""
        clone = CacheState.__new__(CacheState)
        clone.hierarchy = self.hierarchy
        clone._geometry = self._geometry
        clone._tlb_geometry = self._tlb_geometry
        clone._prefetch_geometry = self._prefetch_geometry
        clone.prefetch = None if self.prefetch is None else P.PrefetchArrays(*(array.copy() for array in self.prefetch))
        clone.tlb = None if self.tlb is None else T.TlbArrays(*(array.copy() for array in self.tlb))
        clone.tags = self.tags.copy()
        clone.stamps = self.stamps.copy()
        clone.counts = self.counts.copy()
        clone.clock = self.clock
        return clone

    def totals(self) -> "SimulationResult":
        """Cumulative counts of everything run on this state since the last reset."""
        prefetch_counts, pending = self._prefetch_counts(None, None)
        return SimulationResult(self.hierarchy, self.counts.copy(),
                                tlb_counts=None if self.tlb is None else self.tlb.counts.copy(),
                                prefetch_counts=prefetch_counts, prefetch_pending=pending)

    def _prefetch_counts(self, before: np.ndarray | None, pending_before: np.ndarray | None):
        """Prefetches issued, useful and useless per level (int64, (L, 3)) since ``before`` (the
        kernel's counts then; None: since the reset), and the pending ones now; (None, None) without
        prefetchers. A line that left unused is one issued that is neither useful nor pending."""
        if self.prefetch is None:
            return None, None
        pending = P.pending_prefetches(self.prefetch, self.tags, self._geometry)
        issued_useful = self.prefetch.counts - (0 if before is None else before)
        useless = issued_useful[:, P.ISSUED] - issued_useful[:, P.USEFUL] - (pending - (0 if pending_before is None
                                                                                      else pending_before))
        return np.column_stack([issued_useful, useless]).astype(np.int64), pending

    def resident_lines(self, level: int | str) -> np.ndarray:
        """Sorted line numbers (address // line_size) held by one level."""
        index = self.hierarchy.level_names.index(level) if isinstance(level, str) else int(level)
        geometry = self._geometry
        start = geometry.offset[index]
        stop = start + geometry.n_sets[index] * geometry.ways[index]
        lines = self.tags[start:stop]
        return np.sort(lines[lines >= 0])


@dataclass(frozen=True)
class SimulationResult:
    """Per-level counts of one simulation call.

    Attributes
    ----------
    hierarchy : Hierarchy
    counts : ndarray of int64, shape (L, N_COUNTERS)
        Per level, in the columns of :mod:`cachesim.kernels`: accesses, hits,
        misses (reads and writes together), evictions, back-invalidations,
        then writes, write hits and write misses.
    served_by : ndarray of uint8, shape (N,), or None
        Level that served each access (``L`` means memory), when requested.
    state : CacheState or None
        The state after the call, to continue from.
    tlb_counts : ndarray of int64, shape (3,), or None
        TLB lookups, hits and misses, when the hierarchy has a TLB.
    prefetch_counts : ndarray of int64, shape (L, 3), or None
        When a level has a prefetcher: per level, the prefetches issued,
        useful (a demand access hit the prefetched line in that level) and
        useless (the line left the level unused, evicted or invalidated),
        in this call (:mod:`cachesim.prefetch`); zero where a level has none.
    prefetch_pending : ndarray of int64, shape (L,), or None
        Prefetched lines still unused in each level after the call.
    """

    hierarchy: Hierarchy
    counts: np.ndarray
    served_by: np.ndarray | None = None
    state: CacheState | None = None
    tlb_counts: np.ndarray | None = None
    prefetch_counts: np.ndarray | None = None
    prefetch_pending: np.ndarray | None = None

    @property
    def tlb_accesses(self) -> int | None:
        return None if self.tlb_counts is None else int(self.tlb_counts[T.TLB_ACCESSES])

    @property
    def tlb_hits(self) -> int | None:
        return None if self.tlb_counts is None else int(self.tlb_counts[T.TLB_HITS])

    @property
    def tlb_misses(self) -> int | None:
        return None if self.tlb_counts is None else int(self.tlb_counts[T.TLB_MISSES])

    @property
    def tlb_cycles(self) -> float | None:
        """TLB misses times the TLB's fixed miss penalty (None: no TLB)."""
        return None if self.tlb_counts is None else self.tlb_misses * self.hierarchy.tlb.miss_cycles

    @property
    def prefetches_issued(self) -> np.ndarray | None:
        return None if self.prefetch_counts is None else self.prefetch_counts[:, 0]

    @property
    def prefetches_useful(self) -> np.ndarray | None:
        return None if self.prefetch_counts is None else self.prefetch_counts[:, 1]

    @property
    def prefetches_useless(self) -> np.ndarray | None:
        return None if self.prefetch_counts is None else self.prefetch_counts[:, 2]

    @property
    def accesses(self) -> np.ndarray:
        return self.counts[:, K.ACCESSES]

    @property
    def hits(self) -> np.ndarray:
        return self.counts[:, K.HITS]

    @property
    def misses(self) -> np.ndarray:
        return self.counts[:, K.MISSES]

    @property
    def evictions(self) -> np.ndarray:
        return self.counts[:, K.EVICTIONS]

    @property
    def invalidations(self) -> np.ndarray:
        return self.counts[:, K.INVALIDATIONS]

    @property
    def write_accesses(self) -> np.ndarray:
        return self.counts[:, K.WRITES]

    @property
    def write_hits(self) -> np.ndarray:
        return self.counts[:, K.WRITE_HITS]

    @property
    def write_misses(self) -> np.ndarray:
        return self.counts[:, K.WRITE_MISSES]

    @property
    def read_accesses(self) -> np.ndarray:
        return self.accesses - self.write_accesses

    @property
    def read_hits(self) -> np.ndarray:
        return self.hits - self.write_hits

    @property
    def read_misses(self) -> np.ndarray:
        return self.misses - self.write_misses

    @property
    def hit_rate(self) -> np.ndarray:
        """Hits / accesses per level (NaN where a level saw no access)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.accesses > 0, self.hits / np.maximum(self.accesses, 1), np.nan)

    @property
    def memory_accesses(self) -> int:
        """Accesses served by memory: the misses of the last level."""
        return int(self.misses[-1])

    def to_frame(self) -> pd.DataFrame:
        """One row per level: level, size, line_size, ways, accesses, hits,
        misses, evictions, invalidations, hit_rate, then write_accesses,
        write_hits, write_misses (the writes among accesses, hits, misses);
        with prefetchers, then prefetches_issued, prefetches_useful,
        prefetches_useless and prefetches_pending."""
        levels = self.hierarchy.levels
        prefetch = {} if self.prefetch_counts is None else {
            "prefetches_issued": self.prefetches_issued.astype(np.int64),
            "prefetches_useful": self.prefetches_useful.astype(np.int64),
            "prefetches_useless": self.prefetches_useless.astype(np.int64),
            "prefetches_pending": self.prefetch_pending.astype(np.int64),
        }
        return pd.DataFrame({
            "level": pd.Series([level.name for level in levels], dtype="string"),
            "size": np.array([level.size for level in levels], dtype=np.int64),
            "line_size": np.array([level.line_size for level in levels], dtype=np.int64),
            "ways": np.array([level.ways for level in levels], dtype=np.int64),
            "accesses": self.accesses.astype(np.int64),
            "hits": self.hits.astype(np.int64),
            "misses": self.misses.astype(np.int64),
            "evictions": self.evictions.astype(np.int64),
            "invalidations": self.invalidations.astype(np.int64),
            "hit_rate": self.hit_rate.astype(np.float64),
            "write_accesses": self.write_accesses.astype(np.int64),
            "write_hits": self.write_hits.astype(np.int64),
            "write_misses": self.write_misses.astype(np.int64),
            **prefetch,
        })

    def to_dict(self) -> dict:
        """Plain JSON-ready numbers, with the hierarchy."""
        return {
            "hierarchy": self.hierarchy.to_dict(),
            "levels": [
                {key: (None if isinstance(value, float) and np.isnan(value) else value)
                 for key, value in row.items()}
                for row in self.to_frame().astype(object).to_dict(orient="records")
            ],
            "memory_accesses": self.memory_accesses,
            **({"tlb": {"accesses": self.tlb_accesses, "hits": self.tlb_hits, "misses": self.tlb_misses,
                        "cycles": self.tlb_cycles}} if self.tlb_counts is not None else {}),
        }


def _check_line_range(addresses: np.ndarray, hierarchy: Hierarchy) -> None:
    # Line numbers are kept as int64; with 1-byte lines an address >= 2**63
    # would not fit.
    if hierarchy.levels[0].line_size == 1 and addresses.size and addresses.max() >= 2**63:
        raise InputError("with a 1-byte first-level line, addresses must be below 2**63")


def simulate(addresses, hierarchy: Hierarchy | CacheState, *, writes=None, pcs=None,
             return_levels: bool = False) -> SimulationResult:
    """Run a stream of byte addresses through a cache hierarchy in one compiled call.

    Parameters
    ----------
    addresses : array_like of int, shape (N,)
        Byte addresses (non-negative, below 2**64), in access order; each
        access reads (or writes) the line holding that byte.
    hierarchy : Hierarchy or CacheState
        A configuration (runs on empty caches) or a state to continue; a
        state is updated in place.
    writes : array_like of bool, shape (N,), optional
        True where the access is a write. Omitted (or all false): every
        access is a read, with results identical to a call without it.
        Semantics of writes per level: :mod:`cachesim.by_access`.
    pcs : array_like of int, shape (N,), optional
        A non-negative PC-like id per access (the record kind, say), which
        indexes stride prefetchers' tables; omitted: id 0 for every access.
        Used only by stride prefetchers.
    return_levels : bool
        Also return ``served_by`` (uint8, (N,)): the level index that served
        each access, ``L`` meaning memory.

    Returns
    -------
    SimulationResult
        Counts of this call only, and the state after it (``.state``); with
        the TLB's lookups, hits and misses when the hierarchy has a TLB
        (every access, read or write, is looked up), and the prefetchers'
        counts when a level has one (rules in :mod:`cachesim.prefetch`;
        the access clock then also advances once per issued prefetch).
    """
    state = hierarchy if isinstance(hierarchy, CacheState) else CacheState(hierarchy)
    addresses = as_addresses(addresses)
    flags = as_writes(writes, addresses.size)
    _check_line_range(addresses, state.hierarchy)
    ids = as_pcs(pcs, addresses.size)
    served_by = np.zeros(addresses.size if return_levels else 0, dtype=np.uint8)
    before = state.counts.copy()
    if state.prefetch is None:
        state.clock = int(K.simulate_writes(addresses, flags, state.geometry, state.arrays, state.clock, served_by,
                                            return_levels))
        prefetch_counts = pending = None
    else:
        if addresses.size and addresses.max() >= 2**63:
            raise InputError("with prefetchers, addresses must be below 2**63")
        prefetch_before = state.prefetch.counts.copy()
        pending_before = P.pending_prefetches(state.prefetch, state.tags, state.geometry)
        state.clock = int(P.simulate_prefetching(addresses, flags, ids, state.geometry, state.arrays, state.clock,
                                                 served_by, return_levels, state.prefetch_geometry,
                                                 state.prefetch))
        prefetch_counts, pending = state._prefetch_counts(prefetch_before, pending_before)
    return SimulationResult(state.hierarchy, state.counts - before, served_by if return_levels else None, state,
                            _run_tlb(addresses, state), prefetch_counts, pending)


def _run_tlb(addresses: np.ndarray, state: CacheState) -> np.ndarray | None:
    """Look every address up in the state's TLB; the counts of this call (None: no TLB)."""
    if state.tlb is None:
        return None
    before = state.tlb.counts.copy()
    T.tlb_lookup(addresses, state.tlb_geometry, state.tlb)
    return state.tlb.counts - before


def simulate_many(streams, hierarchy: Hierarchy | None = None, *, states: list[CacheState] | None = None,
                  writes=None, return_levels: bool = False) -> list[SimulationResult]:
    """Run independent streams, each on its own hierarchy state, in one parallel call.

    Parameters
    ----------
    streams : sequence of array_like, length S
        Stream ``s`` runs on state ``s`` (one simulated CPU each).
    hierarchy : Hierarchy, optional
        Configuration of fresh states; omit when ``states`` is given.
    states : list of CacheState, optional
        States to continue (updated in place), all of one hierarchy.
    writes : sequence of array_like of bool, length S, optional
        Write flags of each stream (see :func:`simulate`); omitted: all reads.
    return_levels : bool
        Also return per-access ``served_by`` for every stream.

    Returns
    -------
    list of SimulationResult, length S
    """
    streams = [as_addresses(stream, name=f"streams[{index}]") for index, stream in enumerate(streams)]
    if writes is not None:
        writes = list(writes)
        if len(writes) != len(streams):
            raise InputError(f"simulate_many got {len(streams)} streams but {len(writes)} write-flag arrays")
        flags = [as_writes(flag, stream.size, name=f"writes[{index}]")
                 for index, (flag, stream) in enumerate(zip(writes, streams))]
        if any(flag.size for flag in flags):
            flags = [flag if flag.size else np.zeros(stream.size, dtype=np.bool_)
                     for flag, stream in zip(flags, streams)]
            all_writes = np.concatenate(flags) if flags else np.zeros(0, dtype=np.bool_)
        else:
            all_writes = np.zeros(0, dtype=np.bool_)
    else:
        all_writes = np.zeros(0, dtype=np.bool_)
    if states is None:
        if hierarchy is None:
            raise InputError("simulate_many needs a hierarchy or a list of states")
        states = [CacheState(hierarchy) for _ in streams]
    if len(states) != len(streams):
        raise InputError(f"simulate_many got {len(streams)} streams but {len(states)} states")
    if not streams:
        return []
    reference = states[0].hierarchy
    if hierarchy is not None and hierarchy != reference:
        raise InputError("simulate_many: the states were made for another hierarchy than the one given")
    for index, state in enumerate(states):
        if state.hierarchy != reference:
            raise InputError(f"simulate_many: states[{index}] has another hierarchy than states[0]")
        _check_line_range(streams[index], reference)
    lengths = np.array([stream.size for stream in streams], dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    if reference.prefetches:
        # The prefetching walk has no parallel entry: the streams run one after another.
        return [simulate(stream, state, writes=all_writes[start:stop] if all_writes.size else None,
                         return_levels=return_levels)
                for stream, state, start, stop in zip(streams, states, starts[:-1], starts[1:])]
    addresses = np.concatenate(streams)
    tags = np.stack([state.tags for state in states])
    stamps = np.stack([state.stamps for state in states])
    counts = np.stack([state.counts for state in states])
    before = counts.copy()
    clocks = np.array([state.clock for state in states], dtype=np.int64)
    served_by = np.zeros(addresses.size if return_levels else 0, dtype=np.uint8)
    K.simulate_streams(addresses, starts, states[0].geometry, K.CacheArrays(tags, stamps, counts), clocks,
                       served_by, return_levels, all_writes)
    results = []
    for index, state in enumerate(states):
        state.tags, state.stamps = tags[index].copy(), stamps[index].copy()
        state.counts, state.clock = counts[index].copy(), int(clocks[index])
        levels = served_by[starts[index]:starts[index + 1]] if return_levels else None
        results.append(SimulationResult(reference, counts[index] - before[index], levels, state,
                                        _run_tlb(streams[index], state)))
    return results
