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
  parallel;
- :func:`simulate_writes_into` is :func:`simulate_into` for a stream whose
  accesses may be writes: a bool array beside the addresses (semantics in
  :mod:`cachesim.by_access`);
- the data TLB has kernels of its own, in :mod:`cachesim.tlb`: its state is
  separate from the caches' and it is looked up on every access, so a caller
  runs :func:`cachesim.tlb.tlb_lookup` on the same addresses.

Each takes the hierarchy's :class:`CacheGeometry` (from
:attr:`CacheState.geometry <cachesim.CacheState.geometry>`) and its
:class:`CacheArrays` (from :attr:`CacheState.arrays
<cachesim.CacheState.arrays>`), and returns the access clock after the call,
to be passed to the next one.

A schedule simulation that replays pixels (coherence's ``_run``) would, per
pixel, with ``buffer[:n]`` its addresses and ``flags[:n]`` their write flags::

    clock = simulate_writes_into(buffer[:n], flags[:n], geometry, cache, clock, served, False, work)
    misses = tlb_lookup(buffer[:n], tlb_geometry, TlbArrays(pages[cpu], stamps[cpu], cursor[cpu],
                                                            tlb_counts[process]))
    cycles += misses * tlb_miss_cycles

with ``tlb_geometry`` from :attr:`CacheState.tlb_geometry
<cachesim.CacheState.tlb_geometry>`, the stacked TLBs from
:func:`cachesim.tlb.empty_tlbs` and ``tlb_miss_cycles`` from
``hierarchy.tlb.miss_cycles``. Read-only replays keep calling
:func:`simulate_into` unchanged.

State layout of one hierarchy of ``L`` levels (:class:`CacheArrays`):

- ``tags`` int64 (W,): the line number held by each way, or -1.
  Level ``l`` owns ``tags[offset[l] : offset[l] + n_sets[l] * ways[l]]``;
  set ``s`` of that level is the ``ways[l]`` entries from
  ``offset[l] + s * ways[l]``.
- ``stamps`` int64 (W,): the access clock of the last use (LRU) or
  of the fill (FIFO); unused for random replacement and direct-mapped levels.
- ``counts`` int64 (L, N_COUNTERS): columns :data:`ACCESSES`, :data:`HITS`,
  :data:`MISSES` (reads and writes together), :data:`EVICTIONS`,
  :data:`INVALIDATIONS`, and :data:`WRITES`, :data:`WRITE_HITS`,
  :data:`WRITE_MISSES` (the writes among them) per level.

Line numbers are byte addresses shifted right by the first level's line shift
(``CacheGeometry.line_shift``), then by ``rel_shift[l]`` for level ``l``.
"""
import numpy as np
from numba import njit, prange

from cachesim.by_access import _simulate_by_access, _simulate_indexed
from cachesim.by_level import _simulate_by_level
from cachesim.direct_first import _simulate_direct_first, _simulate_direct_first_skips, serves_direct_first
from cachesim.full import uses_index
from cachesim.sets import (ACCESSES, CHUNK, EVICTIONS, EXCLUSIVE, FIFO, HITS, INCLUSIVE, INVALIDATIONS, LRU,
                           MISSES, N_COUNTERS, NON_INCLUSIVE, RANDOM, WRITE_HITS, WRITE_MISSES, WRITES,
                           CacheArrays, CacheGeometry, ChunkBuffers, chunk_buffers)

__all__ = [
    "ACCESSES", "CHUNK", "EVICTIONS", "EXCLUSIVE", "FIFO", "HITS", "INCLUSIVE", "INVALIDATIONS", "LRU",
    "MISSES", "N_COUNTERS", "NON_INCLUSIVE", "RANDOM", "WRITES", "WRITE_HITS", "WRITE_MISSES",
    "CacheArrays", "CacheGeometry", "ChunkBuffers", "chunk_buffers", "simulate_into", "simulate_stream",
    "simulate_streams", "simulate_writes", "simulate_writes_into", "simulate_skips_into",
]

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

    A long stream through a large fully associative level is indexed, as in
    :func:`simulate_writes`.
    """
    return simulate_writes(addresses, np.zeros(0, dtype=np.bool_), geometry, state, clock, served_by, record)


@njit(cache=True, inline="always")
def simulate_into(addresses, geometry, state, clock, served_by, record, work):
    """:func:`simulate_stream` with caller-owned work buffers.

    Parameters are those of :func:`simulate_stream`, plus ``work``
    (:class:`ChunkBuffers`), reused across calls: the entry point for other
    packages' compiled code that feeds many short streams (one pixel's reads,
    say) to one state. Every access is a read.

    Large fully associative levels are scanned here, never indexed
    (:mod:`cachesim.full`): a short stream would not repay building the
    index, and leaving the indexed walk out keeps its compilation (a good
    part of the walk's) out of every caller compiled around this kernel.
    :func:`simulate_stream` indexes a long stream.
    """
    if geometry.inclusion == NON_INCLUSIVE:
        return _simulate_by_level(addresses, geometry, state, clock, served_by, record, work)
    if serves_direct_first(geometry):
        return _simulate_direct_first(addresses, np.zeros(0, dtype=np.bool_), geometry, state, clock, served_by,
                                     record, work)
    return _simulate_by_access(addresses, np.zeros(0, dtype=np.bool_), geometry, state, clock, served_by,
                               record, work)


@njit(cache=True, inline="always")
def simulate_writes_into(addresses, writes, geometry, state, clock, served_by, record, work):
    """:func:`simulate_into` for a stream of reads and writes.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
    writes : ndarray of bool, shape (N,) or (0,)
        True where the access is a write; an empty array means all reads
        (the result is then exactly that of :func:`simulate_into`).
    geometry, state, clock, served_by, record, work
        As for :func:`simulate_into`.

    Returns
    -------
    int
        The clock after the last access.

    Read-only streams through a non-inclusive hierarchy run level by level
    (:mod:`cachesim.by_level`, the fast path); everything else walks each
    access down the levels (:mod:`cachesim.by_access`, which documents the
    write semantics), with the first two levels looked up at once when the
    first is direct-mapped (:mod:`cachesim.direct_first`). All give
    identical states and counts where they apply. Large fully associative
    levels are scanned, as in :func:`simulate_into`; :func:`simulate_writes`
    indexes them on a long stream.
    """
    if writes.shape[0] == 0 and geometry.inclusion == NON_INCLUSIVE:
        return _simulate_by_level(addresses, geometry, state, clock, served_by, record, work)
    if serves_direct_first(geometry):
        return _simulate_direct_first(addresses, writes, geometry, state, clock, served_by, record, work)
    return _simulate_by_access(addresses, writes, geometry, state, clock, served_by, record, work)


@njit(cache=True, inline="always")
def simulate_skips_into(addresses, writes, skip_mask, geometry, state, clock, work):
    """:func:`simulate_writes_into` of a stream whose certain first-level read hits were taken out.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
        Byte addresses, their low bits (``skip_mask``, at most the line
        offset's) each counting the reads after it that the first level was
        certain to serve, taken out of the stream
        (:func:`coherence.pixel_lines.pixel_lines`).
    writes : ndarray of bool, shape (N,) or (0,)
    skip_mask : int
        0 (no access was taken out) or ``2**b - 1``.
    geometry : CacheGeometry
        One that :func:`cachesim.direct_first.serves_direct_first`.
    state, clock, work
        As for :func:`simulate_into`.

    Returns
    -------
    int
        The clock after the last access, the ones taken out included: the
        state and the counters are those the whole stream leaves.
    """
    return _simulate_direct_first_skips(addresses, writes, skip_mask, geometry, state, clock, work)


@njit(cache=True)
def simulate_writes(addresses, writes, geometry, state, clock, served_by, record):
    """:func:`simulate_writes_into` with fresh work buffers, for one whole stream.

    A long enough stream through a hierarchy with a large fully associative
    level (:func:`cachesim.full.uses_index`) runs on the indexed walk
    (:func:`cachesim.by_access._simulate_indexed`): same results, O(1) an
    access in that level instead of a scan of its ways.
    """
    work = chunk_buffers()
    if uses_index(geometry, addresses.shape[0]):
        return _simulate_indexed(addresses, writes, geometry, state, clock, served_by, record, work)
    return simulate_writes_into(addresses, writes, geometry, state, clock, served_by, record, work)


@njit(cache=True, parallel=True)
def simulate_streams(addresses, starts, geometry, states, clocks, served_by, record, writes):
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
    writes : ndarray of bool, shape (N,) or (0,)
        Write flags of all streams, one after another; (0,): all reads.

    Streams are independent, so they run in parallel.
    """
    for stream in prange(starts.shape[0] - 1):
        start = starts[stream]
        stop = starts[stream + 1]
        out = served_by[start:stop] if record else served_by[:0]
        state = CacheArrays(states.tags[stream], states.stamps[stream], states.counts[stream])
        flags = writes[start:stop] if writes.shape[0] > 0 else writes
        clocks[stream] = simulate_writes(addresses[start:stop], flags, geometry, state, clocks[stream], out,
                                         record)
