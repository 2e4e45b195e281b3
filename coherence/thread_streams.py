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

A dynamic mapping (DB) hands its tasks out through one shared counter.
Its order depends on the schedule; here it is the order of threads of
equal speed: task ``k`` goes to thread ``k % n``, and each thread takes its
tasks in order. Before each task its thread increments the counter, an
atomic read-modify-write of :data:`COUNTER_BYTES` bytes at
:func:`counter_address`: one write access of the auxiliary record kind
(:data:`tracer.trace.records.AUXILIARY_KIND`), which takes a turn of its
own in the rotation. A write needs the line exclusive, as the atomic
operation does, so every hand-out after another thread's is a coherence
miss: DB's counter traffic.
"""
from __future__ import annotations

import numpy as np

from cachesim.interleave import interleave
from cachesim.multicore_state import ThreadStream
from coherence.layout import PlacedLayout
from coherence.mappings import get_mapping
from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.trace.records import AUXILIARY_KIND, INDEX_MASK, KIND_SHIFT, WRITE_FLAG, RecordKind

__all__ = ["COUNTER_BYTES", "PRIVATE_KINDS", "counter_address", "private_span", "record_pieces", "thread_stream"]

#: Record kinds each process has a copy of.
PRIVATE_KINDS = (RecordKind.RAY_STACK, RecordKind.HIT_RECORD, RecordKind.SHADING_TEMP)
_PAGE = 4096
#: Bytes of a dynamic mapping's shared task counter (a 32-bit integer).
COUNTER_BYTES = 4


def private_span(placed: PlacedLayout) -> int:
    """Bytes between two threads' copies of the private kinds: the layout's end rounded up to a 4 KB page."""
    return -(-int(placed.end) // _PAGE) * _PAGE


def counter_address(placed: PlacedLayout) -> int:
    """Where a dynamic mapping's shared task counter lies: the first page after the layout's regions, below
    every thread's private copies."""
    return private_span(placed)


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
    return _pieces(records, threads, placed, line_size)[0]


def _pieces(records, threads, placed: PlacedLayout, line_size: int) -> tuple[ThreadStream, np.ndarray]:
    """:func:`record_pieces`, and the record each access comes from (int64, (N,))."""
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
                        (records[record] & WRITE_FLAG) != 0, end - first, kinds[record].astype(np.uint8)), record


def thread_stream(trace, placed: PlacedLayout, mapping, n_threads: int, *, line_size: int = 64,
                  pixels_per_turn: int = 1) -> ThreadStream:
    """The interleaved stream of ``n_threads`` hardware threads rendering ``trace`` under a static mapping.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placed : PlacedLayout
        Where the trace's records live.
    mapping : str or Mapping
        A static mapping (S, P, R, B ...), or a dynamic one (DB), whose tasks
        go round-robin to the threads, each after a write of the shared
        counter (see the module's docstring).
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
    hand_out = trace.width * trace.height  # the item that stands for a write of the task counter
    if distribution.dynamic:
        items = _handed_out(distribution, n_threads, hand_out)
    else:
        items = [distribution.process_pixels(p) for p in range(n_threads)]
    pixels, threads = interleave(items, pixels_per_turn)
    pixels = pixels.astype(np.int64)
    counter = pixels == hand_out
    pixel = np.where(counter, 0, pixels)
    offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    lengths = np.where(counter, 0, offsets[pixel + 1] - offsets[pixel])
    starts = np.repeat(offsets[pixel] - (np.cumsum(lengths) - lengths), lengths)
    rows = starts + np.arange(int(lengths.sum()))
    stream, record = _pieces(np.asarray(trace.records)[rows], np.repeat(threads, lengths), placed, line_size)
    if not counter.any():
        return stream
    # the counter's writes go in at their items' places: accesses sorted by the item they come from
    item = np.concatenate([np.repeat(np.arange(pixels.size), lengths)[record], np.flatnonzero(counter)])
    order = np.argsort(item, kind="stable")
    n = int(counter.sum())
    added = ThreadStream(np.full(n, counter_address(placed), dtype=np.uint64), threads[counter],
                         np.ones(n, dtype=bool), np.full(n, COUNTER_BYTES, dtype=np.int64),
                         np.full(n, AUXILIARY_KIND, dtype=np.uint8))
    return ThreadStream(*(np.concatenate([ours, theirs])[order] for ours, theirs in zip(stream, added)))


def _handed_out(distribution, n_threads: int, hand_out: int) -> list:
    """Each thread's items under a dynamic mapping: task ``k`` to thread ``k % n_threads``, each task its
    hand-out item ``hand_out`` then its pixels."""
    offsets = np.asarray(distribution.task_offsets, dtype=np.int64)
    pixels = np.asarray(distribution.task_pixels, dtype=np.int64)
    items = []
    for thread in range(n_threads):
        tasks = range(thread, offsets.size - 1, n_threads)
        items.append(np.concatenate([np.zeros(0, dtype=np.int64),
                                     *(np.concatenate(([hand_out], pixels[offsets[k]:offsets[k + 1]]))
                                       for k in tasks)]))
    return items
