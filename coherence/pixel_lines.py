"""Every pixel's line accesses, worked out once and shared by the runs of a study.

A schedule replay turns each pixel's records into line addresses
(:func:`coherence.record_lines.record_lines_and_writes`) every time it renders the
pixel, a large share of a replay's time. A study replays the same trace dozens of times with one layout and one
smallest line size, so :func:`pixel_lines` does that work once, and
:func:`coherence.simulation.simulate_run` reads slices of the result instead.
It costs 9 bytes per line access held (address and write flag), 8 per page
run when certain hits are taken out (below) and a few words per pixel, so a
study asks for it only within a budget (:data:`SHARED_LINES_BUDGET`, or the
study's own); the replay's counts are the same either way. The budget counts
the bytes held at the peak of making the lines (:func:`held_bytes`): with
certain hits taken out, each pixel's accesses are worked out one pixel at a
time and only the accesses kept and the page runs are ever held.

Given the hierarchy the runs replay, :func:`pixel_lines` also takes out the
reads its direct-mapped first level is certain to serve whatever state a
pixel starts on (:func:`skips_certain_hits`): a read of a line that an
earlier read of the same pixel put in the first level, with no access to
another line in any of the line's sets, at any level, in between (nothing
else can remove it: a pixel is never split across time slices). Such a read
changes no cache state, so the line access before it counts it in its low
address bits instead (``PixelLines.skip_mask``), and the cache walk
(:func:`cachesim.kernels.simulate_skips_into`) counts it as the whole
stream would. The data TLB sees every access, so it gets every pixel's
pages apart, a run of accesses to one page as one entry that counts the
rest in its low bits (``PixelLines.page_runs``; a repeat of the last page
is a hit on its entry, :func:`cachesim.tlb.tlb_lookup`).
"""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.direct_first import serves_direct_first
from coherence.layout import PlacedLayout
from coherence.page_placement import translate_addresses
from coherence.record_lines import FILL_AHEAD, _count_lines, _fill_lines
from rtcommon.jit import NO_REFCOUNTS
from rtcommon.validate import InputError, require_power_of_two

#: Bytes a study may spend on shared line addresses (1 GiB); beyond it, each run converts per pixel.
SHARED_LINES_BUDGET = 1 << 30
#: Bytes per line access held: the address (8) and the write flag (1).
BYTES_PER_LINE = 9


class PixelLines(NamedTuple):
    """The line accesses of every pixel, in order.

    Attributes
    ----------
    line_offsets : ndarray of int64, shape (P + 1,)
        Pixel ``p`` reads ``addresses[line_offsets[p]:line_offsets[p + 1]]``;
        shape (0,) in :func:`no_pixel_lines` (convert per pixel instead).
    addresses : ndarray of uint64, shape (M,)
        Byte address of each line access (a multiple of ``1 << line_shift``).
    writes : ndarray of bool, shape (M,)
        True where the access is a write.
    pixel_writes : ndarray of int64, shape (P,)
        Writes among each pixel's accesses.
    line_shift : int
        log2 of the line size the addresses are of.
    skip_mask : int
        0: every access is held. Else ``2**line_shift - 1``: the low bits of
        each address count the certain first-level read hits after it that
        were taken out, for the hierarchy that :attr:`skips_for` names.
    page_offsets : ndarray of int64, shape (P + 1,), or (0,) when ``skip_mask`` is 0
        Pixel ``p``'s pages are ``page_runs[page_offsets[p]:page_offsets[p + 1]]``.
    page_runs : ndarray of uint64, shape (R,)
        Every pixel's accesses, all of them, as runs on one page: the first
        byte address of the run's page, plus in its low ``page_shift`` bits
        how many accesses of the run follow the first.
    page_shift : int
        log2 of the data TLB's page size the runs are of.
    skips_for : str
        What the accesses were taken out for: :func:`skip_key` of the
        hierarchy ("" when none were).
    """

    line_offsets: np.ndarray
    addresses: np.ndarray
    writes: np.ndarray
    pixel_writes: np.ndarray
    line_shift: int
    skip_mask: int = 0
    page_offsets: np.ndarray = np.zeros(0, dtype=np.int64)
    page_runs: np.ndarray = np.zeros(0, dtype=np.uint64)
    page_shift: int = 13
    skips_for: str = ""


def no_pixel_lines(line_shift: int) -> PixelLines:
    """The empty :class:`PixelLines`: a replay given it converts each pixel's records itself."""
    empty = np.zeros(0, dtype=np.int64)
    return PixelLines(empty, np.zeros(0, dtype=np.uint64), np.zeros(0, dtype=np.bool_), empty, int(line_shift))


def skips_certain_hits(hierarchy, line_size: int) -> bool:
    """Whether :func:`pixel_lines` takes certain first-level read hits out for ``hierarchy`` (a
    :class:`cachesim.Hierarchy`) at ``line_size``: the lines are its first level's, that level is
    direct-mapped, and its walk is :mod:`cachesim.direct_first`'s, every level with a power-of-two
    number of sets."""
    from cachesim import CacheState

    geometry = CacheState(hierarchy).geometry
    return (line_size == hierarchy.levels[0].line_size and line_size > 1 and not hierarchy.prefetches
            and bool(serves_direct_first(geometry)) and bool(np.all(np.asarray(geometry.set_mask) >= 0)))


def skip_key(hierarchy) -> str:
    """What decides which accesses :func:`pixel_lines` takes out for ``hierarchy``: its levels' line
    sizes, sets, ways and replacement policies, its inclusion and the data TLB's page size (8 KB without a
    TLB)."""
    levels = ",".join(f"{level.line_size}/{level.n_sets}/{level.assoc}/{level.policy}" for level in hierarchy.levels)
    page_size = hierarchy.tlb.page_size if hierarchy.tlb is not None else DEFAULT_PAGE_SIZE
    return f"{levels};{hierarchy.inclusion};page {page_size}"


#: Page size the accesses taken out keep to for a hierarchy without a data TLB (the 21164's).
DEFAULT_PAGE_SIZE = 8192


def pixel_lines(trace, placed: PlacedLayout, line_size: int, budget_bytes: int | None = None,
                hierarchy=None) -> PixelLines | None:
    """Line accesses of every pixel of ``trace`` at ``line_size`` bytes.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placed : PlacedLayout
        Where the trace's records live (its records are checked against it).
    line_size : int
        A power of two: the smallest line size of the hierarchy replayed.
    budget_bytes : int, optional
        Return None when the bytes held at the peak of making the result
        would be more than this (:func:`held_bytes`). Every access held:
        found before anything large is allocated. Certain hits taken out:
        found while they are, which stops as soon as the bytes written
        exceed the budget, and lets them go.
    hierarchy : cachesim.Hierarchy, optional
        The hierarchy every run of these lines replays: its certain
        first-level read hits are taken out when :func:`skips_certain_hits`.

    Returns
    -------
    PixelLines or None
    """
    line_shift = require_power_of_two("line_size", line_size).bit_length() - 1
    records = np.asarray(trace.records)
    placed.check_records(records)
    pixel_offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    line_offsets = np.zeros(pixel_offsets.shape[0], dtype=np.int64)
    _pixel_line_offsets(records, pixel_offsets, placed.placement, line_shift, line_offsets)
    if hierarchy is not None and skips_certain_hits(hierarchy, line_size):
        return _taken_out_pixel_lines(records, pixel_offsets, placed, line_offsets, hierarchy, budget_bytes)
    n_lines = int(line_offsets[-1])
    if budget_bytes is not None and held_bytes(n_lines, line_offsets.shape[0] - 1) > budget_bytes:
        return None
    # FILL_AHEAD spare entries: the fill writes that many past each pixel's lines.
    with _small_pages():
        addresses = np.empty(n_lines + FILL_AHEAD, dtype=np.uint64)
        writes = np.empty(n_lines + FILL_AHEAD, dtype=np.bool_)
    pixel_writes = np.zeros(pixel_offsets.shape[0] - 1, dtype=np.int64)
    _fill_pixel_lines(records, pixel_offsets, placed.placement, line_offsets, line_shift, addresses, writes,
                      pixel_writes)
    if placed.pages.frame.shape[0] > 0:
        translate_addresses(addresses, n_lines, placed.pages)
    return PixelLines(line_offsets, addresses[:n_lines], writes[:n_lines], pixel_writes, line_shift)


#: Bytes held per page run (:attr:`PixelLines.page_runs`).
BYTES_PER_RUN = 8


def held_bytes(n_lines: int, n_pixels: int, n_runs: int | None = None, longest_pixel: int = 0) -> int:
    """Bytes :func:`pixel_lines` holds at its peak for ``n_lines`` line accesses of ``n_pixels`` pixels.

    Without ``n_runs`` (every access held): the accesses (:data:`BYTES_PER_LINE` each, with
    :data:`~coherence.record_lines.FILL_AHEAD` spare), their offsets (8 bytes a pixel, and 8) and each pixel's
    writes (8 a pixel). With ``n_runs`` (certain hits taken out, ``n_lines`` the accesses kept): those
    accesses without spare, the page runs (:data:`BYTES_PER_RUN` each) and their offsets, the offsets of every
    access (8 bytes a pixel, and 8, each) and the one pixel's accesses being worked out, ``longest_pixel`` at
    most, with spare. Not counted: the hierarchy's sets the take-out follows (16 bytes a set).
    """
    if n_runs is None:
        return BYTES_PER_LINE * (n_lines + FILL_AHEAD) + 8 * (2 * n_pixels + 1)
    return (BYTES_PER_LINE * n_lines + BYTES_PER_RUN * n_runs + 8 * (4 * n_pixels + 3)
            + BYTES_PER_LINE * (longest_pixel + FILL_AHEAD))


def _taken_out_pixel_lines(records, pixel_offsets, placed, line_offsets, hierarchy, budget_bytes):
    """:func:`pixel_lines` with the certain hits of ``hierarchy`` taken out, given the offsets of every access
    (``line_offsets``), in one pass over the records that works out one pixel's line accesses at a time.

    The arrays the accesses kept and the page runs go to are reserved at the count of every access, or with
    ``budget_bytes`` at what the budget lets be written before the pixel that passes it, and its longest pixel
    more (the pass checks after each pixel), whichever is less; only their pages written are ever held, a
    pixel's after another, and they are shrunk to what was written at the end: the most bytes held are
    :func:`held_bytes` of the result. With ``budget_bytes``, the pass stops (and None is returned) as soon as
    the bytes written exceed it.
    """
    n_pixels = line_offsets.shape[0] - 1
    n_lines = int(line_offsets[-1])
    longest = int(np.max(np.diff(line_offsets))) if n_pixels > 0 else 0
    scratch = (np.empty(longest + FILL_AHEAD, dtype=np.uint64), np.empty(longest + FILL_AHEAD, dtype=np.bool_))
    bytes_left = NO_BUDGET if budget_bytes is None else budget_bytes - held_bytes(0, n_pixels, 0, longest)
    take_out = _TakeOut(hierarchy, hierarchy.levels[0].line_size.bit_length() - 1, n_pixels, bytes_left)
    room = max(bytes_left, 0)
    out = take_out.reserve(min(n_lines, room // BYTES_PER_LINE + longest),
                           min(n_lines, room // BYTES_PER_RUN + longest))
    kept, runs, fits = _take_out_records(records, pixel_offsets, placed.placement, line_offsets, *scratch,
                                         take_out.sets, take_out.scalars, take_out.counts, out)
    if not fits:
        return None
    return take_out.lines(out, kept, runs, hierarchy)


#: ``bytes_left`` of :class:`TakeOutScalars` without a budget.
NO_BUDGET = 1 << 62


class TakenOut(NamedTuple):
    """Where :func:`_take_out_pixel` writes what it keeps.

    Attributes
    ----------
    addresses : ndarray of uint64, shape (K,)
        The accesses kept, each counting in its low bits the certain hits taken out after it.
    writes : ndarray of bool, shape (K,)
        Their write flags.
    page_runs : ndarray of uint64, shape (R,)
        Every access as runs on one page (:attr:`PixelLines.page_runs`).
    """

    addresses: np.ndarray
    writes: np.ndarray
    page_runs: np.ndarray


class TakeOutScalars(NamedTuple):
    """The scalars of a take-out: log2 of the line and page sizes, the low bits that count taken-out hits
    (``2**line_shift - 1``), the bytes held per access kept and per page run, and the bytes they may take."""

    line_shift: int
    page_shift: int
    skip_mask: int
    line_bytes: int
    run_bytes: int
    bytes_left: int


class TakeOutCounts(NamedTuple):
    """Per pixel (int64): ``kept_offsets`` (P + 1,) of the accesses kept, ``page_offsets`` (P + 1,) of the page
    runs, ``pixel_writes`` (P,) the writes among its accesses."""

    kept_offsets: np.ndarray
    page_offsets: np.ndarray
    pixel_writes: np.ndarray


class _TakeOut:
    """The arrays and scalars a take-out of ``hierarchy``'s certain hits from lines of ``2**line_shift`` bytes
    works on: its sets before any access (:class:`SetRuns`), :class:`TakeOutScalars` and
    :class:`TakeOutCounts`."""

    def __init__(self, hierarchy, line_shift: int, n_pixels: int, bytes_left: int = NO_BUDGET):
        from cachesim import CacheState

        geometry = CacheState(hierarchy).geometry
        page_shift = (hierarchy.tlb.page_size if hierarchy.tlb is not None else DEFAULT_PAGE_SIZE).bit_length() - 1
        self.scalars = TakeOutScalars(line_shift, page_shift, (1 << line_shift) - 1, BYTES_PER_LINE, BYTES_PER_RUN,
                                      int(bytes_left))
        self.counts = TakeOutCounts(np.zeros(n_pixels + 1, dtype=np.int64), np.zeros(n_pixels + 1, dtype=np.int64),
                                    np.zeros(n_pixels, dtype=np.int64))
        n_sets = np.asarray(geometry.n_sets, dtype=np.int64)
        set_base = np.concatenate([[0], np.cumsum(n_sets)[:-1]]).astype(np.int64)  # level l's sets, flat
        owners = np.full(int(n_sets.sum()), -1, dtype=np.int64)
        self.sets = SetRuns(np.asarray(geometry.rel_shift, dtype=np.int64),
                            np.asarray(geometry.set_mask, dtype=np.int64), set_base, owners, np.zeros_like(owners),
                            np.full(n_sets[0], -1, np.int64))

    @staticmethod
    def reserve(n_lines: int, n_runs: int) -> TakenOut:
        """Arrays with room for ``n_lines`` accesses kept and ``n_runs`` page runs, none of them written yet
        (so none of their pages held)."""
        with _small_pages():
            return TakenOut(np.empty(n_lines, dtype=np.uint64), np.empty(n_lines, dtype=np.bool_),
                            np.empty(n_runs, dtype=np.uint64))

    def lines(self, out: TakenOut, kept: int, runs: int, hierarchy, pixel_writes=None) -> PixelLines:
        """The :class:`PixelLines` of the ``kept`` accesses and ``runs`` page runs written into ``out``, whose
        arrays are shrunk to them in place (giving the rest back without a copy), with ``pixel_writes``
        (default: the counts the take-out filled)."""
        out.addresses.resize(kept, refcheck=False)
        out.writes.resize(kept, refcheck=False)
        out.page_runs.resize(runs, refcheck=False)
        scalars, counts = self.scalars, self.counts
        pixel_writes = counts.pixel_writes if pixel_writes is None else pixel_writes
        return PixelLines(counts.kept_offsets, out.addresses, out.writes, pixel_writes, scalars.line_shift,
                          scalars.skip_mask, counts.page_offsets, out.page_runs, scalars.page_shift,
                          skip_key(hierarchy))


@contextmanager
def _small_pages():
    """Allocate without numpy's advice to back large arrays by transparent huge pages.

    The line addresses are gigabytes written once and then read in order: huge pages save them nothing,
    and where the system must compact memory to hand them out, their first write costs several times the
    system time it costs in ordinary pages. The advice is numpy's, for every thread: it is off while any
    caller is inside (a count under a lock, so overlapping callers on the study's threads cannot leave it
    off); a numpy without the switch allocates as it does.
    """
    try:
        from numpy._core import multiarray
    except ImportError:  # numpy < 2
        from numpy.core import multiarray
    switch = getattr(multiarray, "_set_madvise_hugepage", None)
    if switch is None:
        yield
        return
    with _SMALL_PAGES_LOCK:
        if _SMALL_PAGES_USERS[0] == 0:
            _SMALL_PAGES_USERS[1] = switch(False)
        _SMALL_PAGES_USERS[0] += 1
    try:
        yield
    finally:
        with _SMALL_PAGES_LOCK:
            _SMALL_PAGES_USERS[0] -= 1
            if _SMALL_PAGES_USERS[0] == 0:
                switch(_SMALL_PAGES_USERS[1])


#: Guards :func:`_small_pages`' count of callers inside and the advice it found when the first came in.
_SMALL_PAGES_LOCK = threading.Lock()
_SMALL_PAGES_USERS = [0, True]


def take_out_certain_hits(lines: PixelLines, hierarchy) -> PixelLines:
    """``lines`` with the certain first-level read hits of ``hierarchy`` taken out, and every pixel's page runs
    (see the module's docstring), in new arrays.

    ``lines`` must hold every access (``skip_mask`` 0); ``hierarchy`` must :func:`skips_certain_hits` at
    ``2**lines.line_shift``-byte lines. :func:`pixel_lines` given ``hierarchy`` gives the same result without
    ever holding every access, and is what the studies call; this function is the path from lines already
    held, which the tests compare the records' pass with.
    """
    if lines.skip_mask or not skips_certain_hits(hierarchy, 1 << lines.line_shift):
        raise InputError(f"take_out_certain_hits: lines of {1 << lines.line_shift} bytes with every access held "
                         f"and a hierarchy whose first level is direct-mapped at that line size are needed")
    line_offsets = np.asarray(lines.line_offsets, dtype=np.int64)
    take_out = _TakeOut(hierarchy, lines.line_shift, line_offsets.shape[0] - 1)
    out = take_out.reserve(int(line_offsets[-1]), int(line_offsets[-1]))
    kept, runs = _take_out_lines(line_offsets, lines.addresses, lines.writes, take_out.sets, take_out.scalars,
                                 take_out.counts, out)
    return take_out.lines(out, kept, runs, hierarchy, np.array(lines.pixel_writes, dtype=np.int64))


class SetRuns(NamedTuple):
    """The hierarchy's sets and what :func:`_take_out_pixel` knows of each, levels one after another
    (flat; every array int64).

    Attributes
    ----------
    rel_shift, set_mask : ndarray, shape (L,)
        Each level's line shift relative to the first's and set mask (:class:`cachesim.kernels.CacheGeometry`).
    set_base : ndarray, shape (L,)
        Where each level's sets start in ``owner`` and ``since``.
    owner : ndarray, shape (S,)
        The level's line of the last access to the set, -1 before any.
    since : ndarray, shape (S,)
        Index of the first access of the run of that line in the set: every access to the set since was to it.
    last_read : ndarray, shape (S0,)
        Index of the last read of each first-level set, -1 before any.
    """

    rel_shift: np.ndarray
    set_mask: np.ndarray
    set_base: np.ndarray
    owner: np.ndarray
    since: np.ndarray
    last_read: np.ndarray


@njit(cache=True, nogil=True)
def _take_out_records(records, pixel_offsets, placement, line_offsets, scratch, scratch_writes, sets, scalars,
                      counts, out):
    """Work out each pixel's line accesses from its records into ``scratch`` (and ``scratch_writes``), then
    take its certain hits out into ``out`` (:func:`_take_out_pixel`); fills ``counts``. Stops after the first
    pixel that takes the bytes written past ``scalars.bytes_left``.

    Returns
    -------
    kept, runs : int
        Accesses kept and page runs written.
    fits : bool
        False when stopped.
    """
    kept = 0
    runs = 0
    paged = placement.pages.frame.shape[0] > 0
    for pixel in range(pixel_offsets.shape[0] - 1):
        count, counts.pixel_writes[pixel] = _fill_lines(records, pixel_offsets[pixel], pixel_offsets[pixel + 1],
                                                        placement, scalars.line_shift, scratch, scratch_writes)
        if paged:
            translate_addresses(scratch, count, placement.pages)
        kept, runs = _take_out_pixel(scratch, scratch_writes, count, line_offsets[pixel], sets, scalars, out, kept,
                                     runs)
        counts.kept_offsets[pixel + 1] = kept
        counts.page_offsets[pixel + 1] = runs
        if scalars.line_bytes * kept + scalars.run_bytes * runs > scalars.bytes_left:
            return kept, runs, False
    return kept, runs, True


@njit(cache=True, nogil=True)
def _take_out_lines(line_offsets, addresses, writes, sets, scalars, counts, out):
    """:func:`_take_out_records` (without a budget) from every pixel's line accesses already worked out
    (``addresses`` and ``writes`` at ``line_offsets``); ``counts.pixel_writes`` is left as it is."""
    kept = 0
    runs = 0
    for pixel in range(line_offsets.shape[0] - 1):
        start, stop = line_offsets[pixel], line_offsets[pixel + 1]
        kept, runs = _take_out_pixel(addresses[start:stop], writes[start:stop], stop - start, start, sets, scalars,
                                     out, kept, runs)
        counts.kept_offsets[pixel + 1] = kept
        counts.page_offsets[pixel + 1] = runs
    return kept, runs


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _take_out_pixel(addresses, writes, count, first, sets, scalars, out, kept, runs):
    """Take the certain first-level read hits out of one pixel's ``count`` line accesses (``addresses``,
    ``writes``), which are accesses ``first`` onwards of the whole stream, and make its page runs (see the
    module's docstring).

    A read is certain to hit if the last read of its first-level set (``sets.last_read``), made in this
    pixel, was of its line and, at every level, the run of the line in its set began no later than that read
    (:class:`SetRuns`). The accesses kept go to ``out.addresses[kept:]`` and ``out.writes[kept:]``, the runs,
    each at most ``2**scalars.page_shift`` accesses long, to ``out.page_runs[runs:]``.

    Returns
    -------
    kept, runs : int
        Accesses kept and page runs written, in all, after this pixel's.
    """
    rel_shift = sets.rel_shift
    set_mask = sets.set_mask
    set_base = sets.set_base
    n_levels = rel_shift.shape[0]
    shift = np.uint64(scalars.line_shift)
    pages = np.uint64(scalars.page_shift)
    longest = (1 << scalars.page_shift) - 1  # repeats a run's low bits hold
    count_full = scalars.skip_mask  # taken-out hits an access's low bits hold
    owner = sets.owner
    since = sets.since
    last_read = sets.last_read
    mask0 = np.uint64(set_mask[0])
    carrier = np.uint64(0)  # the kept access the taken-out ones after it count on
    carried = 0
    run_page = np.uint64(1)  # never a page's address: the pixel's first access starts a run
    repeats = 0
    for j in range(count):
        i = first + j
        address = addresses[np.uint64(j)]
        write = writes[np.uint64(j)]
        page = (address >> pages) << pages
        if page == run_page and repeats < longest:
            repeats += 1
            out.page_runs[np.uint64(runs - 1)] += np.uint64(1)
        else:
            out.page_runs[np.uint64(runs)] = page
            run_page = page
            repeats = 0
            runs += 1
        line = np.int64(address >> shift)
        first_set = np.uint64(line) & mask0
        read_at = last_read[first_set]
        certain = not write and j > 0 and read_at >= first and carried < count_full
        for level in range(n_levels):
            level_line = line >> rel_shift[level]
            s = np.uint64(set_base[level] + (level_line & set_mask[level]))
            if owner[s] != level_line:
                certain = False
                owner[s] = level_line
                since[s] = i
            elif since[s] > read_at:
                certain = False
        if not write:
            last_read[first_set] = i
        if certain:
            carried += 1
            out.addresses[carrier] += np.uint64(1)
        else:
            carrier = np.uint64(kept)
            carried = 0
            out.addresses[carrier] = address
            out.writes[carrier] = write
            kept += 1
    return kept, runs


@njit(cache=True, nogil=True)
def _pixel_line_offsets(records, pixel_offsets, placement, line_shift, line_offsets):
    """Cumulative line counts: ``line_offsets[p + 1]`` lines up to the end of pixel ``p``."""
    total = 0
    for pixel in range(pixel_offsets.shape[0] - 1):
        total += _count_lines(records, pixel_offsets[pixel], pixel_offsets[pixel + 1], placement, line_shift)
        line_offsets[pixel + 1] = total


@njit(cache=True, nogil=True)
def _fill_pixel_lines(records, pixel_offsets, placement, line_offsets, line_shift, addresses, writes, pixel_writes):
    """Fill ``addresses`` and ``writes`` (``line_offsets[-1] + FILL_AHEAD``
    entries) with every pixel's line accesses, and ``pixel_writes``."""
    for pixel in range(pixel_offsets.shape[0] - 1):
        first = line_offsets[pixel]
        _, pixel_writes[pixel] = _fill_lines(records, pixel_offsets[pixel], pixel_offsets[pixel + 1], placement,
                                             line_shift, addresses[first:], writes[first:])
