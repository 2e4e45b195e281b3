"""From records to the cache lines they touch: the one record-to-line rule, compiled.

A record read touches every line its bytes span (:func:`record_line_span`),
at the address :class:`coherence.layout.PlacedLayout` gives it; when the
layout's pages are placed in physical memory
(:meth:`~coherence.layout.PlacedLayout.with_pages`), the lines are
translated to physical addresses. The schedule replay
(:mod:`coherence.scheduler`) converts each pixel's records with
:func:`record_lines_and_writes`; :mod:`coherence.pixel_lines` converts a
whole trace once for the runs of a study.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from coherence.page_placement import translate_addresses
from rtcommon.jit import NO_REFCOUNTS, NOT_INLINED
from tracer.trace.records import record_id, record_is_write, record_kind

__all__ = ["FILL_AHEAD", "line_span_bound", "record_line_span", "record_lines", "record_lines_and_writes"]


#: Entries :func:`record_lines_and_writes` writes for every record, spanned
#: or not; its buffers keep this many spare.
FILL_AHEAD = 4


@njit(cache=True, inline="always")
def record_line_span(record, record_start, record_size, kind_first, line_shift):
    """First and last line a record's bytes span (the one record-to-line rule).

    Parameters
    ----------
    record : uint32
        A packed (kind, index) record of an access trace.
    record_start, record_size, kind_first : ndarray of int64
        The fields of a :class:`RecordPlacement`, passed as arrays so that a
        per-record loop reads no bundle field.
    line_shift : int
        log2 of the line size.

    Returns
    -------
    first, last : int
        Line numbers (address >> line_shift), ``first <= last``.
    """
    row = np.uint64(kind_first[np.uint64(record_kind(record))] + record_id(record))  # unsigned: no wraparound code
    start = record_start[row]
    return start >> line_shift, (start + record_size[row] - 1) >> line_shift


@njit(cache=True, nogil=True, inline="always")
def line_span_bound(placement, line_shift):
    """The most lines of ``2**line_shift`` bytes any placed record spans
    (wherever in a line it starts)."""
    return ((placement.max_size + (np.int64(1) << line_shift) - 2) >> line_shift) + 1


@njit(cache=True, nogil=True)
def record_lines(records, start, stop, placement, line_shift, buffer):
    """Byte addresses of the lines that ``records[start:stop]`` touch, in order.

    Parameters
    ----------
    records : ndarray of uint32, shape (N,)
    start, stop : int
        The records to read (one pixel's, say).
    placement : RecordPlacement
    line_shift : int
        log2 of the line size.
    buffer : ndarray of uint64, shape (M,)
        Receives the addresses; replaced by a larger one when too short.

    Returns
    -------
    buffer : ndarray of uint64
        ``buffer`` or its replacement, with the addresses at the front.
    count : int
        Addresses written.
    """
    buffer, _, count, _ = record_lines_and_writes(records, start, stop, placement, line_shift, buffer,
                                                  np.empty(0, dtype=np.bool_))
    return buffer, count


@njit(cache=True, nogil=True)
def record_lines_and_writes(records, start, stop, placement, line_shift, buffer, writes):
    """:func:`record_lines` that also says which line accesses are writes.

    ``writes`` (bool, shape ``buffer.shape``, or (0,) to leave the flags out)
    receives each address's write flag: every line of a record whose write
    flag is set (:func:`tracer.trace.records.record_is_write`) is written. Both
    buffers are replaced together when too short.

    Returns
    -------
    buffer : ndarray of uint64
    writes : ndarray of bool
    count : int
        Addresses written.
    n_writes : int
        How many of them are writes.

    The buffers are grown once, before they are filled (a fill loop that
    may replace its buffer runs several times slower), and keep
    :data:`FILL_AHEAD` spare entries. The lines are counted first only when
    the buffers could be too short for ``stop - start`` records of the
    longest span (:func:`line_span_bound`): a caller that sizes its buffers
    for that saves the counting pass.
    """
    if (stop - start) * line_span_bound(placement, line_shift) + FILL_AHEAD > buffer.shape[0]:
        needed = _count_lines(records, start, stop, placement, line_shift) + FILL_AHEAD
        if needed > buffer.shape[0]:
            size = max(needed, 2 * buffer.shape[0])  # exact for an empty buffer, else room to spare
            buffer = np.empty(size, dtype=np.uint64)
            if writes.shape[0] > 0:
                writes = np.empty(size, dtype=np.bool_)
    count, n_writes = _fill_lines(records, start, stop, placement, line_shift, buffer, writes)
    if placement.pages.frame.shape[0] > 0:
        translate_addresses(buffer, count, placement.pages)
    return buffer, writes, count, n_writes


@njit(cache=True, nogil=True, inline="always")
def _count_lines(records, start, stop, placement, line_shift):
    """How many line accesses ``records[start:stop]`` make."""
    record_start = placement.record_start
    record_size = placement.record_size
    kind_first = placement.kind_first
    needed = 0
    for i in range(start, stop):
        first, last = record_line_span(records[i], record_start, record_size, kind_first, line_shift)
        needed += last - first + 1
    return needed


@njit(cache=True, nogil=True, **NOT_INLINED, **NO_REFCOUNTS)
def _fill_lines(records, start, stop, placement, line_shift, buffer, writes):
    """Fill ``buffer`` (and ``writes``, unless it is empty), which are long
    enough for the lines and :data:`FILL_AHEAD` more.

    Every record's first FILL_AHEAD entries are written whether it spans
    them or not (the next record's overwrite the extra ones): records span
    1 to 4 lines of 32 bytes in no predictable order, and a loop over
    exactly its span ended in a mispredicted branch at almost every record.
    """
    record_start = placement.record_start
    record_size = placement.record_size
    kind_first = placement.kind_first
    flag = writes.shape[0] > 0
    k = 0
    n_writes = 0
    for i in range(start, stop):
        record = records[np.uint64(i)]
        first, last = record_line_span(record, record_start, record_size, kind_first, line_shift)
        write = record_is_write(record)
        span = last - first + 1
        if write:
            n_writes += span
        at = np.uint64(k)
        for j in range(FILL_AHEAD):
            buffer[at + np.uint64(j)] = np.uint64((first + j) << line_shift)
        if flag:
            for j in range(FILL_AHEAD):
                writes[at + np.uint64(j)] = write
        for j in range(FILL_AHEAD, span):  # the rare longer records
            buffer[at + np.uint64(j)] = np.uint64((first + j) << line_shift)
            if flag:
                writes[at + np.uint64(j)] = write
        k += span
    return k, n_writes
