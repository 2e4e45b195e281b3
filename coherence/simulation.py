"""Replaying a pixel-access trace under a work distribution on a simulated machine.

- Each process renders tasks (ordered pixel lists). A static distribution
  gives every process its own tasks; a dynamic one (DB) hands the next task
  of a global queue to whichever process asks first, each hand-out costing
  ``dispatch_cycles`` of waiting (unless a take-ahead task is already held).
- A pixel's records become byte addresses through the placed memory layout
  (every smallest-level line a record spans), run through the caches of the
  CPU the process runs on; its time is its compute cycles (cost model) plus
  the latency of the level that served each read (memory latency for the
  last level's misses). Written records (the write flag of
  :mod:`tracer.trace.records`: the study-era tracer's ray stack, hit records and
  frame buffer) are writes to the caches, which allocate them as the
  hierarchy says; a write costs the first level's latency, as a store
  retired into the 21164's write buffer does. A hierarchy with a data TLB
  gives each CPU one: every access is looked up in it, and each miss costs
  the TLB's fixed ``miss_cycles`` on top of the memory cycles.
- The machine's operating system (:class:`Machine`, :mod:`coherence.scheduler`)
  decides which process runs on which CPU when: one run queue shared by all
  CPUs (processes move between CPUs at the end of time slices, and find the
  caches their new CPU's previous processes left), or static placement (a
  process never moves). Other users' processes sit in the same run queues,
  take CPU time and disturb the caches.

User time and real time come from that one schedule: a process's user time is
the cycles it ran, real time is when the last of our processes finished.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd
from numba import njit

from cachesim import CacheState, Hierarchy
from cachesim import kernels as K
from cachesim import tlb as T
from cachesim.fresh import skips_exactly
from coherence.cost import CostModel
from coherence.distribution import Distribution
from coherence.layout import PlacedLayout, RecordPlacement
from coherence.page_placement import PagePlacement
from coherence.pixel_lines import PixelLines, no_pixel_lines, skip_key, skips_certain_hits
from coherence.recost import (N_ACCESS_COLUMNS, READ_HITS, READ_MISSES, WRITE_HITS, WRITE_MISSES, MissCounts,
                              fixed_schedule)
from coherence.os_rules import (COMPUTE_CYCLES, DISPATCH_CYCLES, FINISH_CYCLES, FIRST_CPU, MEMORY_CYCLES, MIGRATIONS,
                                N_CYCLE_COLUMNS, N_PLACEMENT_COLUMNS, BackgroundLoad, RunQueues)
from coherence.scheduler import CpuTlbs, RunOutputs, run_schedule
from rtcommon.validate import InputError, require_bool, require_int, require_number

SCHEDULERS = ("shared-queue", "static")
PLACEMENTS = ("round-robin", "neighbours")

#: CPUs of the study's AlphaServer 8400, and of a :class:`Machine` unless told otherwise.
STUDY_CPUS = 8

#: Bytes one background slice reads by default (see :class:`Machine`).
DEFAULT_BACKGROUND_FOOTPRINT = 1 << 20

# Background processes' address regions: far above any memory layout's
# (MemoryLayout.base < 2**48), one 2**48-byte region each, the stream's
# start placed at a seeded offset in its first 2**40 bytes.
BACKGROUND_BASE = 1 << 56
BACKGROUND_SPACING = 1 << 48
BACKGROUND_OFFSET_RANGE = 1 << 40


@dataclass(frozen=True)
class Machine:
    """The simulated multiprocessor and its operating system.

    Parameters
    ----------
    n_cpus : int
        CPUs, each with a private cache hierarchy.
    quantum_cycles : float
        Time slice: at its end a process gives its CPU to a waiting one, if
        any (``0``: a process runs until it finishes; needs no background).
    scheduler : {"shared-queue", "static"}
        ``shared-queue`` (default): one run queue for all CPUs, as a
        time-sharing Unix of the study's era kept; a process runs on whichever
        CPU is free when its turn comes, and its cache contents stay behind
        on the CPU it left. ``static``: every process is pinned to one CPU
        (``placement``) and CPUs share nothing.
    placement : {"round-robin", "neighbours"}
        Static scheduler only: process ``p`` goes to CPU ``p % n_cpus``
        (round robin) or processes ``p`` and ``p + 1`` share a CPU
        (``p // ceil(n / n_cpus)``). Background process ``b`` goes to CPU
        ``(n + b) % n_cpus``, after ours.
    background_load : int
        Always-runnable processes of other users, in the same run queue(s)
        as ours: they take CPU time in whole slices and read
        ``background_footprint`` bytes per slice through the CPU's caches.
    background_footprint : int
        Distinct bytes a background process reads in one slice, as a stream
        of lines in its own address region, continuing where its previous
        slice stopped (so it never finds its own data warm either). Default
        1 MiB, fixed by reasoning before any result was seen: another user's
        job of the time (a compile, a numerical code) streaming about
        100 MB/s reads about 1 MB in a 10 ms slice. That is over ten times
        the 96 KB S-cache, so a background slice leaves nothing of ours in
        the D- and S-cache, and a quarter of the 4 MB B-cache, so ours keeps
        most of its B-cache contents. The B-cache share is the uncertain
        part; change it here.
    background_seed : int
        Seed of each background stream's start address (which cache sets it
        begins on).
    switch_cycles : float
        Cycles a CPU spends starting a process other than its last one.
    page_placement : PagePlacement
        Which physical frames the operating system gives the scene's pages
        (:mod:`coherence.page_placement`); default ``contiguous``, physical =
        virtual. Under ``random`` other users' stream pages get hashed
        colours too (:func:`coherence.page_placement.translate_stream`).
    """

    n_cpus: int = STUDY_CPUS
    quantum_cycles: float = 3e6
    scheduler: str = "shared-queue"
    placement: str = "round-robin"
    background_load: int = 0
    background_footprint: int = DEFAULT_BACKGROUND_FOOTPRINT
    background_seed: int = 0
    switch_cycles: float = 0.0
    page_placement: PagePlacement = PagePlacement()

    def __post_init__(self):
        if not isinstance(self.page_placement, PagePlacement):
            raise InputError(f"Machine.page_placement must be a PagePlacement, "
                             f"got {type(self.page_placement).__name__}")
        require_int("Machine.n_cpus", self.n_cpus, 1)
        for name in ("quantum_cycles", "switch_cycles"):
            require_number(f"Machine.{name}", getattr(self, name), 0)
        if self.scheduler not in SCHEDULERS:
            raise InputError(f"Machine.scheduler must be one of {SCHEDULERS}, got {self.scheduler!r}")
        if self.placement not in PLACEMENTS:
            raise InputError(f"Machine.placement must be one of {PLACEMENTS}, got {self.placement!r}")
        if self.scheduler != "static" and self.placement != PLACEMENTS[0]:
            raise InputError(f"Machine.placement={self.placement!r} applies to scheduler='static' only "
                             f"(the {self.scheduler} scheduler moves processes between CPUs)")
        require_int("Machine.background_load", self.background_load, 0)
        require_int("Machine.background_footprint", self.background_footprint, 0)
        require_int("Machine.background_seed", self.background_seed, 0)
        if self.background_load > 0 and self.quantum_cycles == 0:
            raise InputError("Machine.quantum_cycles must be > 0 with a background load: a background "
                             "process never finishes, so without time slices ours would never run")

    def cpu_of(self, n_processes: int) -> np.ndarray:
        """Static scheduler: CPU of each of our processes, int64 (n_processes,)."""
        processes = np.arange(n_processes, dtype=np.int64)
        if self.placement == "round-robin":
            return processes % self.n_cpus
        per_cpu = -(-n_processes // self.n_cpus)
        return processes // per_cpu

    def run_queues(self, n_processes: int) -> RunQueues:
        """The run queues of ``n_processes`` of ours and the background load.

        Processes ``0 .. n-1`` are ours, ``n .. n+B-1`` the background's. At
        time 0 the background processes enter their queues first (they were
        running before our run started), then ours in process order.
        """
        n_background = self.background_load
        if self.scheduler == "static":
            background_cpu = (n_processes + np.arange(n_background, dtype=np.int64)) % self.n_cpus
            process_queue = np.concatenate((self.cpu_of(n_processes), background_cpu)).astype(np.int64)
            n_queues = int(process_queue.max()) + 1
        else:
            process_queue = np.zeros(n_processes + n_background, dtype=np.int64)
            n_queues = 1
        start_order = np.concatenate((np.arange(n_processes, n_processes + n_background),
                                      np.arange(n_processes))).astype(np.int64)
        return RunQueues(process_queue, start_order, n_queues, float(self.quantum_cycles),
                         float(self.switch_cycles))

    def background(self, line_shift: int) -> BackgroundLoad:
        """Where each background process's stream starts, in lines of ``2**line_shift`` bytes."""
        rng = np.random.default_rng(self.background_seed)
        offsets = rng.integers(0, BACKGROUND_OFFSET_RANGE >> line_shift, self.background_load, dtype=np.int64)
        bases = (BACKGROUND_BASE + BACKGROUND_SPACING * np.arange(self.background_load, dtype=np.int64)) >> line_shift
        footprint_lines = -(-int(self.background_footprint) // (1 << line_shift))
        return BackgroundLoad((bases + offsets).astype(np.int64), footprint_lines)


class PixelReads(NamedTuple):
    """What every pixel reads, and where it lives in memory.

    Attributes
    ----------
    pixel_offsets : ndarray of int64, shape (P + 1,)
        Pixel ``p`` reads ``records[pixel_offsets[p]:pixel_offsets[p + 1]]``.
    records : ndarray of uint32, shape (N,)
        Packed (kind, index) records of the trace.
    placement : RecordPlacement
        Address and size of every record.
    line_shift : int
        log2 of the hierarchy's smallest line size: a record read becomes one
        access per line of that size it spans.
    lines : coherence.pixel_lines.PixelLines
        The same accesses worked out in advance, read instead of converting
        each pixel's records when not empty.
    """

    pixel_offsets: np.ndarray
    records: np.ndarray
    placement: RecordPlacement
    line_shift: int
    lines: PixelLines


class PixelCost(NamedTuple):
    """Cycles of a pixel: its compute, plus a latency per access.

    Attributes
    ----------
    compute : ndarray of float64, shape (P,)
        Compute cycles of each pixel (cost model).
    latency : ndarray of float64, shape (L + 1,)
        Cycles of an access served by each level; the last entry is memory.
    """

    compute: np.ndarray
    latency: np.ndarray


class Schedule(NamedTuple):
    """The tasks and how they are handed to processes.

    Attributes
    ----------
    task_offsets : ndarray of int64, shape (T + 1,)
        Task ``t`` is ``task_pixels[task_offsets[t]:task_offsets[t + 1]]``.
    task_pixels : ndarray of int64, shape (P,)
    own_offsets : ndarray of int64, shape (n + 1,)
        Static: process ``p`` renders ``own_tasks[own_offsets[p]:own_offsets[p + 1]]``
        in order (all zero when dynamic).
    own_tasks : ndarray of int64, shape (T,), or (0,) when dynamic
    dynamic : bool
        Tasks go, in order, to whichever process asks first.
    dispatch_cycles : float
        Waiting cycles of one dynamic hand-out.
    take_ahead : int
        Tasks a dynamic process takes beyond the one it renders.
    """

    task_offsets: np.ndarray
    task_pixels: np.ndarray
    own_offsets: np.ndarray
    own_tasks: np.ndarray
    dynamic: bool
    dispatch_cycles: float
    take_ahead: int


def schedule_of(distribution: Distribution) -> Schedule:
    """The kernels' view of a distribution's tasks: static processes' own tasks in order, or the hand-out rules."""
    n_processes = distribution.n_processes
    if distribution.dynamic:
        own_offsets = np.zeros(n_processes + 1, dtype=np.int64)
        own_tasks = np.zeros(0, dtype=np.int64)
    else:
        owner = np.asarray(distribution.task_process, dtype=np.int64)
        own_tasks = np.argsort(owner, kind="stable").astype(np.int64)
        own_offsets = np.searchsorted(owner[own_tasks], np.arange(n_processes + 1)).astype(np.int64)
    return Schedule(distribution.task_offsets, distribution.task_pixels, own_offsets, own_tasks,
                    distribution.dynamic, float(distribution.dispatch_cycles), int(distribution.take_ahead))


@dataclass(frozen=True)
class Run:
    """Result of one simulated run.

    Attributes
    ----------
    processes : DataFrame
        One row per process (see :func:`simulate_run`).
    task_owner : ndarray of int64, shape (T,)
        Process that rendered each task.
    real_cycles : float
        Wall time of the run: when the last of our processes finished.
    pixel_misses : ndarray of int64, shape (H, W, L), or None
        Misses of each pixel (row ``y``, column ``x``) at each cache level,
        in ``hierarchy.levels`` order, reads and writes, on the caches of
        the CPU its process rendered it on; None unless asked for
        (``simulate_run(..., pixel_misses=True)``). Summed over the pixels
        a process rendered, level ``l`` gives its ``<level>_misses``.
    miss_counts : coherence.recost.MissCounts or None
        Per process, the counts its cycles are made of (read and write hits
        and misses per level, TLB misses, the trace's counters) and whether
        they do not depend on cycles: what :func:`coherence.recost.recost_run`
        needs to re-cost the run without replaying it.
    """

    processes: pd.DataFrame
    task_owner: np.ndarray
    real_cycles: float
    pixel_misses: np.ndarray | None = None
    miss_counts: MissCounts | None = None


def simulate_run(trace, distribution: Distribution, hierarchy: Hierarchy, placed: PlacedLayout,
                 cost: CostModel, machine: Machine = Machine(), *, counter_names=None,
                 compute: np.ndarray | None = None, lines: PixelLines | None = None,
                 pixel_misses: bool = False) -> Run:
    """Simulate one distribution of a trace on a machine.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Per-pixel access logs (``pixel_offsets`` (P + 1,), ``records`` (N,),
        ``counters`` (P, K)).
    distribution : Distribution
        Tasks and their assignment for ``trace.width`` x ``trace.height``.
    hierarchy : Hierarchy
        Cache hierarchy of every CPU (latencies included).
    placed : PlacedLayout
        Record addresses (see :meth:`MemoryLayout.place`); placed in physical
        memory by ``machine.page_placement`` here unless already placed
        (:meth:`PlacedLayout.with_pages`).
    cost : CostModel
    machine : Machine
        CPUs, scheduler, time slice and background load.
    counter_names : sequence of str, optional
        Names of the trace's counter columns (default: the tracer's).
    compute : ndarray of float64, shape (P,), optional
        Precomputed compute cycles per pixel (saves time over many runs).
    lines : coherence.pixel_lines.PixelLines, optional
        Every pixel's line accesses from :func:`~coherence.pixel_lines.pixel_lines`
        for this trace, ``placed`` (with its pages placed, when the machine
        places pages) and the hierarchy's smallest line size, with or without
        this hierarchy's certain first-level hits taken out (saves time over
        many runs; the results are the same).
    pixel_misses : bool
        Also return each pixel's misses per cache level (``Run.pixel_misses``,
        shape (H, W, L); 8 bytes per pixel and level).

    Returns
    -------
    Run
        ``processes`` columns: process, cpu, migrations, tasks, pixels, the trace's
        counters summed, ``<level>_accesses``/``_hits``/``_misses`` per level,
        (cpu is the CPU of its first slice, -1 if it never ran; migrations
        counts the slices it ran on another CPU than its previous one),
        memory_accesses, with a TLB tlb_accesses, tlb_misses and tlb_cycles
        (included in memory_cycles), then compute_cycles, memory_cycles,
        dispatch_cycles, user_cycles, user_seconds, finish_cycles.
    """
    if counter_names is None:
        from tracer.trace.access import COUNTER_NAMES as counter_names
    n_pixels = trace.width * trace.height
    if hierarchy.prefetches:
        raise InputError(f"hierarchy {hierarchy.name!r} has prefetchers, which the schedule simulation does not "
                         "model; cachesim.simulate runs them on an address stream")
    if (distribution.width, distribution.height) != (trace.width, trace.height):
        raise InputError(f"distribution is for {distribution.width}x{distribution.height} pixels, "
                         f"the trace for {trace.width}x{trace.height}")
    require_bool("pixel_misses", pixel_misses)
    counters = np.asarray(trace.counters)
    compute = pixel_compute(trace, cost, compute, counter_names)

    if machine.page_placement.translates and placed.pages.frame.shape[0] == 0:
        if lines is not None and lines.line_offsets.shape[0] > 0:
            raise InputError("lines hold virtual addresses but the machine places pages; make them from "
                             "placed.with_pages(machine.page_placement, hierarchy)")
        placed = placed.with_pages(machine.page_placement, hierarchy)
    n_processes = distribution.n_processes
    _warn_idle_processes(distribution)

    queues = machine.run_queues(n_processes)
    n_all = n_processes + machine.background_load
    n_cpus = queues.n_queues if machine.scheduler == "static" else min(machine.n_cpus, n_all)
    state = CacheState(hierarchy)
    n_levels = len(hierarchy.levels)
    # Caches per CPU, counters per process (ours, then the background's).
    caches = K.CacheArrays(np.tile(state.tags, (n_cpus, 1)), np.tile(state.stamps, (n_cpus, 1)),
                           np.zeros((n_all, n_levels, K.N_COUNTERS), dtype=np.int64))
    counts = caches.counts[:n_processes]
    latency = np.array([level.latency for level in hierarchy.levels] + [hierarchy.memory_latency],
                       dtype=np.float64)
    line_shift = min(level.line_size for level in hierarchy.levels).bit_length() - 1
    if lines is None:
        lines = no_pixel_lines(line_shift)
    elif lines.line_shift != line_shift or lines.line_offsets.shape != (n_pixels + 1,):
        raise InputError(f"lines are for {lines.line_offsets.shape[0] - 1} pixels of {1 << lines.line_shift}-byte "
                         f"lines; this run needs {n_pixels} pixels of {1 << line_shift}-byte lines")
    elif lines.skip_mask and (lines.skips_for != skip_key(hierarchy)
                              or not skips_certain_hits(hierarchy, 1 << line_shift)):
        raise InputError(f"lines had their certain first-level hits taken out for the hierarchy {lines.skips_for!r}; "
                         f"this run's is {skip_key(hierarchy)!r}: make them with pixel_lines(..., hierarchy=) of it")

    out_cycles = np.zeros((n_processes, N_CYCLE_COLUMNS), dtype=np.float64)
    out_placement = np.zeros((n_processes, N_PLACEMENT_COLUMNS), dtype=np.int64)
    out_placement[:, FIRST_CPU] = -1
    task_owner = np.full(distribution.n_tasks, -1, dtype=np.int64)
    tlbs = _cpu_tlbs(state, n_cpus, n_all)
    out_misses = np.zeros((n_pixels if pixel_misses else 0, n_levels), dtype=np.int64)
    run_schedule(PixelReads(np.asarray(trace.pixel_offsets, dtype=np.int64), np.asarray(trace.records),
                            placed.placement, line_shift, lines),
                 state.geometry, caches, tlbs, PixelCost(compute, latency),
                 schedule_of(distribution),
                 queues, _background(machine, line_shift, state, tlbs),
                 RunOutputs(out_cycles, out_placement, task_owner, out_misses))
    if not distribution.dynamic:
        task_owner[:] = distribution.task_process  # empty tasks after a process's last pixel included

    pixel_owner = np.empty(n_pixels, dtype=np.int64)
    task_sizes = np.diff(distribution.task_offsets)
    pixel_owner[distribution.task_pixels] = np.repeat(task_owner, task_sizes)
    frame = {
        "process": np.arange(n_processes, dtype=np.int64),
        "cpu": out_placement[:, FIRST_CPU],
        "migrations": out_placement[:, MIGRATIONS],
        "tasks": np.bincount(task_owner, minlength=n_processes).astype(np.int64),
        "pixels": np.bincount(pixel_owner, minlength=n_processes).astype(np.int64),
    }
    by_process = _counters_by_process(counters, pixel_owner, n_processes)
    for column, name in enumerate(counter_names):
        frame[name] = by_process[:, column]
    for index, level in enumerate(hierarchy.levels):
        frame[f"{level.name}_accesses"] = counts[:, index, K.ACCESSES]
        frame[f"{level.name}_hits"] = counts[:, index, K.HITS]
        frame[f"{level.name}_misses"] = counts[:, index, K.MISSES]
    frame["memory_accesses"] = counts[:, -1, K.MISSES]
    if tlbs.enabled:
        frame["tlb_accesses"] = tlbs.counts[:n_processes, T.TLB_ACCESSES]
        frame["tlb_misses"] = tlbs.counts[:n_processes, T.TLB_MISSES]
        frame["tlb_cycles"] = tlbs.counts[:n_processes, T.TLB_MISSES] * tlbs.miss_cycles
    frame["compute_cycles"] = out_cycles[:, COMPUTE_CYCLES]
    frame["memory_cycles"] = out_cycles[:, MEMORY_CYCLES]
    frame["dispatch_cycles"] = out_cycles[:, DISPATCH_CYCLES]
    frame["user_cycles"] = (out_cycles[:, COMPUTE_CYCLES] + out_cycles[:, MEMORY_CYCLES]
                            + out_cycles[:, DISPATCH_CYCLES])
    frame["user_seconds"] = frame["user_cycles"] / cost.clock_hz
    frame["finish_cycles"] = out_cycles[:, FINISH_CYCLES]
    processes = pd.DataFrame(frame)
    accesses = np.empty((n_processes, n_levels, N_ACCESS_COLUMNS), dtype=np.int64)
    accesses[:, :, READ_HITS] = counts[:, :, K.HITS] - counts[:, :, K.WRITE_HITS]
    accesses[:, :, READ_MISSES] = counts[:, :, K.MISSES] - counts[:, :, K.WRITE_MISSES]
    accesses[:, :, WRITE_HITS] = counts[:, :, K.WRITE_HITS]
    accesses[:, :, WRITE_MISSES] = counts[:, :, K.WRITE_MISSES]
    tlb_misses = tlbs.counts[:n_processes, T.TLB_MISSES].copy() if tlbs.enabled else np.zeros(n_processes, np.int64)
    miss_counts = MissCounts(accesses, tlb_misses, by_process, tuple(counter_names),
                             fixed_schedule(distribution, machine))
    return Run(processes, task_owner, float(out_cycles[:, FINISH_CYCLES].max()),
               out_misses.reshape(trace.height, trace.width, n_levels) if pixel_misses else None, miss_counts)


def pixel_compute(trace, cost: CostModel, compute, counter_names) -> np.ndarray:
    """Compute cycles per pixel, float64 shape (P,): ``compute`` as given and checked, or ``cost``'s cycles of
    the trace's counters (columns ``counter_names``) when it is None."""
    n_pixels = trace.width * trace.height
    if compute is None:
        compute = cost.compute_cycles(np.asarray(trace.counters), counter_names)
    compute = np.ascontiguousarray(compute, dtype=np.float64)
    if compute.shape != (n_pixels,):
        raise InputError(f"compute must have shape ({n_pixels},), got {compute.shape}")
    return compute


@njit(cache=True, nogil=True)
def _counters_by_process(counters, pixel_owner, n_processes):
    """Sum the trace's counter rows of each process's pixels.

    One pass over the rows, without the interpreter lock: a memory-mapped
    trace's counters are read once, in order (a column at a time would read
    every page once per counter).

    Parameters
    ----------
    counters : ndarray of int64, shape (P, K)
    pixel_owner : ndarray of int64, shape (P,)
        The process (0..n_processes-1) that traced each pixel.
    n_processes : int

    Returns
    -------
    ndarray of int64, shape (n_processes, K)
    """
    sums = np.zeros((n_processes, counters.shape[1]), np.int64)
    for pixel in range(counters.shape[0]):
        owner = pixel_owner[pixel]
        for column in range(counters.shape[1]):
            sums[owner, column] += counters[pixel, column]
    return sums


def _background(machine: Machine, line_shift: int, state: CacheState, tlbs: CpuTlbs) -> BackgroundLoad:
    """The machine's background load, its slices skipped rather than walked where that is exact
    (:mod:`cachesim.fresh`: the caches' state and our processes' counts are the same either way; a data
    TLB then looks each slice up as page runs, as exact)."""
    load = machine.background(line_shift)
    pages = machine.page_placement.background(machine.page_placement.colours(state.hierarchy))
    # a TLB looks the skipped lines up by pages (their page runs): its page size must hold a line
    tlb_fits = not tlbs.enabled or tlbs.geometry.page_shift >= line_shift
    skip = (machine.background_load > 0 and tlb_fits and line_shift == state.geometry.line_shift
            and pages.colour_bits < 0 and skips_exactly(state.geometry, load.footprint_lines))
    return BackgroundLoad(load.first_line, load.footprint_lines, bool(skip), pages)


def _cpu_tlbs(state: CacheState, n_cpus: int, n_all: int) -> CpuTlbs:
    """An empty data TLB per CPU and zero counters per process; a disabled placeholder without one."""
    geometry = state.tlb_geometry
    if geometry is None:
        none = np.zeros((n_cpus, 1), dtype=np.int64)
        return CpuTlbs(False, T.TlbGeometry(0, 1, T.NLU), none, none, np.zeros((n_cpus, T.N_CURSOR), np.int64),
                       np.zeros((n_all, T.N_TLB_COUNTERS), dtype=np.int64), 0.0)
    tlbs = T.empty_tlbs(n_cpus, geometry.entries)
    return CpuTlbs(True, geometry, tlbs.pages, tlbs.stamps, tlbs.cursor,
                   np.zeros((n_all, T.N_TLB_COUNTERS), dtype=np.int64), float(state.hierarchy.tlb.miss_cycles))


def _warn_idle_processes(distribution: Distribution) -> None:
    """Warn when some processes can get no pixels: a legal run (they count
    with zero user time) whose speed-up the user may misread."""
    n_processes = distribution.n_processes
    size = f"{distribution.width}x{distribution.height}"
    if distribution.dynamic:
        n_work = int(np.count_nonzero(distribution.task_lengths))
        if n_work < n_processes:
            warnings.warn(f"mapping {distribution.name}: {n_work} non-empty tasks for {n_processes} processes "
                          f"on a {size} image, so {n_processes - n_work} processes get no work and the "
                          f"speed-up cannot exceed {n_work}; use a larger image or smaller tasks",
                          stacklevel=3)
        return
    n_idle = int(np.count_nonzero(distribution.process_pixel_counts() == 0))
    if n_idle:
        warnings.warn(f"mapping {distribution.name}: {n_idle} of {n_processes} processes get no pixels "
                      f"of the {size} image; they count with zero user time", stacklevel=3)
