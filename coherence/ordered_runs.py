"""Ray orders composed with pixel mappings: each process owns rays by the mapping, then orders its own rays.

A path-traced trace (:mod:`tracer.trace.segments`) logs every ray's records
as one segment, and a ray's records do not depend on when other rays run,
so a ray order is a permutation of record *pieces* (a segment, or part of
one), plus the auxiliary records the order itself reads and writes (ray
state, queue entries). This module turns a mapping's
:class:`~coherence.distribution.Distribution` and an order into a schedule
the existing simulation runs unchanged (:func:`coherence.simulation.simulate_run`):

* The unit an order works on is what one process owns at once: under a
  static mapping, every pixel the process renders (its tasks in task
  order); under a dynamic one (DB), each handed-out task, so rays are
  ordered within each block.
* An order (:data:`Order`) returns, for one unit's segments in depth-first
  order, the pieces in replay order as ranges of an extended record space:
  positions below ``n_records`` are the trace's records, positions from
  ``n_records`` on index the unit's own auxiliary records.
* Pieces become *pseudo-pixels*: consecutive pieces of one pixel that
  follow each other in the records merge, and every pseudo-pixel is
  numbered by where its records lie, so the pseudo-trace's records are the
  trace's records followed by every unit's auxiliary records (no copy of
  the trace's records when no order adds any). A unit is one task of the
  pseudo-distribution, its pseudo-pixels in replay order; static units are
  owned by their process, dynamic ones are handed out as the mapping's
  tasks were.
* A pixel's compute cycles are shared among its pieces by their record
  counts (a whole pixel keeps its cycles exactly). A unit's sorting cycles
  are added to its first pseudo-pixel, and so are its pixels' counters,
  summed (a unit's pieces all run on one process, so the sums per process
  are unchanged; the other pieces' rows stay zero and, left unwritten,
  take no memory).

So the depth-first order (each unit's segments as they are, no auxiliary
records) replays exactly the run of the mapping itself.

Auxiliary records live where the order's buffers are (an ``extents``
function, such as :meth:`coherence.ray_order_base.OrderBuffers.extents`):
:func:`with_order_buffers` numbers every distinct buffer address as a record
of the auxiliary kind and places it there, so the simulation reads and
writes them as it does the scene's records. A static unit uses its
process's buffers; every dynamic task uses process 0's, which, since every
CPU of the simulation has caches of its own, is each process reusing its
own buffers from one block to the next (two processes time-sharing one CPU
would share them).

On a platform's shared levels, :func:`simulate_ordered_shared` runs the
same pseudo-pixels through :func:`coherence.shared_run.simulate_shared_run`.
There the buffers must be the replaying process's own even under DB (one
process's buffer lines would otherwise move between cores), so their
records are private to a process, as the tracer's per-ray data are: the run
places process ``p``'s at ``OrderBuffers.extents(.., p)`` whichever blocks
it takes. The depth-first order replays the platform's run of the mapping
itself there too.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from coherence.distribution import Distribution
from rtcommon.validate import InputError
from tracer.trace.records import AUXILIARY_KIND, INDEX_MASK, KIND_SHIFT, N_KINDS, WRITE_FLAG, pack_aux, unpack_aux
from tracer.trace.segments import SegmentColumn


class OrderedUnit(NamedTuple):
    """What an order makes of one unit's rays.

    Attributes
    ----------
    starts, stops : ndarray of int64, shape (N,)
        Pieces in replay order: positions ``starts[i] .. stops[i] - 1`` of
        the extended record space (below ``n_records``: the trace's
        records; from ``n_records`` on: ``aux[position - n_records]``).
    aux : ndarray of uint32, shape (M,)
        The unit's auxiliary records; every one in exactly one piece.
    sort_cycles : float
        Cycles the order spends sorting the unit's rays.
    """

    starts: np.ndarray
    stops: np.ndarray
    aux: np.ndarray
    sort_cycles: float


#: An order: ``order(segments, rows, n_records) -> OrderedUnit``, where ``segments``
#: is the trace's :class:`~tracer.trace.segments.RaySegments` and ``rows`` (int64)
#: the unit's segment rows in depth-first order.
Order = Callable[..., OrderedUnit]


def depth_first(segments, rows: np.ndarray, n_records: int) -> OrderedUnit:
    """Each ray's segment in the order the path tracer traced it: the mapping's own run."""
    ints = segments.ints
    return OrderedUnit(ints[rows, SegmentColumn.FIRST], ints[rows, SegmentColumn.STOP], np.zeros(0, np.uint32), 0.0)


def pieces_unit(pieces, n_records: int) -> OrderedUnit:
    """The :class:`OrderedUnit` of an ``OrderedPieces`` (:mod:`coherence.ray_order_base`).

    Its auxiliary record ``i`` is replayed just before piece ``aux_after[i]``
    (after the last piece when that is the number of pieces), auxiliary
    records of one place in their own order.
    """
    n_pieces = len(pieces.piece_first)
    n_aux = len(pieces.aux_records)
    keys = np.concatenate([2 * np.arange(n_pieces, dtype=np.int64) + 1, 2 * np.asarray(pieces.aux_after, np.int64)])
    sequence = np.argsort(keys, kind="stable")
    aux_at = n_records + np.arange(n_aux, dtype=np.int64)
    starts = np.concatenate([np.asarray(pieces.piece_first, np.int64), aux_at])[sequence]
    stops = np.concatenate([np.asarray(pieces.piece_stop, np.int64), aux_at + 1])[sequence]
    return OrderedUnit(starts, stops, np.asarray(pieces.aux_records, np.uint32), float(pieces.sort_cycles))


class PieceTrace(NamedTuple):
    """A trace whose pixels are pieces (``width`` pieces, ``height`` 1), as the simulation reads a trace."""

    pixel_offsets: np.ndarray  #: (Q + 1,) int64
    records: np.ndarray        #: (R + M,) uint32: the trace's records, then every unit's auxiliary records
    counters: np.ndarray       #: (Q, K) int64
    width: int
    height: int


class OrderedWork(NamedTuple):
    """An ordered run's inputs for :func:`coherence.simulation.simulate_run`, and what it is made of."""

    trace: PieceTrace
    distribution: Distribution  #: over the pieces (``width`` x 1)
    compute: np.ndarray         #: (Q,) float64 compute cycles per piece
    n_aux: int                  #: auxiliary records of all units
    sort_cycles: float          #: of all units
    aux_process: np.ndarray     #: (n_aux,) int64 whose buffers each auxiliary record is in


def unit_pixels(distribution: Distribution) -> list:
    """The pixels of each unit an order works on, in render order (static: per process; dynamic: per task)."""
    if distribution.dynamic:
        return [distribution.task(t) for t in range(distribution.n_tasks)]
    return [distribution.process_pixels(p) for p in range(distribution.n_processes)]


def _ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """The integers of every range ``starts[i] .. stops[i] - 1``, ranges one after another (int64)."""
    lengths = stops - starts
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    ends = np.cumsum(lengths)
    return np.arange(total, dtype=np.int64) + np.repeat(starts - (ends - lengths), lengths)


def ordered_work(trace, distribution: Distribution, order: Order, pixel_compute: np.ndarray,
                 name: str = "order") -> OrderedWork:
    """Compose ``distribution`` (a mapping's, for the trace's image) with ``order`` (module docstring).

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Path-traced: with ``segments``.
    distribution : Distribution
    order : Order
    pixel_compute : ndarray of float64, shape (P,)
        Compute cycles of each pixel (:meth:`coherence.cost.CostModel.compute_cycles`).
    name : str
        The order's name, for error messages.

    Returns
    -------
    OrderedWork

    Raises
    ------
    ValueError
        The trace has no segments, a pixel has no records, or the order's pieces do not replay
        every record of the unit's rays and every auxiliary record exactly
        once.
    """
    segments = trace.segments
    if segments is None:
        raise InputError("ray orders need a path-traced trace (with segments); render with --workload pathtrace")
    if (distribution.width, distribution.height) != (trace.width, trace.height):
        raise InputError(f"distribution is for {distribution.width}x{distribution.height} pixels, "
                         f"the trace for {trace.width}x{trace.height}")
    n_records = int(trace.n_records)
    pixel_offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    n_pixels = pixel_offsets.shape[0] - 1
    if np.any(pixel_offsets[1:] == pixel_offsets[:-1]):
        raise InputError("ray orders need every pixel to have records (each path's camera ray reads the root)")
    seg_offsets = np.searchsorted(segments.ints[:, SegmentColumn.PIXEL], np.arange(n_pixels + 1)).astype(np.int64)
    starts, stops, unit_of, aux_parts, sort, aux_process, unit_counters = [], [], [], [], [], [], []
    pixel_counters = np.asarray(trace.counters)
    aux_base = n_records
    for unit, pixels in enumerate(unit_pixels(distribution)):
        rows = _ranges(seg_offsets[pixels], seg_offsets[pixels + 1])
        result = order(segments, rows, n_records)
        first, stop = _checked_unit(result, segments, rows, n_records, name)
        shift = np.where(first >= n_records, aux_base - n_records, 0)
        starts.append(first + shift)
        stops.append(stop + shift)
        unit_of.append(np.full(len(first), unit, np.int64))
        aux_parts.append(np.asarray(result.aux, np.uint32))
        aux_process.append(len(result.aux))  # records in process 0's buffers (dynamic) or its process's
        aux_base += len(result.aux)
        sort.append(float(result.sort_cycles))
        unit_counters.append(pixel_counters[pixels].sum(axis=0))
    starts, stops, unit_of = (np.concatenate(parts) if parts else np.zeros(0, np.int64)
                              for parts in (starts, stops, unit_of))
    starts, stops, unit_of = _merged(starts, stops, unit_of, pixel_offsets, n_records)
    rank = np.argsort(starts, kind="stable")
    offsets = np.append(starts[rank], aux_base)
    if not np.array_equal(stops[rank], offsets[1:]) or (len(offsets) and offsets[0] != 0):
        raise InputError(f"ray order {name!r}: its pieces do not replay every record exactly once")
    piece_id = np.empty(len(rank), np.int64)
    piece_id[rank] = np.arange(len(rank), dtype=np.int64)
    aux = np.concatenate(aux_parts) if aux_parts else np.zeros(0, np.uint32)
    del aux_parts
    records = np.asarray(trace.records) if len(aux) == 0 else np.concatenate([np.asarray(trace.records), aux])
    compute = _piece_compute(np.asarray(pixel_compute, np.float64), offsets, pixel_offsets, n_records)
    n_units = len(sort)
    first_piece = np.searchsorted(unit_of, np.arange(n_units))
    has_piece = first_piece < np.append(first_piece[1:], len(unit_of))
    np.add.at(compute, piece_id[first_piece[has_piece]], np.asarray(sort)[has_piece])
    counters = np.zeros((len(rank), pixel_counters.shape[1]), np.int64)
    if n_units:
        counters[piece_id[first_piece[has_piece]]] = np.asarray(unit_counters)[has_piece]
    task_offsets = np.searchsorted(unit_of, np.arange(n_units + 1)).astype(np.int64)
    n_pieces = len(rank)
    if distribution.dynamic:
        pieces = Distribution(distribution.name, n_pieces, 1, distribution.n_processes, task_offsets, piece_id, None,
                              distribution.dispatch_cycles, distribution.take_ahead)
    else:
        pieces = Distribution(distribution.name, n_pieces, 1, distribution.n_processes, task_offsets, piece_id,
                              np.arange(n_units, dtype=np.int64))
    aux_owner = np.zeros(n_units, np.int64) if distribution.dynamic else np.arange(n_units, dtype=np.int64)
    aux_process = np.repeat(aux_owner, np.asarray(aux_process, np.int64))
    return OrderedWork(PieceTrace(offsets, records, counters, n_pieces, 1), pieces, compute, len(aux), float(sum(sort)),
                       aux_process)


def _checked_unit(result, segments, rows, n_records: int, name: str) -> tuple:
    """The pieces of one unit as int64 arrays, checked to stay within the unit's records and its aux."""
    if not isinstance(result, OrderedUnit):
        raise InputError(f"ray order {name!r} must return an OrderedUnit, got {type(result).__name__}")
    first = np.asarray(result.starts, dtype=np.int64)
    stop = np.asarray(result.stops, dtype=np.int64)
    n_aux = len(result.aux)
    if first.shape != stop.shape or first.ndim != 1 or np.any(stop < first) \
            or np.any((first < n_records) & (stop > n_records)) or np.any(stop > n_records + n_aux):
        raise InputError(f"ray order {name!r}: a piece is not a range of the trace's records or of the unit's "
                         f"{n_aux} auxiliary records")
    own = int((segments.ints[rows, SegmentColumn.STOP] - segments.ints[rows, SegmentColumn.FIRST]).sum())
    if int((stop - first).sum()) != own + n_aux:
        raise InputError(f"ray order {name!r}: its pieces hold {int((stop - first).sum())} records, the unit's "
                         f"rays {own} and its auxiliary records {n_aux}")
    return first, stop


def _merged(starts, stops, unit_of, pixel_offsets, n_records: int) -> tuple:
    """Join each piece to the one before it when it continues it: same unit, records that follow on, and
    one pixel (or both auxiliary). Empty pieces are dropped."""
    keep = stops > starts
    starts, stops, unit_of = starts[keep], stops[keep], unit_of[keep]
    pixel = np.where(starts < n_records, np.searchsorted(pixel_offsets, starts, side="right") - 1, -1)
    joins = np.zeros(len(starts), bool)
    joins[1:] = (starts[1:] == stops[:-1]) & (unit_of[1:] == unit_of[:-1]) & (pixel[1:] == pixel[:-1])
    head = np.flatnonzero(~joins)
    tail_stop = np.append(head[1:], len(starts)) - 1
    return starts[head], stops[tail_stop], unit_of[head]


def _piece_compute(pixel_compute, offsets, pixel_offsets, n_records: int) -> np.ndarray:
    """Compute cycles per piece: a pixel's shared by record counts (a whole pixel keeps its own)."""
    starts, stops = offsets[:-1], offsets[1:]
    in_trace = starts < n_records
    pixel = np.searchsorted(pixel_offsets, starts[in_trace], side="right") - 1
    length = stops[in_trace] - starts[in_trace]
    pixel_length = pixel_offsets[pixel + 1] - pixel_offsets[pixel]
    cycles = pixel_compute[pixel]
    compute = np.zeros(len(starts))
    compute[in_trace] = np.where(length == pixel_length, cycles, cycles * length / pixel_length)
    return compute


def simulate_ordered(trace, distribution: Distribution, order: Order, hierarchy, placed, cost, machine, *,
                     name: str = "order", extents=None) -> tuple:
    """Simulate ``distribution`` with every unit's rays in ``order`` on ``machine``.

    Parameters are those of :func:`coherence.simulation.simulate_run` and of
    :func:`ordered_work`; ``extents`` places the order's auxiliary records
    (:func:`with_order_buffers`), needed when it adds any.

    Returns
    -------
    (coherence.simulation.Run, OrderedWork)
        The run's processes, pixels counting pieces; its ``pixel_misses`` are not asked for.
    """
    from coherence.simulation import simulate_run
    from tracer.trace.access import COUNTER_NAMES

    work = ordered_work(trace, distribution, order, cost.compute_cycles(trace.counters, COUNTER_NAMES), name)
    pieces = work.trace
    if work.n_aux:
        if machine.page_placement.translates:
            raise InputError(f"ray order {name!r} adds buffer records, which have no page frames: simulate it on "
                             "a machine without page placement")
        if extents is None:
            raise InputError(f"ray order {name!r} adds buffer records: give extents= to place them")
        placed, pieces = with_order_buffers(placed, work, int(trace.n_records), extents)
    return simulate_run(pieces, work.distribution, hierarchy, placed, cost, machine, compute=work.compute), work


def simulate_ordered_shared(trace, distribution: Distribution, order: Order, shared, placed, cost, machine, *,
                            name: str = "order", buffers=None) -> tuple:
    """Simulate ``distribution`` with every unit's rays in ``order`` on a platform's shared levels.

    The ordered work of :func:`ordered_work` runs through
    :func:`coherence.shared_run.simulate_shared_run`, so an order and the
    depth-first run it is compared with share one cache model. The order's
    buffers are each process's own, at the addresses
    :meth:`coherence.ray_order_base.OrderBuffers.extents` gives it: their
    records are private to the process that replays them (as the ray data of
    :data:`coherence.thread_streams.PRIVATE_KINDS` are), so under a dynamic
    mapping each handed-out block's rays use the buffers of the process that
    took it, and no two processes share a buffer line.

    Parameters
    ----------
    trace, distribution, order, placed, cost, machine, name
        As :func:`simulate_ordered` (``placed`` and ``machine`` without page placement).
    shared : coherence.shared_run.SharedLevels
        The platform's shared levels and its interleaving ``Q``.
    buffers : coherence.ray_order_base.OrderBuffers, optional
        Where each process's buffers lie (default ``OrderBuffers()``); its
        ``base`` must be at least its ``spacing``.

    Returns
    -------
    (coherence.shared_run.SharedRun, OrderedWork)
        The run (pixels counting pieces) and what it replayed.
    """
    from coherence.shared_run import SharedLevels, simulate_shared_run
    from tracer.trace.access import COUNTER_NAMES

    if not isinstance(shared, SharedLevels):
        raise InputError(f"simulate_ordered_shared needs SharedLevels, got {type(shared).__name__}")
    work = ordered_work(trace, distribution, order, cost.compute_cycles(trace.counters, COUNTER_NAMES), name)
    placed, pieces = shared_order_pieces(work, placed, int(trace.n_records), shared.hierarchy.levels[0].line_size,
                                         buffers, name)
    run = simulate_shared_run(pieces.trace, work.distribution, shared.machine,
                              placed, cost, machine, interleave_cycles=shared.interleave_cycles,
                              compute=work.compute, pieces=pieces.pieces)
    return run, work


class SharedOrderPieces(NamedTuple):
    """An ordered run's accesses for the shared levels (:func:`shared_order_pieces`)."""

    trace: PieceTrace  #: the pseudo-trace, aux records renumbered to the buffer rows
    pieces: object     #: :class:`coherence.piece_words.PixelPieces` of its pseudo-pixels


def shared_order_pieces(work: OrderedWork, placed, n_records: int, line_size: int, buffers=None,
                        name: str = "order") -> tuple:
    """The layout with the order's buffer rows and every pseudo-pixel's accesses, buffers private to a process.

    Every auxiliary record gets a row of process 0's buffer slots placed one
    ``spacing`` below process 0's buffers, its accesses marked private with
    ``spacing`` as the distance between two processes' copies: the run moves
    process ``p``'s to ``buffers.extents(.., p)``.

    Parameters
    ----------
    work : OrderedWork
    placed : coherence.layout.PlacedLayout
        Virtual addresses (no page placement).
    n_records : int
        The trace's records.
    line_size : int
        The first level's line size.
    buffers : coherence.ray_order_base.OrderBuffers, optional
    name : str
        The order's name, for error messages.

    Returns
    -------
    (PlacedLayout, SharedOrderPieces)
    """
    from coherence.ray_order_base import OrderBuffers
    from coherence.shared_run import pixel_pieces
    from coherence.piece_words import PRIVATE_BIT, PixelPieces
    from coherence.thread_streams import PRIVATE_KINDS

    if not work.n_aux:
        return placed, SharedOrderPieces(work.trace, pixel_pieces(work.trace, placed, line_size))
    buffers = OrderBuffers() if buffers is None else buffers
    if buffers.base < buffers.spacing:
        raise InputError(f"ray order {name!r} on shared levels: OrderBuffers.base ({buffers.base}) must be at least "
                         f"its spacing ({buffers.spacing})")
    trace_kinds = np.asarray(work.trace.records[:n_records]) >> np.uint32(KIND_SHIFT)
    if np.isin(trace_kinds, [int(kind) for kind in PRIVATE_KINDS]).any():
        # those copies are one layout span apart, the buffers one spacing: the run moves both by one distance
        raise InputError(f"ray order {name!r} on shared levels: the trace logs per-ray private records; ray orders "
                         "take path-traced traces, which log none")

    def below_process_zero(aux_records, process):
        start, size = buffers.extents(aux_records, 0)
        return start - buffers.spacing, size

    one_owner = OrderedWork(work.trace, work.distribution, work.compute, work.n_aux, work.sort_cycles,
                            np.zeros(work.n_aux, np.int64))
    placed, trace = with_order_buffers(placed, one_owner, n_records, below_process_zero)
    pieces = pixel_pieces(trace, placed, line_size)
    # the buffers' accesses are private as well: each process's buffers lie one spacing from the next's
    words = np.where(pieces.kinds == AUXILIARY_KIND, pieces.words | PRIVATE_BIT, pieces.words)
    return placed, SharedOrderPieces(trace, PixelPieces(pieces.piece_offsets, pieces.addresses, words,
                                                        int(buffers.spacing)))


def with_order_buffers(placed, work: OrderedWork, n_records: int, extents) -> tuple:
    """``placed`` with a record of the auxiliary kind for every buffer slot ``work``'s aux records may touch.

    Parameters
    ----------
    placed : coherence.layout.PlacedLayout
        Placed for the trace, virtual addresses (no page placement).
    work : OrderedWork
    n_records : int
        The trace's records (the aux records follow them in ``work.trace.records``).
    extents : callable
        ``extents(aux_records, process) -> (start, size)``, int64 arrays:
        where each auxiliary record of ``process`` lives. Each process has
        a row for every slot of each sub-kind up to the largest it uses.

    Returns
    -------
    (PlacedLayout, PieceTrace)
        The layout with its auxiliary rows (kinds between the last
        :class:`~tracer.trace.records.RecordKind` and the auxiliary kind
        hold none), and ``work.trace`` with its aux records renumbered to
        them (write flags kept).
    """
    from dataclasses import replace

    if placed.pages.frame.shape[0]:
        raise InputError("ray orders with buffers need virtual addresses: a machine without page placement")
    aux = np.asarray(work.trace.records[n_records:], np.uint32)
    sub, slot = (part.astype(np.int64) for part in unpack_aux(aux))
    row = np.empty(len(aux), np.int64)
    starts, sizes = [], []
    n_rows = 0
    for process in np.unique(work.aux_process):
        # rows of this process: each aux sub-kind's slots 0 .. its largest, sub-kinds one after another
        mine = work.aux_process == process
        for kind in np.unique(sub[mine]):
            these = mine & (sub == kind)
            n_slots = int(slot[these].max()) + 1
            row[these] = n_rows + slot[these]
            start, size = extents(pack_aux(int(kind), np.arange(n_slots)), int(process))
            starts.append(np.asarray(start, np.int64))
            sizes.append(np.asarray(size, np.int64))
            n_rows += n_slots
    if n_rows > INDEX_MASK + 1:
        raise InputError(f"the ray order's buffers span {n_rows} records, more than the "
                         f"{INDEX_MASK + 1} one record kind can index")
    addresses = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    buffer_sizes = np.concatenate(sizes) if sizes else np.zeros(0, np.int64)
    n_scene = len(placed.record_start)
    kind_first = np.empty(AUXILIARY_KIND + 2, np.int64)
    kind_first[:N_KINDS + 1] = placed.kind_first
    kind_first[N_KINDS + 1:] = n_scene
    kind_first[AUXILIARY_KIND + 1] = n_scene + n_rows
    buffered = replace(placed, record_start=np.concatenate([placed.record_start, addresses]),
                       record_size=np.concatenate([placed.record_size, buffer_sizes]), kind_first=kind_first)
    renumbered = ((np.uint32(AUXILIARY_KIND) << np.uint32(KIND_SHIFT)) | (aux & np.uint32(WRITE_FLAG))
                  | row.astype(np.uint32))
    records = np.concatenate([np.asarray(work.trace.records[:n_records]), renumbered])
    return buffered, work.trace._replace(records=records)
