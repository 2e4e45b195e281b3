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

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.interleave import interleave
from cachesim.multicore_state import ThreadStream
from coherence.layout import PlacedLayout
from coherence.mappings import get_mapping
from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.trace.records import AUXILIARY_KIND, INDEX_MASK, KIND_SHIFT, WRITE_FLAG, RecordKind

__all__ = ["COUNTER_BYTES", "PRIVATE_KINDS", "RecordPlaces", "counter_address", "private_span", "record_pieces",
           "record_places", "split_records", "thread_stream"]

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


class RecordPlaces(NamedTuple):
    """Where each record lies, as :func:`split_records` reads it (from a :class:`PlacedLayout`).

    Attributes
    ----------
    kind_first : ndarray of int64, shape (K + 1,)
        Row of each kind's first record.
    record_start, record_size : ndarray of int64, shape (R,)
        First byte and bytes of each row.
    private_kind : ndarray of bool, shape (16,)
        Which record kinds each thread has a copy of (:data:`PRIVATE_KINDS`).
    span : int
        Bytes between two threads' copies (:func:`private_span`).
    line_shift : int
        log2 of the line size records are split at.
    """

    kind_first: np.ndarray
    record_start: np.ndarray
    record_size: np.ndarray
    private_kind: np.ndarray
    span: int
    line_shift: int


def record_places(records, placed: PlacedLayout, line_size: int) -> RecordPlaces:
    """The checked :class:`RecordPlaces` of ``placed`` for splitting ``records`` (uint32, (R,)) at lines of
    ``line_size`` bytes; refused when the layout's pages are translated or a record is not in it."""
    line_size = require_power_of_two("line_size", line_size)
    if placed.pages.frame.size:
        raise InputError("thread streams take virtual addresses: give a layout without page placement")
    placed.check_records(records)
    private_kind = np.zeros(1 << (32 - KIND_SHIFT), dtype=np.bool_)
    private_kind[[int(kind) for kind in PRIVATE_KINDS]] = True
    return RecordPlaces(placed.kind_first, placed.record_start, placed.record_size, private_kind,
                        private_span(placed), line_size.bit_length() - 1)


@njit(cache=True, inline="always")
def _record_bytes(record, thread, places):
    """Kind, first byte and end of one packed record made by ``thread`` (its own copy of a private kind)."""
    kind = np.int64(record >> np.uint32(KIND_SHIFT))
    row = places.kind_first[kind] + np.int64(record & np.uint32(INDEX_MASK))
    start = places.record_start[row]
    if places.private_kind[kind]:
        start += (thread + 1) * places.span
    return kind, start, start + places.record_size[row]


@njit(cache=True)
def _count_pieces(records, group_offsets, group_threads, places):
    """Accesses (lines spanned) of each group of records; int64 (G,)."""
    shift = places.line_shift
    counts = np.zeros(group_threads.shape[0], dtype=np.int64)
    for group in range(group_threads.shape[0]):
        thread = group_threads[group]
        n = np.int64(0)
        for i in range(group_offsets[group], group_offsets[group + 1]):
            _, start, end = _record_bytes(records[i], thread, places)
            n += ((end - 1) >> shift) - (start >> shift) + 1
        counts[group] = n
    return counts


@njit(cache=True)
def _fill_pieces(records, group_offsets, group_threads, places, out, record_of):
    """Write each record's accesses, in order, into ``out`` (a :class:`ThreadStream` of the right length;
    its ``threads`` left alone) and, when it is not empty, each access's record into ``record_of``."""
    shift = places.line_shift
    line_bytes = np.int64(1) << shift
    addresses, writes, sizes, kinds = out.addresses, out.writes, out.sizes, out.kinds
    with_records = record_of.shape[0] > 0
    k = 0
    for group in range(group_threads.shape[0]):
        thread = group_threads[group]
        for i in range(group_offsets[group], group_offsets[group + 1]):
            record = records[i]
            kind, start, end = _record_bytes(record, thread, places)
            is_write = (record & np.uint32(WRITE_FLAG)) != 0
            for line in range(start >> shift, ((end - 1) >> shift) + 1):
                line_start = line << shift
                first = max(start, line_start)
                addresses[k] = np.uint64(first)
                sizes[k] = min(end, line_start + line_bytes) - first
                kinds[k] = np.uint8(kind)
                writes[k] = is_write
                if with_records:
                    record_of[k] = i
                k += 1


def split_records(records, group_offsets, group_threads, places: RecordPlaces, *, with_records: bool = False):
    """Each record's accesses: one per line its bytes span, with its bytes there, its kind and write flag.

    Parameters
    ----------
    records : ndarray of uint32, shape (R,)
        Packed records, in access order, checked by :func:`record_places`.
    group_offsets : ndarray of int64, shape (G + 1,)
        Group ``g`` is records ``group_offsets[g]:group_offsets[g + 1]``.
    group_threads : ndarray of int64, shape (G,)
        Hardware thread that makes each group's records (chooses the copy
        of a private kind; -1: the layout's own place).
    places : RecordPlaces
    with_records : bool
        Also give the record each access comes from.

    Returns
    -------
    stream : ThreadStream
        One entry per access, in order; its ``threads`` empty (0,).
    counts : ndarray of int64, shape (G,)
        Accesses of each group.
    record_of : ndarray of int64, shape (N,) or (0,)
        With ``with_records``, the record of each access.
    """
    records = np.ascontiguousarray(records, dtype=np.uint32)
    group_offsets = np.ascontiguousarray(group_offsets, dtype=np.int64)
    group_threads = np.ascontiguousarray(group_threads, dtype=np.int64)
    if (group_offsets.ndim != 1 or group_offsets.size != group_threads.size + 1 or group_offsets[0] != 0
            or group_offsets[-1] != records.size or np.any(np.diff(group_offsets) < 0)):
        raise InputError(f"split_records: group_offsets must rise from 0 to the {records.size} records with one "
                         f"entry more than group_threads ({group_threads.size}), got shape {group_offsets.shape}")
    counts = _count_pieces(records, group_offsets, group_threads, places)
    n = int(counts.sum())
    out = ThreadStream(np.empty(n, dtype=np.uint64), np.zeros(0, dtype=np.int64), np.empty(n, dtype=np.bool_),
                       np.empty(n, dtype=np.int64), np.empty(n, dtype=np.uint8))
    record_of = np.empty(n if with_records else 0, dtype=np.int64)
    _fill_pieces(records, group_offsets, group_threads, places, out, record_of)
    return out, counts, record_of


def _pieces(records, threads, placed: PlacedLayout, line_size: int) -> tuple[ThreadStream, np.ndarray]:
    """:func:`record_pieces`, and the record each access comes from (int64, (N,))."""
    records = np.ascontiguousarray(records, dtype=np.uint32)
    places = record_places(records, placed, line_size)
    threads = np.asarray(threads, dtype=np.int64)
    if threads.shape != records.shape:
        raise InputError(f"record_pieces: threads must have one entry per record ({records.shape}), "
                         f"got shape {threads.shape}")
    # records in runs of one thread
    runs = np.flatnonzero(threads[1:] != threads[:-1]) + 1
    offsets = np.concatenate(([0], runs, [threads.size]) if threads.size else ([0],)).astype(np.int64)
    stream, counts, record = split_records(records, offsets, threads[offsets[:-1]], places, with_records=True)
    return ThreadStream(stream.addresses, np.repeat(threads[offsets[:-1]], counts), stream.writes, stream.sizes,
                        stream.kinds), record


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
