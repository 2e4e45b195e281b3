"""A turn's reads that hit the thread's first level, in a loop of their own.

Nineteen in twenty accesses of a run on shared levels are reads that hit
the first level (:mod:`coherence.shared_schedule`): such a hit changes
nothing but the counts and, under LRU, the way's stamp. The event loop
serves them here, in a small loop that keeps its few values in registers,
and takes every other access (a miss, a write) through
:func:`cachesim.multicore.shared_access`. Counts, stamps, clocks and cycles
are those the access-by-access path gives, added in the same order.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.multicore_sets import probe_set, set_index
from coherence.piece_words import KIND_MASK, KIND_SHIFT, PRIVATE_BIT, WRITE_BIT
from rtcommon.jit import NO_REFCOUNTS

__all__ = ["FirstLevel", "TurnPace", "first_level_reads"]


class FirstLevel(NamedTuple):
    """The first-level instance serving one hardware thread.

    Attributes
    ----------
    tags, stamps : ndarray of int64, shape (W,)
        The shared state's (:class:`cachesim.multicore_state.SharedArrays`); stamps updated in place.
    first_way : int
        The instance's first way in ``tags``.
    set_mask : int
        ``n_sets - 1`` for a power of two of sets, else -1.
    n_sets, ways : int
    lru : bool
        A hit stamps its way with the access clock.
    line_shift : uint64
        log2 of the line size.
    """

    tags: np.ndarray
    stamps: np.ndarray
    first_way: int
    set_mask: int
    n_sets: int
    ways: int
    lru: bool
    line_shift: np.uint64


class TurnPace(NamedTuple):
    """How far a turn may go: it ends once ``clock + advance - turn_start`` reaches ``interleave_cycles``.

    Attributes
    ----------
    clock, turn_start, interleave_cycles : float
    share : float
        Compute cycles each access of the pixel carries.
    hit_cycles : float
        The first level's latency.
    offset : uint64
        What a private access's address moves by for this process.
    """

    clock: float
    turn_start: float
    interleave_cycles: float
    share: float
    hit_cycles: float
    offset: np.uint64


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def first_level_reads(pieces, k, stop, first, pace, kind_hits, running):
    """Serve accesses ``k, k + 1, ...`` of a pixel while they are reads that hit ``first`` and the turn lasts.

    Parameters
    ----------
    pieces : coherence.piece_words.PixelPieces
    k, stop : int
        The next access and the pixel's end.
    first : FirstLevel
    pace : TurnPace
    kind_hits : ndarray of int64, shape (16,)
        The instance's hit count per record kind (a view of the state's counts), added to.
    running : tuple
        ``(advance, memory, access_clock, previous_line)`` before access ``k``: cycles the turn has
        advanced since ``pace.clock``, memory cycles of the pixel's segment, the access clock, and the line
        the previous access left as its set's most recent entry (-1: none).

    Returns
    -------
    tuple
        ``(k, advance, memory, access_clock, previous_line, hits)``: the first access not served
        (a write, a miss, the pixel's end, or the turn over) and the running values after the hits.
    """
    advance, memory, access_clock, previous_line = running
    hits = 0
    tags = first.tags
    addresses = pieces.addresses
    words = pieces.words
    while k < stop and pace.clock + advance - pace.turn_start < pace.interleave_cycles:
        word = words[k]
        if word & WRITE_BIT:
            break
        address = addresses[k]
        if word & PRIVATE_BIT:
            address += pace.offset
        line = np.int64(address >> first.line_shift)
        if line != previous_line:
            slot = probe_set(tags, first.first_way + set_index(line, first.set_mask, first.n_sets) * first.ways,
                             first.ways, line)
            if slot < 0:
                break
            if first.lru:
                first.stamps[slot] = access_clock + 1
        access_clock += 1
        kind_hits[(word >> KIND_SHIFT) & KIND_MASK] += 1
        hits += 1
        previous_line = line
        memory += pace.hit_cycles
        advance += pace.share + pace.hit_cycles
        k += 1
    return k, advance, memory, access_clock, previous_line, hits
