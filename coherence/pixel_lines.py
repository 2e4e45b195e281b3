"""Every pixel's line accesses, worked out once and shared by the runs of a study.

A schedule replay turns each pixel's records into line addresses
(:func:`coherence.record_lines.record_lines_and_writes`) every time it renders the
pixel, a large share of a replay's time. A study replays the same trace dozens of times with one layout and one
smallest line size, so :func:`pixel_lines` does that work once, and
:func:`coherence.simulation.simulate_run` reads slices of the result instead.
It costs 9 bytes per line access (address and write flag) and 16 per pixel
(offset and write count), so a study asks for it only within
:data:`SHARED_LINES_BUDGET`; the replay's counts are the same either way.

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
is a hit on its entry, :func:`cachesim.tlb.tlb_lookup`). On the study-era
traces about a quarter of the line accesses go, and six in ten TLB lookups.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.direct_first import serves_direct_first
from coherence.layout import PlacedLayout
from coherence.record_lines import FILL_AHEAD, _count_lines, _fill_lines
from coherence.page_placement import translate_addresses
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
    sizes, sets and ways, its inclusion and the data TLB's page size (8 KB without a TLB)."""
    levels = ",".join(f"{level.line_size}/{level.n_sets}/{level.assoc}" for level in hierarchy.levels)
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


def take_out_certain_hits(lines: PixelLines, hierarchy) -> PixelLines:
    """``lines`` with the certain first-level read hits of ``hierarchy`` taken out, and every pixel's page runs
    (see the module's docstring).

    ``lines`` (every access held, ``skip_mask`` 0, its arrays owned by nothing else and
    :data:`~coherence.record_lines.FILL_AHEAD` entries longer than it shows) is overwritten: its
    ``line_offsets``, ``addresses`` and ``writes`` become the result's, shrunk in place. ``hierarchy`` must
    :func:`skips_certain_hits` at ``2**lines.line_shift``-byte lines.
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
    owners = np.full((n_sets.shape[0], int(n_sets.max())), -1, dtype=np.int64)
    page_offsets = np.zeros(line_offsets.shape[0], dtype=np.int64)
    page_runs = np.empty(lines.addresses.shape[0], dtype=np.uint64)  # only the pages written are ever taken
    n_runs = _page_runs(line_offsets, addresses, page_shift, page_offsets, page_runs)
    page_runs.resize(n_runs, refcheck=False)
    n_kept = _take_out_certain_hits(line_offsets, addresses, writes, line_shift,
                                    np.asarray(geometry.rel_shift, dtype=np.int64),
                                    np.asarray(geometry.set_mask, dtype=np.int64), skip_mask, owners,
                                    np.zeros_like(owners), np.full(n_sets[0], -1, np.int64))
    addresses.resize(n_kept + FILL_AHEAD, refcheck=False)  # gives the rest back without a copy
    writes.resize(n_kept + FILL_AHEAD, refcheck=False)
    return PixelLines(line_offsets, addresses[:n_kept], writes[:n_kept], lines.pixel_writes, line_shift, skip_mask,
                      page_offsets, page_runs, page_shift, skip_key(hierarchy))


@njit(cache=True, nogil=True)
def _page_runs(line_offsets, addresses, page_shift, page_offsets, page_runs):
    """Every pixel's accesses as runs on one page (:attr:`PixelLines.page_runs`); returns the runs."""
    shift = np.uint64(page_shift)
    most = np.uint64((1 << page_shift) - 1)  # a longer run continues in a new entry
    n_runs = 0
    for pixel in range(line_offsets.shape[0] - 1):
        for i in range(line_offsets[pixel], line_offsets[pixel + 1]):
            page = (addresses[i] >> shift) << shift
            last = n_runs - 1
            if n_runs > page_offsets[pixel] and (page_runs[last] >> shift) << shift == page \
                    and page_runs[last] - page < most:
                page_runs[last] += np.uint64(1)
            else:
                page_runs[n_runs] = page
                n_runs += 1
        page_offsets[pixel + 1] = n_runs
    return n_runs


@njit(cache=True, nogil=True)
def _take_out_certain_hits(line_offsets, addresses, writes, line_shift, rel_shift, set_mask, skip_mask, owner, since,
                           last_read):
    """Take the certain first-level read hits out of every pixel's accesses, in place (see the module's
    docstring); returns the accesses kept.

    ``owner[l, s]`` is the level-``l`` line of the last access to set ``s`` of level ``l``, ``since[l, s]``
    the index of the first access of its run there (the accesses to that set since were all to that line);
    ``last_read[s]`` the index of the last read of first-level set ``s``. A read is certain to hit if the
    last read of its first-level set, made in this pixel, was of its line and, at every level, the set's
    run of the line began no later than that read. ``line_offsets`` becomes the kept accesses' offsets.
    """
    n_levels = rel_shift.shape[0]
    shift = np.uint64(line_shift)
    mask0 = set_mask[0]
    kept = 0
    start = line_offsets[0]
    for pixel in range(line_offsets.shape[0] - 1):
        stop = line_offsets[pixel + 1]
        carrier = -1  # the kept access the taken-out ones after it count on
        for i in range(start, stop):
            address = addresses[i]
            line = np.int64(address >> shift)
            write = writes[i]
            read_at = last_read[line & mask0]
            certain = (not write and carrier >= 0 and read_at >= start
                       and (addresses[carrier] & np.uint64(skip_mask)) < np.uint64(skip_mask))
            for level in range(n_levels):
                level_line = line >> rel_shift[level]
                s = level_line & set_mask[level]
                if owner[level, s] != level_line:
                    certain = False
                    owner[level, s] = level_line
                    since[level, s] = i
                elif since[level, s] > read_at:
                    certain = False
            if not write:
                last_read[line & mask0] = i
            if certain:
                addresses[carrier] += np.uint64(1)
            else:
                addresses[kept] = address
                writes[kept] = write
                carrier = kept
                kept += 1
        line_offsets[pixel + 1] = kept
        start = stop
    return kept


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
