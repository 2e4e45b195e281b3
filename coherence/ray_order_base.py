"""The base of every ray order: what an order returns, its buffers in memory, and the wavefront walk.

A path-traced trace's rays are segments (:mod:`tracer.trace.segments`): each
ray reads one run of records, and what it reads does not depend on when
other rays run. A *ray order* is therefore a permutation of segments (as a
mapping is a permutation of pixels), possibly cut into pieces (a treelet
order suspends a ray where it enters another treelet), plus the records the
order itself adds: its ray buffer and its queues are memory too.

An order takes the segments one process owns, as rows of
:class:`~tracer.trace.segments.RaySegments` in their depth-first order (a
pixel's samples in order, each sample's rays in the order traced), and
returns :class:`OrderedPieces`: the record ranges to replay, in order, the
auxiliary records (:data:`tracer.trace.records.AUXILIARY_KIND`) to replay
between them, and the cycles it spends sorting.

Auxiliary records
-----------------
* ``RAY_STATE`` (index: the path's slot, its rank among the process's
  paths): a path's state, :data:`RAY_STATE_BYTES` bytes, written when one
  of its rays is suspended and read when it resumes.
* ``QUEUE_ENTRY`` (index: a slot of a queue): a 4-byte ray id
  (:data:`QUEUE_ENTRY_BYTES`), written when a ray is queued and read when
  it is taken off the queue.

They live in a region of their own per process (:class:`OrderBuffers`),
far above every scene layout, like the private kinds' per-thread copies:
one process's buffers never share a line with the scene or with another
process's buffers. :func:`coherence.ordered_runs.with_order_buffers` places
them for the schedule simulation at the same addresses.

Wavefronts
----------
:func:`wavefront_pieces` runs a process's rays in *phases*: phase ``2 k``
holds the extension rays of bounce ``k`` (camera rays for ``k = 0``), phase
``2 k + 1`` the shadow rays cast from their hits. A ray exists only after
its parent (the extension ray of its path before it) has run, and every
parent of phase ``p`` lies in phase ``p - 1`` or ``p - 2``, so running the
phases in order respects every data dependence. Within a phase, rays run
in the order they were queued (first in, first out; camera rays in the
process's depth-first order), or sorted stably by a key. The walk:

1. at the start, every camera ray is queued (its queue entry written) and
   its path's state written (the path is created);
2. a ray resumes (its queue entry and its path's state read), runs its
   records, is suspended (its path's state written) and, if it is an
   extension ray, queues its children (the shadow rays of its hit, then the
   next bounce), one queue entry written each.

A phase's queue holds its rays at their queue positions; three queues are
live at once (the phase being run and the two it fills), so phase ``p``
uses the queue slots ``(p mod 3) * C ..``, with ``C`` the largest phase. A
sorted phase is sorted in place: its rays are read from the slots of their
sorted positions; the sort's cycles come from
:func:`coherence.cost.ray_sort_cycles`, its memory traffic is not replayed.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cachesim import CacheState, Hierarchy, SimulationResult, simulate
from coherence.cost import ray_sort_cycles
from coherence.layout import PlacedLayout
from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.trace.records import (AUX_INDEX_MASK, AUX_KIND_SHIFT, AUXILIARY_KIND, INDEX_MASK, KIND_SHIFT, WRITE_FLAG,
                                  AuxKind, pack_aux)
from tracer.trace.segments import RaySegments, SegmentColumn, SegmentRayType

#: Bytes of a path's saved state in a ray buffer: origin, direction, throughput
#: and radiance so far as 3 float32 each (48), pixel and sample (4 + 4), bounce
#: and random-number counter (4 + 4); a float32 path tracer's ray record.
RAY_STATE_BYTES = 64
#: Bytes of a queue entry: a 32-bit ray id (the ray buffer's slot).
QUEUE_ENTRY_BYTES = 4
#: Where process 0's order buffers start: above every layout (bases < 2**48)
#: and below the background load's regions (2**56 up).
ORDER_BUFFERS_BASE = 1 << 50
#: Bytes between two processes' order buffers.
ORDER_BUFFERS_SPACING = 1 << 40
#: Offset of the queues from the ray buffer (room for 2**24 slots of 256 bytes).
QUEUE_OFFSET = 1 << 32


@dataclass(frozen=True)
class OrderBuffers:
    """Where a ray order's buffers live and how big their entries are.

    Parameters
    ----------
    ray_state_bytes : int
        Bytes of a path's saved state (1 .. 256).
    queue_entry_bytes : int
        Bytes of a queue entry (1 .. 256).
    base : int
        Address of process 0's ray buffer, a multiple of 4096; its queues
        start :data:`QUEUE_OFFSET` bytes later.
    spacing : int
        Bytes between two processes' buffers (a power of two >= 2**33).
    """

    ray_state_bytes: int = RAY_STATE_BYTES
    queue_entry_bytes: int = QUEUE_ENTRY_BYTES
    base: int = ORDER_BUFFERS_BASE
    spacing: int = ORDER_BUFFERS_SPACING

    def __post_init__(self):
        require_int("OrderBuffers.ray_state_bytes", self.ray_state_bytes, 1, 256)
        require_int("OrderBuffers.queue_entry_bytes", self.queue_entry_bytes, 1, 256)
        require_int("OrderBuffers.base", self.base, 0, 2**55)
        if self.base % 4096:
            raise InputError(f"OrderBuffers.base must be a multiple of 4096, got {self.base}")
        require_power_of_two("OrderBuffers.spacing", self.spacing)
        if self.spacing < 2 * QUEUE_OFFSET:
            raise InputError(f"OrderBuffers.spacing must be >= {2 * QUEUE_OFFSET}, got {self.spacing}")

    def extents(self, aux_records, process: int) -> tuple[np.ndarray, np.ndarray]:
        """Address and size of each auxiliary record of ``process``: int64 (A,) each."""
        process = require_int("process", process, 0, 1023)
        records = np.asarray(aux_records, dtype=np.uint32)
        if np.any((records >> KIND_SHIFT) != AUXILIARY_KIND):
            raise InputError(f"aux_records must all be of the auxiliary kind {AUXILIARY_KIND}")
        index = (records & np.uint32(INDEX_MASK)).astype(np.int64)
        sub, slot = index >> AUX_KIND_SHIFT, index & AUX_INDEX_MASK
        state = sub == AuxKind.RAY_STATE
        if np.any(~state & (sub != AuxKind.QUEUE_ENTRY)):
            raise InputError("aux_records of a ray order must be ray states or queue entries")
        size = np.where(state, self.ray_state_bytes, self.queue_entry_bytes).astype(np.int64)
        start = self.base + process * self.spacing + np.where(state, 0, QUEUE_OFFSET) + slot * size
        return start, size


class OrderedPieces(NamedTuple):
    """What a ray order replays for one process, in order.

    Attributes
    ----------
    piece_first, piece_stop : ndarray of int64, shape (Q,)
        Piece ``q`` replays the trace's records ``piece_first[q] .. piece_stop[q] - 1``.
    piece_segment : ndarray of int64, shape (Q,)
        The segment (row of the trace's RaySegments) each piece belongs to.
    aux_records : ndarray of uint32, shape (A,)
        Records the order adds (ray states, queue entries; write flag set on
        writes), in replay order.
    aux_after : ndarray of int64, shape (A,)
        How many pieces are replayed before each auxiliary record
        (non-decreasing; ``Q`` for one after the last piece).
    sort_cycles : float
        Cycles the order spends sorting rays (no memory traffic replayed).
    """

    piece_first: np.ndarray
    piece_stop: np.ndarray
    piece_segment: np.ndarray
    aux_records: np.ndarray
    aux_after: np.ndarray
    sort_cycles: float

    @property
    def n_pieces(self) -> int:
        return int(self.piece_first.shape[0])

    def aux_counts(self) -> dict:
        """Auxiliary records by sub-kind and direction: ``{"ray_state_reads": .., "ray_state_writes": ..,
        "queue_reads": .., "queue_writes": ..}``."""
        records = self.aux_records
        sub = (records & np.uint32(INDEX_MASK)) >> np.uint32(AUX_KIND_SHIFT)
        write = (records & np.uint32(WRITE_FLAG)) != 0
        counts = {}
        for name, kind in (("ray_state", AuxKind.RAY_STATE), ("queue", AuxKind.QUEUE_ENTRY)):
            counts[f"{name}_reads"] = int(np.count_nonzero((sub == kind) & ~write))
            counts[f"{name}_writes"] = int(np.count_nonzero((sub == kind) & write))
        return counts

    def records(self, trace_records) -> tuple[np.ndarray, np.ndarray]:
        """The replayed stream: every piece's records with the auxiliary records between them.

        Returns
        -------
        records : ndarray of uint32, shape (M,)
        is_aux : ndarray of bool, shape (M,)
            True for the order's own records.
        """
        trace_records = np.asarray(trace_records)
        lengths = self.piece_stop - self.piece_first
        # auxiliary record i comes after the records of pieces 0 .. aux_after[i] - 1 and after i others
        n_total = int(lengths.sum()) + self.aux_records.shape[0]
        is_aux = np.zeros(n_total, dtype=bool)
        aux_place = np.concatenate(([0], np.cumsum(lengths)))[self.aux_after] + np.arange(self.aux_records.shape[0])
        is_aux[aux_place] = True
        out = np.empty(n_total, dtype=np.uint32)
        out[aux_place] = self.aux_records
        if lengths.sum():
            starts = np.repeat(self.piece_first - (np.cumsum(lengths) - lengths), lengths)
            out[~is_aux] = trace_records[starts + np.arange(int(lengths.sum()))]
        return out, is_aux


class RayOrder:
    """Base of ray orders.

    Subclasses are frozen dataclasses with a ``name`` that implement
    ``_order(segments, rows, scene_bounds, tree, records) -> OrderedPieces``
    on validated arguments (:func:`coherence.ray_orders.order_pieces` calls
    it): ``segments`` a RaySegments, ``rows`` int64 (S,), ``scene_bounds``
    float64 (2, 3) (lowest and highest corner of the scene), ``tree`` the
    kd-tree or None and ``records`` the trace's records (uint32 (R,)) or None.
    """

    name: str  # provided by each subclass
    #: Whether the order needs the kd-tree (treelet orders).
    needs_tree: bool = False
    #: Whether the order reads the trace's records (treelet orders).
    needs_records: bool = False

    def _order(self, segments: RaySegments, rows: np.ndarray, scene_bounds: np.ndarray, tree,
               records) -> OrderedPieces:  # pragma: no cover
        raise NotImplementedError


def depth_first_pieces(segments: RaySegments, rows: np.ndarray) -> OrderedPieces:
    """Each segment whole, in the given order, with no record of the order's own."""
    ints = segments.ints[rows]
    empty = np.zeros(0, dtype=np.int64)
    return OrderedPieces(ints[:, SegmentColumn.FIRST].astype(np.int64), ints[:, SegmentColumn.STOP].astype(np.int64),
                         rows.astype(np.int64), np.zeros(0, dtype=np.uint32), empty, 0.0)


def path_structure(ints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Paths, phases and parents of a process's segments in depth-first order.

    Parameters
    ----------
    ints : ndarray of int64, shape (S, 6)
        The segments' rows of ``RaySegments.ints``, in depth-first order.

    Returns
    -------
    path : ndarray of int64, shape (S,)
        Rank of each segment's path (pixel, sample) in the order.
    phase : ndarray of int64, shape (S,)
        ``2 * bounce`` for an extension ray, ``2 * bounce + 1`` for a shadow ray.
    parent : ndarray of int64, shape (S,)
        Position of the extension ray that spawned each ray (-1 for camera rays).
    extension : ndarray of bool, shape (S,)
        Whether each ray is a camera or bounce ray.

    Raises
    ------
    ValueError
        If a path's rays are not in depth-first order (a path whose rays are
        not consecutive, or a ray before its parent).
    """
    n = ints.shape[0]
    pixel, sample = ints[:, SegmentColumn.PIXEL], ints[:, SegmentColumn.SAMPLE]
    new_path = np.ones(n, dtype=bool)
    new_path[1:] = (pixel[1:] != pixel[:-1]) | (sample[1:] != sample[:-1])
    path = np.cumsum(new_path) - 1
    ray_type = ints[:, SegmentColumn.RAY_TYPE]
    bounce = ints[:, SegmentColumn.BOUNCE]
    extension = ray_type != SegmentRayType.SHADOW
    phase = 2 * bounce + (~extension)
    # the latest extension ray up to each position, within its path
    last_extension = np.where(extension, np.arange(n), -1)
    last_extension = np.maximum.accumulate(last_extension) if n else last_extension
    path_start = np.flatnonzero(new_path)[path] if n else path
    previous = np.concatenate(([-1], last_extension[:-1])) if n else last_extension
    parent = np.where(extension, previous, last_extension)
    parent = np.where(parent >= path_start, parent, -1)
    camera = ray_type == SegmentRayType.CAMERA
    expected = np.where(extension, 2 * (bounce - 1), 2 * bounce)
    bad = (camera != (parent < 0)) | (~camera & (parent >= 0) & (phase[np.maximum(parent, 0)] != expected))
    bad |= new_path & ~camera
    if n and len(np.unique(np.stack((pixel[new_path], sample[new_path])), axis=1)[0]) != int(new_path.sum()):
        bad[0] = True
    if bad.any():
        s = int(np.flatnonzero(bad)[0])
        raise InputError(f"segments: the rays of a path must be consecutive and in depth-first order (camera ray, "
                         f"its shadow rays, then each bounce and its shadow rays); segment position {s} (pixel "
                         f"{int(pixel[s])}, sample {int(sample[s])}) is not")
    return path.astype(np.int64), phase.astype(np.int64), parent.astype(np.int64), extension


def wavefront_pieces(segments: RaySegments, rows: np.ndarray, keys: np.ndarray | None = None,
                     key_bits: int = 0) -> OrderedPieces:
    """The wavefront walk of the module docstring, FIFO or sorted by ``keys`` within each phase.

    Parameters
    ----------
    segments : RaySegments
    rows : ndarray of int64, shape (S,)
        The process's segments in depth-first order.
    keys : ndarray of uint64, shape (S,), optional
        A sort key per segment (ties keep queue order); None: first in, first out.
    key_bits : int
        Significant bits of the keys (the sort's passes; 0 without keys).

    Returns
    -------
    OrderedPieces
    """
    ints = segments.ints[rows]
    path, phase, parent, extension = path_structure(ints)
    n = rows.shape[0]
    run_seq = np.full(n, -1, dtype=np.int64)   # global replay position of each segment
    queue_pos = np.zeros(n, dtype=np.int64)    # position in its phase's queue when queued
    run_pos = np.zeros(n, dtype=np.int64)      # position in its phase's queue when run (sorted)
    n_phases = int(phase.max()) + 1 if n else 0
    members_of = np.argsort(phase, kind="stable")
    bounds = np.searchsorted(phase[members_of], np.arange(n_phases + 1))
    sort_cycles = 0.0
    done = 0
    for p in range(n_phases):
        members = members_of[bounds[p]:bounds[p + 1]]
        # queue order: by when the parent ran, children of one parent in depth-first order
        queued = members[np.lexsort((members, run_seq[np.maximum(parent[members], 0)]))]
        queue_pos[queued] = np.arange(queued.size)
        if keys is not None:
            ran = queued[np.argsort(keys[queued], kind="stable")]
            sort_cycles += ray_sort_cycles(queued.size, key_bits)
        else:
            ran = queued
        run_pos[ran] = np.arange(ran.size)
        run_seq[ran] = done + np.arange(ran.size)
        done += ran.size
    order = np.argsort(run_seq)
    capacity = int(np.diff(bounds).max(initial=0))
    return _wavefront_records(rows, ints, order, (path, phase, parent, extension), (queue_pos, run_pos, capacity),
                              sort_cycles)


def _wavefront_records(rows, ints, order, structure, queues, sort_cycles) -> OrderedPieces:
    """Pieces and auxiliary records of the wavefront walk, rays in ``order`` (positions into ``rows``)."""
    path, phase, parent, extension = structure
    queue_pos, run_pos, capacity = queues
    n = rows.shape[0]
    if 3 * capacity > AUX_INDEX_MASK + 1 or (n and path.max() > AUX_INDEX_MASK):
        raise InputError(f"a wavefront of {capacity} rays (or {int(path.max(initial=0)) + 1} paths) is more than "
                         f"the auxiliary records' {AUX_INDEX_MASK + 1} slots hold: give the process fewer rays")
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    queue_slot = (phase % 3) * capacity + queue_pos
    run_slot = (phase % 3) * capacity + run_pos
    # events (after how many pieces, tie-break, record): sorted by the first two
    camera = np.flatnonzero(parent < 0)
    children = np.flatnonzero(parent >= 0)
    state, queue = int(AuxKind.RAY_STATE), int(AuxKind.QUEUE_ENTRY)
    # at one place: the camera rays' creation, then the previous ray's suspension (its state, then its
    # children's queue entries in depth-first order), then the next ray's resumption (queue entry, state)
    after = [np.zeros(2 * camera.size, dtype=np.int64), rank, rank, rank + 1, rank[parent[children]] + 1]
    tie = [np.arange(2 * camera.size) - 2 * camera.size, np.full(n, n + 1), np.full(n, n + 2),
           np.zeros(n, np.int64), 1 + children]
    start = (pack_aux(queue, queue_slot[camera], True), pack_aux(state, path[camera], True))
    records = [np.stack(start, axis=1).reshape(-1) if camera.size else np.zeros(0, np.uint32),
               pack_aux(queue, run_slot, False), pack_aux(state, path, False), pack_aux(state, path, True),
               pack_aux(queue, queue_slot[children], True)]
    after, tie, records = np.concatenate(after), np.concatenate(tie), np.concatenate(records)
    sequence = np.lexsort((tie, after))
    return OrderedPieces(ints[order, SegmentColumn.FIRST].astype(np.int64),
                         ints[order, SegmentColumn.STOP].astype(np.int64), rows[order].astype(np.int64),
                         records[sequence].astype(np.uint32), after[sequence], float(sort_cycles))


def order_stream(trace_records, pieces: OrderedPieces, placed: PlacedLayout, line_size: int, *,
                 buffers: OrderBuffers = OrderBuffers(), process: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The line accesses a process makes when it replays ``pieces``.

    Parameters
    ----------
    trace_records : ndarray of uint32, shape (N,)
        The trace's records.
    pieces : OrderedPieces
    placed : PlacedLayout
        Where the scene's records live (virtual addresses).
    line_size : int
        A power of two: every line of this size a record spans is one access.
    buffers : OrderBuffers
        Where the order's buffers live.
    process : int
        Whose buffers (0 .. 1023).

    Returns
    -------
    addresses : ndarray of uint64, shape (M,)
        First byte of every line accessed, in order.
    writes : ndarray of bool, shape (M,)
    """
    line_size = require_power_of_two("line_size", line_size)
    if placed.pages.frame.size:
        raise InputError("order_stream takes virtual addresses: give a layout without page placement")
    records, is_aux = pieces.records(trace_records)
    placed.check_records(records[~is_aux])
    start = np.empty(records.size, dtype=np.int64)
    size = np.empty(records.size, dtype=np.int64)
    scene = records[~is_aux]
    rows = placed.kind_first[(scene >> KIND_SHIFT).astype(np.int64)] + (scene & INDEX_MASK).astype(np.int64)
    start[~is_aux], size[~is_aux] = placed.record_start[rows], placed.record_size[rows]
    start[is_aux], size[is_aux] = buffers.extents(records[is_aux], process)
    first = start // line_size
    spans = (start + size - 1) // line_size - first + 1
    record = np.repeat(np.arange(records.size), spans)
    line = first[record] + np.arange(record.size) - np.repeat(np.cumsum(spans) - spans, spans)
    return (line * line_size).astype(np.uint64), (records[record] & np.uint32(WRITE_FLAG)) != 0


def replay_order(trace_records, pieces: OrderedPieces, placed: PlacedLayout, hierarchy: Hierarchy | CacheState, *,
                 buffers: OrderBuffers = OrderBuffers(), process: int = 0) -> SimulationResult:
    """Run the accesses of :func:`order_stream` through ``hierarchy`` (its smallest line size).

    A hierarchy starts empty; a CacheState continues (and is updated).
    """
    state = hierarchy if isinstance(hierarchy, CacheState) else CacheState(hierarchy)
    line_size = min(level.line_size for level in state.hierarchy.levels)
    addresses, writes = order_stream(trace_records, pieces, placed, line_size, buffers=buffers, process=process)
    return simulate(addresses, state, writes=writes)
