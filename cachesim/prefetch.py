"""Hardware prefetchers: compiled models over named state arrays.

A level of a :class:`~cachesim.config.Hierarchy` may have a
:class:`~cachesim.prefetch_config.Prefetcher`; a hierarchy with one runs
through :func:`simulate_prefetching`, a walk of its own, so the paths
without prefetchers (:mod:`cachesim.kernels`) are unchanged. Sources of the
models and a worked example: ``docs/prefetch.md``.

Rules, per access (every access is a demand access; prefetches are not
accesses and are not counted among a level's accesses, hits or misses):

1. The demand access walks down the levels and fills the levels that missed,
   exactly as without prefetchers (:mod:`cachesim.by_access`).
2. Then each level with a prefetcher that the access reached (level 0, and
   below it the levels the access missed down to the one that served it),
   from the first level down, sees the access: a *miss* when the access
   missed the level, else a hit. By its kind and trigger it yields candidate
   lines of its own line size:

   - next-line, with trigger ``miss`` (Smith 1982's prefetch on miss),
     ``access`` (prefetch always) or ``tagged`` (a miss, or the first demand
     hit of a prefetched line): lines ``x + distance + j`` for ``j`` in
     ``0 .. degree - 1``, ``x`` the accessed line;
   - stride: the access (with trigger ``access``, or only a miss with
     ``miss``) updates the entry ``pc mod table_size`` of the level's
     reference prediction table (Chen & Baer 1995). A new id takes the entry
     over: ``previous = address``, ``stride = 0``, state *initial*, no
     prefetch. Else, with ``correct`` meaning ``address - previous ==
     stride``: initial goes to steady when correct, else to transient with
     the new stride; transient goes to steady when correct, else to
     no-prediction with the new stride; steady stays when correct, else goes
     to initial keeping its stride; no-prediction goes to transient when
     correct, else stays with the new stride; ``previous = address`` always.
     In the steady state after the update, with a non-zero stride, the
     candidates are the lines of ``address + (distance + j) * stride`` for
     ``j`` in ``0 .. degree - 1`` (those below address 0 are dropped).
3. A candidate already in the level is dropped (a probe that changes
   nothing). Otherwise the prefetch is *issued*: the access clock advances
   by one (so a prefetched line is newer than the demand line that caused
   it, and random replacement draws on this clock), the line is looked up
   from the level below down (a hit there refreshes LRU recency like a
   demand hit, but counts nothing), and it fills the levels that missed,
   from memory's side up to the prefetching level, like a demand fill:
   evictions and, in an inclusive hierarchy, back-invalidations of the
   levels above are counted as for demand fills. Levels above the
   prefetching one are not filled.

Counts per level with a prefetcher: prefetches *issued*; *useful*, the
prefetched lines that a demand access hit in this level before they left
it; *useless*, those that left it unused (evicted, or invalidated by
inclusion); and *pending*, those still in it unused (a state's issued =
useful + useless + pending). Timing is not modelled: a prefetch completes at
once, so nothing is counted late.

State (:class:`PrefetchArrays`): ``marks`` (W,) holds, per way of the
hierarchy, the line a prefetch put there, or -1; a way holds an unused
prefetched line exactly when its tag equals its mark (a demand fill or a
demand hit clears the mark). ``table`` (T, 4) holds the stride tables of all
levels, one row per entry: id (-1: empty), previous address, stride, state.
``counts`` (L, 2): issued and useful; useless follows from the marks
(:func:`pending_prefetches`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.full import _fill_levels, _lookup, _serving_level
from cachesim.prefetch_config import MAX_DEGREE
from cachesim.sets import INVALIDATIONS, ChunkBuffers, _add_counts, chunk_buffers
from rtcommon.jit import NO_REFCOUNTS

# Prefetcher kinds (PrefetchGeometry.kind); NO_PREFETCH for a level without one.
NO_PREFETCH, NEXT_LINE, STRIDE = 0, 1, 2
# Triggers (PrefetchGeometry.trigger).
ON_MISS, ON_ACCESS, TAGGED = 0, 1, 2
# States of a stride-table entry (Chen & Baer's four).
INITIAL, TRANSIENT, STEADY, NO_PREDICTION = 0, 1, 2, 3
# Columns of a stride-table row.
TABLE_ID, TABLE_PREVIOUS, TABLE_STRIDE, TABLE_STATE = 0, 1, 2, 3
# Columns of PrefetchArrays.counts.
ISSUED, USEFUL = 0, 1
N_PREFETCH_COUNTERS = 2

_KIND_CODES = {"next-line": NEXT_LINE, "stride": STRIDE}
_TRIGGER_CODES = {"miss": ON_MISS, "access": ON_ACCESS, "tagged": TAGGED}
# A stride times the furthest candidate's multiple stays below this, so that
# the candidate's address cannot wrap around.
_MAX_REACH = np.int64(1) << 62


class PrefetchWork(NamedTuple):
    """Work buffers of one :func:`simulate_prefetching` call.

    Attributes
    ----------
    demand, fetch : ChunkBuffers
        The per-level buffers of the demand accesses' walk and of the
        prefetches' (whose hits in lower levels are not demand hits).
    candidates : ndarray of int64, shape (MAX_DEGREE,)
        One trigger's candidate lines.
    """

    demand: ChunkBuffers
    fetch: ChunkBuffers
    candidates: np.ndarray


class PrefetchGeometry(NamedTuple):
    """The prefetchers' fixed parameters, per level of a hierarchy of ``L`` levels.

    Attributes
    ----------
    kind : ndarray of int64, shape (L,)
        :data:`NO_PREFETCH`, :data:`NEXT_LINE` or :data:`STRIDE`.
    trigger : ndarray of int64, shape (L,)
        :data:`ON_MISS`, :data:`ON_ACCESS` or :data:`TAGGED`.
    degree, distance : ndarray of int64, shape (L,)
    table_offset, table_size : ndarray of int64, shape (L,)
        Each stride prefetcher's rows in :attr:`PrefetchArrays.table` (size 0: none).
    """

    kind: np.ndarray
    trigger: np.ndarray
    degree: np.ndarray
    distance: np.ndarray
    table_offset: np.ndarray
    table_size: np.ndarray


class PrefetchArrays(NamedTuple):
    """The prefetchers' mutable state (updated in place).

    Attributes
    ----------
    marks : ndarray of int64, shape (W,)
        Per way of the hierarchy, the line a prefetch placed there, or -1.
    table : ndarray of int64, shape (T, 4)
        Stride-table rows: id (-1: empty), previous address, stride, state.
    counts : ndarray of int64, shape (L, N_PREFETCH_COUNTERS)
        Prefetches issued and useful per level.
    """

    marks: np.ndarray
    table: np.ndarray
    counts: np.ndarray


def prefetch_geometry(hierarchy, instances=None) -> PrefetchGeometry | None:
    """The kernels' view of a hierarchy's prefetchers (None when it has none).

    ``instances`` (int, (L,)) gives the instances of each level on a machine
    of shared levels (:mod:`cachesim.multicore`), each with its own stride
    table: instance ``g`` of level ``l`` owns the ``table_size[l]`` rows from
    ``table_offset[l] + g * table_size[l]``. None: one instance per level.
    """
    if not hierarchy.prefetches:
        return None
    prefetchers = [level.prefetcher for level in hierarchy.levels]
    sizes = np.array([p.table_size if p is not None and p.kind == "stride" else 0 for p in prefetchers],
                     dtype=np.int64)
    rows = sizes if instances is None else sizes * np.asarray(instances, dtype=np.int64)
    return PrefetchGeometry(
        kind=np.array([NO_PREFETCH if p is None else _KIND_CODES[p.kind] for p in prefetchers], dtype=np.int64),
        trigger=np.array([ON_MISS if p is None else _TRIGGER_CODES[p.trigger] for p in prefetchers],
                         dtype=np.int64),
        degree=np.array([0 if p is None else p.degree for p in prefetchers], dtype=np.int64),
        distance=np.array([0 if p is None else p.distance for p in prefetchers], dtype=np.int64),
        table_offset=np.concatenate(([0], np.cumsum(rows)[:-1])).astype(np.int64),
        table_size=sizes,
    )


def empty_prefetch_arrays(geometry: PrefetchGeometry, n_ways: int, instances=None) -> PrefetchArrays:
    """Fresh prefetcher state for a hierarchy of ``n_ways`` ways in all.

    With ``instances`` (as for :func:`prefetch_geometry`), ``counts`` has
    shape (L, G, N_PREFETCH_COUNTERS), ``G`` the most instances of a level.
    """
    n_levels = geometry.kind.shape[0]
    per_level = np.ones(n_levels, dtype=np.int64) if instances is None else np.asarray(instances, dtype=np.int64)
    table = np.zeros((int((geometry.table_size * per_level).sum()), 4), dtype=np.int64)
    table[:, TABLE_ID] = -1
    shape = (n_levels, N_PREFETCH_COUNTERS) if instances is None else (n_levels, int(per_level.max()),
                                                                       N_PREFETCH_COUNTERS)
    return PrefetchArrays(np.full(n_ways, -1, dtype=np.int64), table, np.zeros(shape, dtype=np.int64))


def pending_prefetches(prefetch: PrefetchArrays, tags: np.ndarray, cache_geometry) -> np.ndarray:
    """Prefetched lines still unused in each level (int64, (L,)); 0 where a level has no prefetcher."""
    held = (prefetch.marks == tags) & (tags >= 0)
    stops = cache_geometry.offset + cache_geometry.n_sets * cache_geometry.ways
    return np.array([int(held[start:stop].sum()) for start, stop in zip(cache_geometry.offset, stops)],
                    dtype=np.int64)


@njit(cache=True)
def simulate_prefetching(addresses, writes, pcs, geometry, state, clock, served_by, record, prefetch_geometry,
                         prefetch):
    """Run a stream through one state whose levels may have prefetchers.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
        Byte addresses in access order, below 2**63.
    writes : ndarray of bool, shape (N,) or (0,)
        True where the access is a write; (0,): all reads.
    pcs : ndarray of int64, shape (N,) or (0,)
        A non-negative PC-like id per access, which indexes the stride
        tables; (0,): every access has id 0.
    geometry : CacheGeometry
    state : CacheArrays
        Updated in place, as by :func:`cachesim.kernels.simulate_writes`.
    clock : int
        Access clock before the call; it advances once per access and once
        per issued prefetch.
    served_by : ndarray of uint8, shape (N,) or (0,)
        When ``record`` is true, receives the level that served each access.
    record : bool
    prefetch_geometry : PrefetchGeometry
    prefetch : PrefetchArrays
        Updated in place.

    Returns
    -------
    int
        The clock after the call.
    """
    demand = chunk_buffers()
    fetch = chunk_buffers()  # the prefetches' walks: their hits are not demand hits
    for buffers in (demand, fetch):
        buffers.level_hits[:] = 0
        buffers.level_write_hits[:] = 0
        buffers.level_invalidations[:] = 0
    work = PrefetchWork(demand, fetch, np.empty(MAX_DEGREE, dtype=np.int64))
    return _walk(addresses, writes, pcs, geometry, state, clock, served_by if record else served_by[:0],
                 prefetch_geometry, prefetch, work)


@njit(cache=True, **NO_REFCOUNTS)
def _walk(addresses, writes, pcs, geometry, state, clock, served_by, prefetch_geometry, prefetch, work):
    """The loop of :func:`simulate_prefetching`; records ``served_by`` when it is not empty."""
    n_levels = geometry.rel_shift.shape[0]
    demand = work.demand
    fetch = work.fetch
    candidates = work.candidates
    record = served_by.shape[0] > 0
    marks = prefetch.marks
    kind = prefetch_geometry.kind
    has_writes = writes.shape[0] > 0
    has_pcs = pcs.shape[0] > 0
    n_writes = np.int64(0)
    for i in range(addresses.shape[0]):
        address = np.int64(addresses[i])
        clock += 1
        is_write = has_writes and writes[i]
        if is_write:
            n_writes += 1
        served = _serving_level(address >> geometry.line_shift, 0, geometry, state, None, clock, is_write, demand)
        if record:
            served_by[i] = served
        first_use = False
        if served < n_levels and kind[served] != NO_PREFETCH:
            line = demand.level_lines[served]
            slot = _lookup(line, served, geometry, state, None)
            if marks[slot] == line:
                marks[slot] = -1
                prefetch.counts[served, USEFUL] += 1
                first_use = True
        _fill_levels(served, 0, geometry, state, None, clock, is_write, demand)
        _unmark(0, served, geometry, state, kind, marks, demand.level_lines)
        pc = pcs[i] if has_pcs else np.int64(0)
        for level in range(min(served + 1, n_levels)):
            if kind[level] == NO_PREFETCH:
                continue
            level_shift = geometry.line_shift + geometry.rel_shift[level]
            n_candidates = _candidates(level, level_shift, address, pc, level < served,
                                       first_use and level == served, prefetch_geometry, prefetch.table,
                                       candidates)
            for k in range(n_candidates):
                clock = _issue(candidates[k], level, geometry, state, kind, prefetch, fetch, clock)
    _add_counts(state.counts, addresses.shape[0], n_writes, demand.level_hits, demand.level_write_hits,
                demand.level_invalidations)
    for level in range(n_levels):
        state.counts[level, INVALIDATIONS] += fetch.level_invalidations[level]
    return clock


@njit(cache=True, inline="always")
def _unmark(first, stop, geometry, state, kind, marks, lines):
    """Clear the marks of the ways that levels ``first .. stop - 1`` just filled with ``lines[level]``."""
    for level in range(first, stop):
        if kind[level] != NO_PREFETCH:
            slot = _lookup(lines[level], level, geometry, state, None)
            if slot >= 0:
                marks[slot] = -1


@njit(cache=True, inline="always")
def _candidates(level, level_shift, address, pc, missed, first_use, prefetch_geometry, table, out):
    """Write the lines a level's prefetcher asks for after an access into ``out``; return how many."""
    trigger = prefetch_geometry.trigger[level]
    degree = prefetch_geometry.degree[level]
    distance = prefetch_geometry.distance[level]
    if trigger == ON_MISS and not missed:
        return 0
    if prefetch_geometry.kind[level] == NEXT_LINE:
        if trigger == TAGGED and not (missed or first_use):
            return 0
        line = address >> level_shift
        for j in range(degree):
            out[j] = line + distance + j
        return degree
    row = prefetch_geometry.table_offset[level] + pc % prefetch_geometry.table_size[level]
    if table[row, TABLE_ID] != pc:
        table[row, TABLE_ID] = pc
        table[row, TABLE_PREVIOUS] = address
        table[row, TABLE_STRIDE] = 0
        table[row, TABLE_STATE] = INITIAL
        return 0
    seen = address - table[row, TABLE_PREVIOUS]
    entry = table[row, TABLE_STATE]
    if seen == table[row, TABLE_STRIDE]:
        entry = TRANSIENT if entry == NO_PREDICTION else STEADY
    elif entry == STEADY:
        entry = INITIAL
    else:
        entry = TRANSIENT if entry == INITIAL else NO_PREDICTION
        table[row, TABLE_STRIDE] = seen
    table[row, TABLE_STATE] = entry
    table[row, TABLE_PREVIOUS] = address
    stride = table[row, TABLE_STRIDE]
    if entry != STEADY or stride == 0 or abs(stride) >= _MAX_REACH // (distance + degree):
        return 0
    n = 0
    for j in range(degree):
        target = address + (distance + j) * stride
        if target >= 0:
            out[n] = target >> level_shift
            n += 1
    return n


@njit(cache=True, inline="always")
def _issue(line, level, geometry, state, kind, prefetch, fetch, clock):
    """Prefetch ``line`` into ``level`` unless it is there; return the clock after it."""
    if _lookup(line, level, geometry, state, None) >= 0:
        return clock
    clock += 1
    fetch.level_lines[level] = line
    served = _serving_level(line << geometry.rel_shift[level], level + 1, geometry, state, None, clock, False,
                            fetch)
    _fill_levels(served, level, geometry, state, None, clock, False, fetch)
    _unmark(level + 1, served, geometry, state, kind, prefetch.marks, fetch.level_lines)
    prefetch.marks[_lookup(line, level, geometry, state, None)] = line
    prefetch.counts[level, ISSUED] += 1
    return clock
