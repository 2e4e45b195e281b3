"""Every pixel's line accesses, worked out once and shared by the runs of a study.

A schedule replay turns each pixel's records into line addresses
(:func:`coherence.record_lines.record_lines_and_writes`) every time it renders the
pixel, a large share of a replay's time. A study replays the same trace dozens of times with one layout and one
smallest line size, so :func:`pixel_lines` does that work once, and
:func:`coherence.simulation.simulate_run` reads slices of the result instead.
It costs 9 bytes per line access (address and write flag) and 16 per pixel
(offset and write count), so a study asks for it only within
:data:`SHARED_LINES_BUDGET`; the replay's counts are the same either way. The
budget counts those bytes only: while certain hits are taken out (below) the
page runs take up to 8 more bytes per access and 8 per pixel, of which the
runs actually written stay (one per run of accesses to one page).

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
        Return None, having allocated nothing large, when the result would
        take more than this many bytes.
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
    n_lines = int(line_offsets[-1])
    if budget_bytes is not None and n_lines * BYTES_PER_LINE > budget_bytes:
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
    lines = PixelLines(line_offsets, addresses[:n_lines], writes[:n_lines], pixel_writes, line_shift)
    if hierarchy is None or not skips_certain_hits(hierarchy, line_size):
        return lines
    return take_out_certain_hits(lines, hierarchy)


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
    (see the module's docstring).

    ``lines`` (every access held, ``skip_mask`` 0, its arrays owned by nothing else and
    :data:`~coherence.record_lines.FILL_AHEAD` entries longer than it shows) is overwritten: its
    ``line_offsets``, ``addresses`` and ``writes`` become the result's, shrunk in place, so neither ``lines``
    nor any other view of its arrays may be read afterwards (:func:`pixel_lines` calls it on arrays it has
    just made). ``hierarchy`` must :func:`skips_certain_hits` at ``2**lines.line_shift``-byte lines.
    """
    from cachesim import CacheState

    if lines.skip_mask or not skips_certain_hits(hierarchy, 1 << lines.line_shift):
        raise InputError(f"take_out_certain_hits: lines of {1 << lines.line_shift} bytes with every access held "
                         f"and a hierarchy whose first level is direct-mapped at that line size are needed")
    line_offsets = lines.line_offsets
    addresses = lines.addresses.base if lines.addresses.base is not None else lines.addresses
    writes = lines.writes.base if lines.writes.base is not None else lines.writes
    line_shift = lines.line_shift
    geometry = CacheState(hierarchy).geometry
    page_shift = (hierarchy.tlb.page_size if hierarchy.tlb is not None else DEFAULT_PAGE_SIZE).bit_length() - 1
    skip_mask = (1 << line_shift) - 1
    n_sets = np.asarray(geometry.n_sets, dtype=np.int64)
    set_base = np.concatenate([[0], np.cumsum(n_sets)[:-1]]).astype(np.int64)  # level l's sets in the flat arrays
    owners = np.full(int(n_sets.sum()), -1, dtype=np.int64)
    page_offsets = np.zeros(line_offsets.shape[0], dtype=np.int64)
    with _small_pages():
        page_runs = np.empty(lines.addresses.shape[0], dtype=np.uint64)  # shrunk to the runs written below
    sets = SetRuns(np.asarray(geometry.rel_shift, dtype=np.int64), np.asarray(geometry.set_mask, dtype=np.int64),
                   set_base, owners, np.zeros_like(owners), np.full(n_sets[0], -1, np.int64))
    n_kept, n_runs = _take_out_certain_hits(line_offsets, addresses, writes, line_shift, skip_mask, sets, page_shift,
                                            page_offsets, page_runs)
    page_runs.resize(n_runs, refcheck=False)
    addresses.resize(n_kept + FILL_AHEAD, refcheck=False)  # gives the rest back without a copy
    writes.resize(n_kept + FILL_AHEAD, refcheck=False)
    return PixelLines(line_offsets, addresses[:n_kept], writes[:n_kept], lines.pixel_writes, line_shift, skip_mask,
                      page_offsets, page_runs, page_shift, skip_key(hierarchy))


class SetRuns(NamedTuple):
    """The hierarchy's sets and what :func:`_take_out_certain_hits` knows of each, levels one after another
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


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _take_out_certain_hits(line_offsets, addresses, writes, line_shift, skip_mask, sets, page_shift, page_offsets,
                           page_runs):
    """Take the certain first-level read hits out of every pixel's accesses, in place, and write its page runs
    (see the module's docstring), in one pass.

    A read is certain to hit if the last read of its first-level set (``sets.last_read``), made in this
    pixel, was of its line and, at every level, the run of the line in its set began no later than that read
    (:class:`SetRuns`). ``line_offsets`` becomes the kept accesses' offsets, ``page_offsets`` (P + 1,) the
    runs'; ``page_runs`` receives the runs, each at most ``2**page_shift`` accesses long.

    Returns
    -------
    kept, runs : int
        Accesses kept and page runs written.
    """
    rel_shift = sets.rel_shift
    set_mask = sets.set_mask
    set_base = sets.set_base
    n_levels = rel_shift.shape[0]
    shift = np.uint64(line_shift)
    pages = np.uint64(page_shift)
    longest = np.uint64((1 << page_shift) - 1)  # repeats a run's low bits hold
    count_full = np.uint64(skip_mask)
    owner = sets.owner
    since = sets.since
    last_read = sets.last_read
    mask0 = np.uint64(set_mask[0])
    kept = 0
    runs = 0
    start = line_offsets[0]
    for pixel in range(line_offsets.shape[0] - 1):
        stop = line_offsets[pixel + 1]
        carrier = np.uint64(0)  # the kept access the taken-out ones after it count on
        run_page = np.uint64(1)  # never a page's address: the pixel's first access starts a run
        run_at = np.uint64(0)
        for i in range(start, stop):
            at = np.uint64(i)
            address = addresses[at]
            write = writes[at]
            page = (address >> pages) << pages
            if page == run_page and page_runs[run_at] - page < longest:
                page_runs[run_at] += np.uint64(1)
            else:
                run_at = np.uint64(runs)
                page_runs[run_at] = page
                run_page = page
                runs += 1
            line = np.int64(address >> shift)
            first_set = np.uint64(line) & mask0
            read_at = last_read[first_set]
            certain = not write and i > start and read_at >= start and (addresses[carrier] & count_full) < count_full
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
                addresses[carrier] += np.uint64(1)
            else:
                carrier = np.uint64(kept)
                addresses[carrier] = address
                writes[carrier] = write
                kept += 1
        line_offsets[pixel + 1] = kept
        page_offsets[pixel + 1] = runs
        start = stop
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
