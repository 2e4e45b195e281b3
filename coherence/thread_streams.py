"""One interleaved stream of hardware threads from a trace and a static mapping, for shared caches.

:func:`thread_stream` turns the pixels a static mapping gives each of ``n``
processes into the stream :func:`cachesim.multicore.simulate_threads`
replays: process ``p`` runs on hardware thread ``p``, and the threads take
turns of ``pixels_per_turn`` pixels each, round-robin, in their own pixel
order (a thread whose pixels are done drops out of the rotation). Each
record becomes one access per line its bytes span, with the bytes it
touches in that line and its kind, so a write to a 3-byte pixel of the
frame buffer and a read of the neighbouring pixel by another thread are
disjoint bytes of one line.

Per-ray data is private to a process: the records of
:data:`PRIVATE_KINDS` (ray stack, hit records, shading temporaries) of
thread ``t`` lie at their layout address plus ``(t + 1) * span``, with
``span`` the layout's extent rounded up to a 4 KB page, so that each
thread has its own copy at the same place in a page and no line holds two
threads' copies. The scene and the frame buffer stay shared.
"""
from __future__ import annotations

import numpy as np

from cachesim.multicore import ThreadStream, interleave
from coherence.layout import PlacedLayout
from coherence.mappings import get_mapping
from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.trace.records import INDEX_MASK, KIND_SHIFT, WRITE_FLAG, RecordKind

__all__ = ["PRIVATE_KINDS", "private_span", "record_pieces", "thread_stream"]

#: Record kinds each process has a copy of.
PRIVATE_KINDS = (RecordKind.RAY_STACK, RecordKind.HIT_RECORD, RecordKind.SHADING_TEMP)
_PAGE = 4096


def private_span(placed: PlacedLayout) -> int:
    """Bytes between two threads' copies of the private kinds: the layout's end rounded up to a 4 KB page."""
    return -(-int(placed.end) // _PAGE) * _PAGE


def record_pieces(records, threads, placed: PlacedLayout, line_size: int) -> ThreadStream:
    """Each record's accesses: one per line its bytes span, with its bytes there, its kind and write flag.

    Parameters
    ----------
    records : ndarray of uint32, shape (R,)
        Packed records, in access order.
    threads : ndarray of int64, shape (R,)
        Hardware thread of each record (chooses the copy of a private kind).
    placed : PlacedLayout
        Where the records live; refused when its pages are translated.
    line_size : int
        A power of two: the first cache level's line size.

    Returns
    -------
    ThreadStream
        ``addresses`` (first byte of each access), ``threads``, ``writes``,
        ``sizes`` and ``kinds``, one entry per access, in order.
    """
    line_size = require_power_of_two("line_size", line_size)
    if placed.pages.frame.size:
        raise InputError("thread streams take virtual addresses: give a layout without page placement")
    records = np.ascontiguousarray(records, dtype=np.uint32)
    placed.check_records(records)
    kinds = (records >> KIND_SHIFT).astype(np.int64)
    rows = placed.kind_first[kinds] + (records & INDEX_MASK).astype(np.int64)
    private = np.isin(kinds, [int(kind) for kind in PRIVATE_KINDS])
    starts = placed.record_start[rows] + np.where(private, (threads + 1) * private_span(placed), 0)
    ends = starts + placed.record_size[rows]
    spans = (ends - 1) // line_size - starts // line_size + 1
    record = np.repeat(np.arange(records.size), spans)
    piece = np.arange(record.size) - np.repeat(np.cumsum(spans) - spans, spans)
    line_start = (starts[record] // line_size + piece) * line_size
    first = np.maximum(starts[record], line_start)
    end = np.minimum(ends[record], line_start + line_size)
    return ThreadStream(first.astype(np.uint64), np.asarray(threads, dtype=np.int64)[record],
                        (records[record] & WRITE_FLAG) != 0, end - first, kinds[record].astype(np.uint8))


def thread_stream(trace, placed: PlacedLayout, mapping, n_threads: int, *, line_size: int = 64,
                  pixels_per_turn: int = 1) -> ThreadStream:
    """The interleaved stream of ``n_threads`` hardware threads rendering ``trace`` under a static mapping.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placed : PlacedLayout
        Where the trace's records live.
    mapping : str or Mapping
        A static mapping (S, P, R, B ...); a dynamic one is refused: its
        order depends on the schedule.
    n_threads : int
        Processes, one per hardware thread.
    line_size : int
        The first cache level's line size (records are split at its lines).
    pixels_per_turn : int
        Pixels a thread renders before the next thread's turn (>= 1).

    Returns
    -------
    ThreadStream
        The arrays :func:`cachesim.multicore.simulate_threads` takes (see
        :func:`record_pieces`).
    """
    n_threads = require_int("n_threads", n_threads, 1)
    pixels_per_turn = require_int("pixels_per_turn", pixels_per_turn, 1)
    mapping = get_mapping(mapping)
    distribution = mapping.build(trace.width, trace.height, n_threads)
    if distribution.dynamic:
        raise InputError(f"mapping {mapping.name!r} hands out work at run time: its threads' order comes from "
                         "the schedule, not from the mapping; give a static mapping")
    pixels, threads = interleave([distribution.process_pixels(p) for p in range(n_threads)], pixels_per_turn)
    pixels = pixels.astype(np.int64)
    offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    lengths = offsets[pixels + 1] - offsets[pixels]
    starts = np.repeat(offsets[pixels] - (np.cumsum(lengths) - lengths), lengths)
    rows = starts + np.arange(int(lengths.sum()))
    return record_pieces(np.asarray(trace.records)[rows], np.repeat(threads, lengths), placed, line_size)
