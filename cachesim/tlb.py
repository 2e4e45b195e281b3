"""Compiled data-TLB kernels: a fully associative cache of page numbers.

The TLB is looked up on every access, read or write, and its contents depend
only on the pages touched, never on the caches; so it runs as a pass of its
own over the same addresses (:func:`tlb_lookup`), and compiled code of other
packages calls it beside :func:`cachesim.kernels.simulate_into`.

State of one TLB of ``E`` entries (:class:`TlbArrays`):

- ``pages`` int64 (E,): the page number held by each entry, or -1;
- ``stamps`` int64 (E,): the TLB clock of each entry's last use (LRU only);
- ``cursor`` int64 (N_CURSOR + HINTS,): :data:`NEXT_FILL` (the entry the
  round-robin fill pointer designates), :data:`LAST_USED` (the entry of the
  last lookup, -1 before any) and :data:`CLOCK` (lookups so far), then
  :data:`HINTS` guesses: for each value of a page number's low bits, the
  entry that last held such a page. A lookup checks its guess before it
  scans the entries; a page is held by one entry at most, so a guess that
  holds the page is the entry, and a wrong guess costs only the scan. The
  guesses change no count and no entry (a cursor of N_CURSOR columns, with
  none, gives the same results);
- ``counts`` int64 (3,): :data:`TLB_ACCESSES`, :data:`TLB_HITS`,
  :data:`TLB_MISSES`.

Policies (:class:`TlbGeometry` ``policy``):

- :data:`NLU`, not-last-used, the 21164 DTB's: a fill goes to the entry the
  fill pointer designates, unless that entry served the last lookup, in
  which case it goes to the next one; the pointer then moves one past the
  filled entry. The 21164 hardware reference manual says the DTB is filled
  by a not-last-used algorithm implemented in hardware and that each fill
  (a write of DTB_TAG) increments the TB entry pointer, which starts at
  entry 0; skipping the last-used entry is our reading of "not last used".
- :data:`TLB_FIFO`: the same round robin without the skip.
- :data:`TLB_LRU`: the least recently used entry (an empty one first).
"""
from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.jit import NO_REFCOUNTS

# Replacement policies (TlbGeometry.policy).
NLU, TLB_LRU, TLB_FIFO = 0, 1, 2
# Columns of TlbArrays.cursor.
NEXT_FILL, LAST_USED, CLOCK = 0, 1, 2
N_CURSOR = 3
#: Entry guesses after the cursor's columns (:func:`tlb_lookup`), one per value of a page number's low bits.
HINTS = 256
# Columns of TlbArrays.counts.
TLB_ACCESSES, TLB_HITS, TLB_MISSES = 0, 1, 2
N_TLB_COUNTERS = 3


class TlbGeometry(NamedTuple):
    """A TLB's fixed parameters.

    Attributes
    ----------
    page_shift : int
        log2 of the page size: byte address to page number.
    entries : int
        Number of entries (fully associative).
    policy : int
        :data:`NLU`, :data:`TLB_LRU` or :data:`TLB_FIFO`.
    """

    page_shift: int
    entries: int
    policy: int


class TlbArrays(NamedTuple):
    """The mutable contents and counters of one TLB (updated in place).

    Attributes
    ----------
    pages : ndarray of int64, shape (E,)
        Page number held by each entry, or -1.
    stamps : ndarray of int64, shape (E,)
        TLB clock of each entry's last use (read by LRU only).
    cursor : ndarray of int64, shape (N_CURSOR + HINTS,) or (N_CURSOR,)
        Fill pointer, last-used entry and clock (columns :data:`NEXT_FILL`,
        :data:`LAST_USED`, :data:`CLOCK`), then the entry guesses (see the
        module's docstring; without them, the same results).
    counts : ndarray of int64, shape (N_TLB_COUNTERS,)
        Cumulative lookups, hits and misses.
    """

    pages: np.ndarray
    stamps: np.ndarray
    cursor: np.ndarray
    counts: np.ndarray


def empty_tlb(entries: int) -> TlbArrays:
    """A TLB of ``entries`` entries with nothing in it and zero counters."""
    cursor = np.zeros(N_CURSOR + HINTS, dtype=np.int64)
    cursor[LAST_USED] = -1
    return TlbArrays(np.full(entries, -1, dtype=np.int64), np.zeros(entries, dtype=np.int64), cursor,
                     np.zeros(N_TLB_COUNTERS, dtype=np.int64))


def empty_tlbs(n_tlbs: int, entries: int) -> TlbArrays:
    """``n_tlbs`` empty TLBs stacked (shapes (S, E), (S, N_CURSOR + HINTS), (S, N_TLB_COUNTERS)).

    TLB ``s`` is ``TlbArrays(pages[s], stamps[s], cursor[s], counts[s])``; a
    caller whose TLBs stay with CPUs but whose counters follow processes
    builds the bundle from ``cursor[cpu]`` and another (P, N_TLB_COUNTERS)
    array's row, as for the caches.
    """
    cursor = np.zeros((n_tlbs, N_CURSOR + HINTS), dtype=np.int64)
    cursor[:, LAST_USED] = -1
    return TlbArrays(np.full((n_tlbs, entries), -1, dtype=np.int64), np.zeros((n_tlbs, entries), dtype=np.int64),
                     cursor, np.zeros((n_tlbs, N_TLB_COUNTERS), dtype=np.int64))


@njit(cache=True, **NO_REFCOUNTS)
def tlb_lookup(addresses, geometry, tlb, skip_mask=0):
    """Look up the page of every address in one TLB, in order.

    Parameters
    ----------
    addresses : ndarray of uint64, shape (N,)
        Byte addresses in access order (reads and writes alike).
    geometry : TlbGeometry
    tlb : TlbArrays
        Updated in place, counters included.
    skip_mask : int
        0, or ``2**b - 1``: the low ``b`` bits of each address count further
        accesses that followed it on the same page and were taken out of
        the stream (:func:`coherence.pixel_lines.pixel_lines`). Each is a
        lookup of the page the last one found: a hit that stamps that entry,
        as it would in the full stream.

    Returns
    -------
    int
        The misses of this call (each costs the TLB's fixed miss penalty).
    """
    low = np.uint64(skip_mask)
    skipped = np.int64(0)
    pages = tlb.pages
    stamps = tlb.stamps
    cursor = tlb.cursor
    entries = geometry.entries
    policy = geometry.policy
    shift = np.uint64(geometry.page_shift)
    clock = cursor[CLOCK]
    next_fill = cursor[NEXT_FILL]
    last = cursor[LAST_USED]
    last_page = pages[last] if last >= 0 else np.int64(-1)
    # The entry used before the last one: streams that alternate between two
    # pages (tree nodes and primitives, say) find it here without a scan. A
    # page is held by one entry at most, so a check of that entry is exact.
    before = np.int64(0)
    before_page = np.int64(-1)
    misses = np.int64(0)
    hinted = cursor.shape[0] >= N_CURSOR + HINTS  # the entry guesses follow the cursor's columns
    for i in range(addresses.shape[0]):
        address = addresses[i]
        page = np.int64(address >> shift)
        repeats = np.int64(address & low)  # same-page lookups after this one: hits on its entry
        skipped += repeats
        clock += 1 + repeats  # an entry's stamp is its last lookup's, the repeats' included
        if page == last_page:
            stamps[last] = clock
            continue
        if page == before_page and pages[before] == page:
            stamps[before] = clock
            before, last = last, before
            before_page, last_page = last_page, page
            continue
        hint = np.uint64(N_CURSOR) + (np.uint64(page) & np.uint64(HINTS - 1))
        found = np.int64(0)
        if hinted:
            found = cursor[hint]
        if pages[found] != page:  # the guess (or entry 0) does not hold the page
            # One pass without early exit over the entries: the host vectorises it.
            found = -1
            for entry in range(entries):
                found = entry if pages[entry] == page else found
        if found < 0:
            misses += 1
            if policy == TLB_LRU:
                found = 0
                oldest = np.int64(9223372036854775807)
                for entry in range(entries):
                    age = stamps[entry] if pages[entry] >= 0 else np.int64(-1)
                    if age < oldest:
                        oldest = age
                        found = entry
            else:
                found = next_fill
                if policy == NLU and found == last:
                    found = (found + 1) % entries
                next_fill = (found + 1) % entries
            pages[found] = page
        if hinted:
            cursor[hint] = found
        stamps[found] = clock
        before = last if last >= 0 else np.int64(0)
        before_page = last_page
        last = found
        last_page = page
    n = addresses.shape[0] + skipped
    cursor[CLOCK] = clock
    cursor[NEXT_FILL] = next_fill
    cursor[LAST_USED] = last
    tlb.counts[TLB_ACCESSES] += n
    tlb.counts[TLB_HITS] += n - misses
    tlb.counts[TLB_MISSES] += misses
    return misses
