"""Every pixel's line accesses, worked out once and shared by the runs of a study.

A schedule replay turns each pixel's records into line addresses
(:func:`coherence.record_lines.record_lines_and_writes`) every time it renders the
pixel, a large share of a replay's time. A study replays the same trace dozens of times with one layout and one
smallest line size, so :func:`pixel_lines` does that work once, and
:func:`coherence.simulation.simulate_run` reads slices of the result instead.
It costs 9 bytes per line access (address and write flag) and 16 per pixel
(offset and write count), so a study asks for it only within
:data:`SHARED_LINES_BUDGET`; the replay's counts are the same either way.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from coherence.layout import PlacedLayout
from coherence.record_lines import FILL_AHEAD, _count_lines, _fill_lines
from coherence.page_placement import translate_addresses
from rtcommon.validate import require_power_of_two

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
    """

    line_offsets: np.ndarray
    addresses: np.ndarray
    writes: np.ndarray
    pixel_writes: np.ndarray
    line_shift: int


def no_pixel_lines(line_shift: int) -> PixelLines:
    """The empty :class:`PixelLines`: a replay given it converts each pixel's records itself."""
    empty = np.zeros(0, dtype=np.int64)
    return PixelLines(empty, np.zeros(0, dtype=np.uint64), np.zeros(0, dtype=np.bool_), empty, int(line_shift))


def pixel_lines(trace, placed: PlacedLayout, line_size: int, budget_bytes: int | None = None) -> PixelLines | None:
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
    return PixelLines(line_offsets, addresses[:n_lines], writes[:n_lines], pixel_writes, line_shift)


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
