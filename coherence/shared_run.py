"""One run of a trace under a mapping on a machine with shared cache levels (the checked entry to :mod:`coherence.shared_schedule`).

>>> from coherence.shared_run import simulate_shared_run          # doctest: +SKIP
>>> run = simulate_shared_run(trace, distribution, platform.hierarchy, placed, platform.cost,
...                           Machine(n_cpus=platform.n_threads), interleave_cycles=1000)
>>> run.run.processes, run.shared.level_frame()                     # doctest: +SKIP

The rules of the schedule and of the interleaving are in
:mod:`coherence.shared_schedule`; those of the shared levels and their
coherence in :mod:`cachesim.multicore`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cachesim import multicore as MC
from cachesim.multicore_prefetch import pending_by_instance, thread_prefetchers
from cachesim.multicore_state import SharedResult, SharedState
from cachesim.prefetch import ISSUED, USEFUL
from cachesim.sharing import SharedHierarchy
from coherence.cost import CostModel
from coherence.distribution import Distribution
from coherence.layout import PlacedLayout
from coherence.recost import N_ACCESS_COLUMNS, READ_HITS, READ_MISSES, WRITE_HITS, WRITE_MISSES, MissCounts
from coherence.os_rules import (COMPUTE_CYCLES, DISPATCH_CYCLES, FINISH_CYCLES, FIRST_CPU, MEMORY_CYCLES, MIGRATIONS,
                                N_CYCLE_COLUMNS, N_PLACEMENT_COLUMNS)
from coherence.piece_words import PixelPieces, pack_pieces
from coherence.shared_schedule import SharedMachine, SharedOutputs, cpu_threads, run_shared_schedule
from coherence.simulation import Machine, PixelCost, Run, _counters_by_process, pixel_compute, schedule_of
from coherence.thread_streams import counter_address, record_places, split_records
from rtcommon.validate import InputError, require_number
from tracer.trace.records import AUXILIARY_KIND

__all__ = ["DEFAULT_INTERLEAVE_CYCLES", "PREFETCH_RUN_COLUMNS", "RECORDS", "SHARED_RUN_COLUMNS", "SharedLevels",
           "SharedRun", "TASK_COUNTER_COLUMNS", "pixel_pieces", "shared_run_row", "simulate_shared_run"]

#: ``Q`` of a run unless told otherwise: the cycles a hardware thread runs
#: before the thread whose clock is lowest takes over (see :mod:`coherence.shared_schedule`).
DEFAULT_INTERLEAVE_CYCLES = 1000

#: What :func:`simulate_shared_run` can also return, named in its ``record``.
RECORDS = ("log", "pixel_misses")

@dataclass(frozen=True)
class SharedLevels:
    """A study's caches when hardware threads share levels: the machine and how finely its threads interleave.

    Given as ``hierarchy`` to :func:`coherence.studies.study`, every run is
    simulated by :func:`simulate_shared_run`.

    Parameters
    ----------
    machine : SharedHierarchy
    interleave_cycles : float
        ``Q`` >= 1 (see :mod:`coherence.shared_schedule`).
    """

    machine: SharedHierarchy
    interleave_cycles: float = DEFAULT_INTERLEAVE_CYCLES

    def __post_init__(self):
        if not isinstance(self.machine, SharedHierarchy):
            raise InputError(f"SharedLevels.machine must be a SharedHierarchy, got {type(self.machine).__name__}")
        require_number("SharedLevels.interleave_cycles", self.interleave_cycles, 1)

    @property
    def hierarchy(self):
        """The levels one hardware thread sees (a :class:`cachesim.Hierarchy`: names, sizes, latencies)."""
        return self.machine.hierarchy

    def to_dict(self) -> dict:
        """The machine's table and Q (JSON-ready)."""
        return {"machine": self.machine.to_dict(), "interleave_cycles": float(self.interleave_cycles)}


#: Per level, the machine's counts a study's row of a run on shared levels gets, as ``<level>_<name>``
#: (``machine_misses``: all the level's instances' misses, background reads included).
SHARED_RUN_COLUMNS = (("machine_misses", MC.MISSES), ("coherence_invalidations", MC.COHERENCE_INVALIDATIONS),
                      ("coherence_misses", MC.COHERENCE_MISSES), ("false_sharing_misses", MC.FALSE_SHARING_MISSES))


#: Per level, a run's prefetch counts (:attr:`SharedResult.prefetch_counts` columns), as ``<level>_<name>``; a
#: row has them only when the machine has prefetchers (0 at its levels without one).
PREFETCH_RUN_COLUMNS = (("prefetches_issued", 0), ("prefetches_useful", 1), ("prefetches_useless", 2))


#: A run's task counter traffic (accesses of the auxiliary record kind: a dynamic mapping's hand-outs, see
#: :mod:`coherence.shared_schedule`; ray-order runs' buffers are of that kind too): its accesses at the first
#: level (one per task handed out), and its coherence invalidations and coherence misses summed over the levels.
TASK_COUNTER_COLUMNS = (("task_counter_accesses", MC.ACCESSES),
                        ("task_counter_invalidations", MC.COHERENCE_INVALIDATIONS),
                        ("task_counter_coherence_misses", MC.COHERENCE_MISSES))


def shared_run_row(shared: SharedResult) -> dict:
    """``<level>_machine_misses``, ``_coherence_invalidations``, ``_coherence_misses`` and
    ``_false_sharing_misses`` of a run, summed over the level's instances and record kinds; on a machine with
    prefetchers also ``<level>_prefetches_issued``, ``_useful`` and ``_useless`` (:data:`PREFETCH_RUN_COLUMNS`),
    summed over the level's instances; and the task counter's traffic (:data:`TASK_COUNTER_COLUMNS`; 0 under a
    static mapping)."""
    totals = shared.level_counts()
    names = shared.machine.hierarchy.level_names
    row = {f"{name}_{column}": int(totals[level, index])
           for level, name in enumerate(names) for column, index in SHARED_RUN_COLUMNS}
    counter = shared.counts[:, :, AUXILIARY_KIND].sum(axis=1)  # (L, counters)
    row.update({column: int(counter[0, index] if column == "task_counter_accesses" else counter[:, index].sum())
                for column, index in TASK_COUNTER_COLUMNS})
    if shared.prefetch_counts is not None:
        prefetched = shared.prefetch_counts.sum(axis=1)
        row.update({f"{name}_{column}": int(prefetched[level, index])
                    for level, name in enumerate(names) for column, index in PREFETCH_RUN_COLUMNS})
    return row


@dataclass(frozen=True)
class SharedRun:
    """A run on shared levels: the run as :func:`coherence.simulation.simulate_run` gives it, and the machine's counts.

    Attributes
    ----------
    run : coherence.simulation.Run
        Per process: the same columns as a private-cache run (hits and
        misses per level are the process's accesses, wherever they were
        served; ``cpu`` is the scheduler's CPU, hardware thread
        ``coherence.shared_schedule.cpu_threads(n_cores, smt)[cpu]``).
    shared : cachesim.multicore_state.SharedResult
        Counts per level, instance and record kind of the machine's
        instances (background reads included, as kind 0), with coherence
        invalidations, coherence misses and false-sharing misses.
    log : (ndarray, ndarray, ndarray) or None
        With ``"log"`` in ``record``: address, hardware thread and piece index
        (:data:`coherence.shared_schedule.COUNTER_ACCESS`: a hand-out's access of
        the task counter) of every access in the order the machine served it.
    """

    run: Run
    shared: SharedResult
    log: tuple | None = None


def pixel_pieces(trace, placed: PlacedLayout, line_size: int) -> PixelPieces:
    """Every pixel's accesses: one per line of ``line_size`` bytes a record spans, with its bytes, kind and flags.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    placed : PlacedLayout
        Where the records live (virtual addresses: no page placement).
    line_size : int
        The first level's line size.

    Returns
    -------
    PixelPieces
        Private kinds at their layout address (``private`` True), to be
        moved to a process's copy as it makes them.
    """
    offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    records = np.asarray(trace.records)
    places = record_places(records, placed, line_size)
    # each pixel split as by thread -1: private kinds at their layout address
    stream, counts, _ = split_records(records, offsets, np.full(offsets.shape[0] - 1, -1, dtype=np.int64), places)
    piece_offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return pack_pieces(piece_offsets, stream.addresses, stream.sizes, stream.kinds, stream.writes,
                       places.private_kind[stream.kinds], int(places.span))


def simulate_shared_run(trace, distribution: Distribution, hierarchy: SharedHierarchy, placed: PlacedLayout,
                        cost: CostModel, machine: Machine, *, interleave_cycles: float = DEFAULT_INTERLEAVE_CYCLES,
                        compute: np.ndarray | None = None, pieces: PixelPieces | None = None,
                        record: tuple = ()) -> SharedRun:
    """Simulate one distribution of a trace on the hardware threads of a shared hierarchy.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    distribution : Distribution
    hierarchy : SharedHierarchy
        Levels, latencies and which hardware threads share each level; one
        CPU of the schedule is one hardware thread.
    placed : PlacedLayout
        Record addresses (no page placement: the machine's must be ``contiguous``).
    cost : CostModel
    machine : Machine
        ``n_cpus`` must equal the hierarchy's hardware threads; scheduler,
        time slice, switch cycles and background load as in
        :func:`coherence.simulation.simulate_run`.
    interleave_cycles : float
        ``Q`` >= 1 (see :mod:`coherence.shared_schedule`).
    compute : ndarray of float64, shape (P,), optional
        Compute cycles per pixel (saves time over many runs).
    pieces : PixelPieces, optional
        :func:`pixel_pieces` of this trace, layout and first-level line size (saves time over many runs).
    record : tuple of str
        What else to return (:data:`RECORDS`): ``"log"``, the order the machine served the accesses in
        (``SharedRun.log``; for tests, memory per access); ``"pixel_misses"``, each pixel's misses per level
        on the shared levels (``run.pixel_misses``, (H, W, L): the misses of the pixel's own accesses, made by
        the thread that replayed them; the task counter's accesses belong to no pixel).

    Returns
    -------
    SharedRun
    """
    from tracer.trace.access import COUNTER_NAMES

    if not isinstance(hierarchy, SharedHierarchy):
        raise InputError(f"simulate_shared_run needs a SharedHierarchy, got {type(hierarchy).__name__}")
    levels = hierarchy.hierarchy.levels
    if machine.n_cpus != hierarchy.n_threads:
        raise InputError(f"Machine.n_cpus is {machine.n_cpus}; on shared hierarchy {hierarchy.name!r} it must be its "
                         f"{hierarchy.n_threads} hardware threads")
    if machine.page_placement.translates:
        raise InputError(f"page placement {machine.page_placement!r}: runs on shared levels take virtual "
                         "addresses; use contiguous")
    if (distribution.width, distribution.height) != (trace.width, trace.height):
        raise InputError(f"distribution is for {distribution.width}x{distribution.height} pixels, "
                         f"the trace for {trace.width}x{trace.height}")
    q = require_number("interleave_cycles", interleave_cycles, 1)
    if isinstance(record, str) or not isinstance(record, (tuple, list)) or not set(record) <= set(RECORDS):
        raise InputError(f"record must be a tuple of {', '.join(map(repr, RECORDS))}, got {record!r}")
    log, pixel_misses = "log" in record, "pixel_misses" in record
    n_pixels = trace.width * trace.height
    counters = np.asarray(trace.counters)
    compute = pixel_compute(trace, cost, compute, COUNTER_NAMES)
    line_size = levels[0].line_size
    if pieces is None:
        pieces = pixel_pieces(trace, placed, line_size)
    elif pieces.piece_offsets.shape != (n_pixels + 1,):
        raise InputError(f"pieces are for {pieces.piece_offsets.shape[0] - 1} pixels; this run needs {n_pixels}")

    n_processes = distribution.n_processes
    queues = machine.run_queues(n_processes)
    state = SharedState(hierarchy)
    n_levels = len(levels)
    latency = np.array([level.latency for level in levels] + [hierarchy.hierarchy.memory_latency], dtype=np.float64)
    out_cycles = np.zeros((n_processes, N_CYCLE_COLUMNS), dtype=np.float64)
    out_placement = np.zeros((n_processes, N_PLACEMENT_COLUMNS), dtype=np.int64)
    out_placement[:, FIRST_CPU] = -1
    task_owner = np.full(distribution.n_tasks, -1, dtype=np.int64)
    accesses = np.zeros((n_processes, n_levels, N_ACCESS_COLUMNS), dtype=np.int64)
    line_shift = line_size.bit_length() - 1
    background = machine.background(line_shift)
    n_logged = _log_room(pieces, machine, log, distribution)
    out = SharedOutputs(out_cycles, out_placement, task_owner, accesses,
                        np.zeros(n_logged, dtype=np.uint64), np.zeros(n_logged, dtype=np.int64),
                        np.zeros(n_logged, dtype=np.int64), np.zeros(1, dtype=np.int64),
                        np.zeros((n_pixels if pixel_misses else 0, n_levels), dtype=np.int64))
    state.clock = int(run_shared_schedule(
        pieces, SharedMachine(state.geometry, state.machine_geometry, state.arrays, line_shift,
                              cpu_threads(hierarchy.n_cores, hierarchy.smt), counter_address(placed)),
        PixelCost(compute, latency),
        schedule_of(distribution),
        queues, background, out, float(q), thread_prefetchers(state)))
    state.counts[..., MC.ACCESSES] = state.counts[..., MC.HITS] + state.counts[..., MC.MISSES]
    state.counts[..., MC.WRITES] = state.counts[..., MC.WRITE_HITS] + state.counts[..., MC.WRITE_MISSES]
    if not distribution.dynamic:
        task_owner[:] = distribution.task_process
    run = _run(trace, distribution, hierarchy, cost, machine, counters, out)
    shared = SharedResult(hierarchy, state.counts.copy(), state.served.copy(), True, state,
                          *_prefetch_counts(state))
    logged = None
    if log:
        length = int(out.log_length[0])
        logged = (out.log_addresses[:length], out.log_threads[:length], out.log_pieces[:length])
    return SharedRun(run, shared, logged)


def _prefetch_counts(state: SharedState) -> tuple:
    """``(prefetch_counts, prefetch_pending)`` of a run's :class:`SharedResult` (None, None without prefetchers):
    per level and instance the prefetches issued, useful and useless (issued - useful - pending), and those
    still pending."""
    if state.prefetch is None:
        return None, None
    counts = state.prefetch.counts
    pending = pending_by_instance(state.prefetch, state.tags, state.geometry, state.machine_geometry)
    useless = counts[..., ISSUED] - counts[..., USEFUL] - pending
    return np.concatenate([counts, useless[..., None]], axis=-1), pending


def _log_room(pieces: PixelPieces, machine: Machine, log: bool, distribution: Distribution) -> int:
    """Entries the access log needs: every piece once, plus a dynamic mapping's hand-outs (0 without a log)."""
    if not log:
        return 0
    if machine.background_load:
        raise InputError("simulate_shared_run: record=('log',) is for runs without a background load")
    return int(pieces.words.shape[0]) + (distribution.n_tasks if distribution.dynamic else 0)


def _run(trace, distribution, hierarchy: SharedHierarchy, cost: CostModel, machine: Machine, counters,
         out: SharedOutputs) -> Run:
    """The run's per-process table, as :func:`coherence.simulation.simulate_run` lays it out."""
    from tracer.trace.access import COUNTER_NAMES

    n_processes = distribution.n_processes
    n_pixels = trace.width * trace.height
    task_owner = out.task_owner
    pixel_owner = np.empty(n_pixels, dtype=np.int64)
    pixel_owner[distribution.task_pixels] = np.repeat(task_owner, np.diff(distribution.task_offsets))
    frame = {
        "process": np.arange(n_processes, dtype=np.int64),
        "cpu": out.placement[:, FIRST_CPU],
        "migrations": out.placement[:, MIGRATIONS],
        "tasks": np.bincount(task_owner, minlength=n_processes).astype(np.int64),
        "pixels": np.bincount(pixel_owner, minlength=n_processes).astype(np.int64),
    }
    by_process = _counters_by_process(counters, pixel_owner, n_processes)
    for column, name in enumerate(COUNTER_NAMES):
        frame[name] = by_process[:, column]
    accesses = out.accesses
    hits = accesses[:, :, READ_HITS] + accesses[:, :, WRITE_HITS]
    misses = accesses[:, :, READ_MISSES] + accesses[:, :, WRITE_MISSES]
    for index, name in enumerate(hierarchy.hierarchy.level_names):
        frame[f"{name}_accesses"] = hits[:, index] + misses[:, index]
        frame[f"{name}_hits"] = hits[:, index]
        frame[f"{name}_misses"] = misses[:, index]
    frame["memory_accesses"] = misses[:, -1]
    cycles = out.cycles
    frame["compute_cycles"] = cycles[:, COMPUTE_CYCLES]
    frame["memory_cycles"] = cycles[:, MEMORY_CYCLES]
    frame["dispatch_cycles"] = cycles[:, DISPATCH_CYCLES]
    frame["user_cycles"] = cycles[:, COMPUTE_CYCLES] + cycles[:, MEMORY_CYCLES] + cycles[:, DISPATCH_CYCLES]
    frame["user_seconds"] = frame["user_cycles"] / cost.clock_hz
    frame["finish_cycles"] = cycles[:, FINISH_CYCLES]
    # Never re-costable: which thread's turn comes next, and so what the shared levels hold, follows the clocks.
    miss_counts = MissCounts(accesses.copy(), np.zeros(n_processes, np.int64), by_process, tuple(COUNTER_NAMES),
                             False)
    per_pixel = out.pixel_misses.reshape(trace.height, trace.width, -1) if out.pixel_misses.shape[0] else None
    return Run(pd.DataFrame(frame), task_owner, float(cycles[:, FINISH_CYCLES].max()), per_pixel, miss_counts)
