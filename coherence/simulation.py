"""Replaying a pixel-access trace under a work distribution on a simulated machine.

One compiled event loop serves every mapping:

- Each process renders tasks (ordered pixel lists). A static distribution
  gives every process its own tasks; a dynamic one (DB) hands the next task
  of a global queue to whichever process asks first, each hand-out costing
  ``dispatch_cycles`` of waiting (unless a take-ahead task is already held).
- Processes are placed on CPUs (:class:`Machine`); each CPU has its own
  cache hierarchy state, shared by the processes placed on it, which run
  round robin in time slices of ``quantum_cycles``.
- A pixel's reads become byte addresses through the placed memory layout
  (every smallest-level line a record spans), run through its CPU's caches;
  its time is its compute cycles (cost model) plus the latency of the level
  that served each access (memory latency for the last level's misses).
- The CPU whose clock is lowest always moves next, so dynamic hand-outs
  happen in time order.

Real (wall) time with other users' load follows processor sharing: with
``k`` of our processes still running and ``B`` always-runnable background
processes on ``C`` CPUs, each of ours progresses at ``min(1, C / (k + B))``
of a CPU (the OS gives every process, not every user, a share). Background
processes are not simulated in the caches.
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
from coherence.cost import CostModel
from coherence.layout import PlacedLayout, RecordPlacement, record_lines
from coherence.distribution import Distribution

PLACEMENTS = ("round-robin", "neighbours")

# Columns of the per-process cycle totals the event loop writes.
COMPUTE_CYCLES, MEMORY_CYCLES, DISPATCH_CYCLES, FINISH_CYCLES = 0, 1, 2, 3
N_CYCLE_COLUMNS = 4


@dataclass(frozen=True)
class Machine:
    """The simulated multiprocessor.

    Parameters
    ----------
    n_cpus : int
        CPUs, each with a private cache hierarchy.
    quantum_cycles : float
        Time slice when several processes share a CPU; ``0`` runs each to
        completion before the next starts.
    placement : {"round-robin", "neighbours"}
        Process ``p`` goes to CPU ``p % n_cpus`` (round robin) or processes
        ``p`` and ``p + 1`` share a CPU (``p // ceil(n / n_cpus)``).
    background_load : int
        Always-runnable processes of other users (for real time only).
    switch_cycles : float
        Cost of a context switch between two of our processes on a CPU.
    """

    n_cpus: int = 8
    quantum_cycles: float = 3e6
    placement: str = "round-robin"
    background_load: int = 0
    switch_cycles: float = 0.0

    def __post_init__(self):
        if isinstance(self.n_cpus, bool) or not isinstance(self.n_cpus, (int, np.integer)) or self.n_cpus < 1:
            raise ValueError(f"Machine.n_cpus must be an integer >= 1, got {self.n_cpus!r}")
        for name in ("quantum_cycles", "switch_cycles"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.number)) or not value >= 0 or not np.isfinite(value):
                raise ValueError(f"Machine.{name} must be a finite number >= 0, got {value!r}")
        if self.placement not in PLACEMENTS:
            raise ValueError(f"Machine.placement must be one of {PLACEMENTS}, got {self.placement!r}")
        if isinstance(self.background_load, bool) or not isinstance(self.background_load, (int, np.integer)) \
                or self.background_load < 0:
            raise ValueError(f"Machine.background_load must be an integer >= 0, got {self.background_load!r}")

    def cpu_of(self, n_processes: int) -> np.ndarray:
        """CPU of each process, int64 (n_processes,)."""
        processes = np.arange(n_processes, dtype=np.int64)
        if self.placement == "round-robin":
            return processes % self.n_cpus
        per_cpu = -(-n_processes // self.n_cpus)
        return processes // per_cpu


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
    """

    pixel_offsets: np.ndarray
    records: np.ndarray
    placement: RecordPlacement
    line_shift: int


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


class CpuSharing(NamedTuple):
    """Which processes share each CPU, and how.

    Attributes
    ----------
    cpu_processes : ndarray of int64, shape (n,)
        Processes grouped by CPU.
    cpu_offsets : ndarray of int64, shape (C + 1,)
        CPU ``c`` runs ``cpu_processes[cpu_offsets[c]:cpu_offsets[c + 1]]``.
    quantum : float
        Time slice in cycles (``0``: each runs to completion).
    switch_cycles : float
        Cost of switching between two of our processes.
    """

    cpu_processes: np.ndarray
    cpu_offsets: np.ndarray
    quantum: float
    switch_cycles: float


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
        Wall time of the run under the machine's background load.
    """

    processes: pd.DataFrame
    task_owner: np.ndarray
    real_cycles: float


def simulate_run(trace, distribution: Distribution, hierarchy: Hierarchy, placed: PlacedLayout,
                 cost: CostModel, machine: Machine = Machine(), *, counter_names=None,
                 compute: np.ndarray | None = None) -> Run:
    """Simulate one distribution of a trace on a machine.

    Parameters
    ----------
    trace : tracer.trace.AccessTrace
        Per-pixel access logs (``pixel_offsets`` (P + 1,), ``records`` (N,),
        ``counters`` (P, K)).
    distribution : Distribution
        Tasks and their assignment for ``trace.width`` x ``trace.height``.
    hierarchy : Hierarchy
        Cache hierarchy of every CPU (latencies included).
    placed : PlacedLayout
        Record addresses (see :meth:`MemoryLayout.place`).
    cost : CostModel
    machine : Machine
    counter_names : sequence of str, optional
        Names of the trace's counter columns (default: the tracer's).
    compute : ndarray of float64, shape (P,), optional
        Precomputed compute cycles per pixel (saves time over many runs).

    Returns
    -------
    Run
        ``processes`` columns: process, cpu, tasks, pixels, the trace's
        counters summed, ``<level>_accesses``/``_hits``/``_misses`` per level,
        memory_accesses, compute_cycles, memory_cycles, dispatch_cycles,
        user_cycles, user_seconds, finish_cycles.
    """
    if counter_names is None:
        from tracer.trace import COUNTER_NAMES as counter_names
    n_pixels = trace.width * trace.height
    if (distribution.width, distribution.height) != (trace.width, trace.height):
        raise ValueError(f"distribution is for {distribution.width}x{distribution.height} pixels, "
                         f"the trace for {trace.width}x{trace.height}")
    counters = np.asarray(trace.counters)
    if compute is None:
        compute = cost.compute_cycles(counters, counter_names)
    compute = np.ascontiguousarray(compute, dtype=np.float64)
    if compute.shape != (n_pixels,):
        raise ValueError(f"compute must have shape ({n_pixels},), got {compute.shape}")

    n_processes = distribution.n_processes
    _warn_idle_processes(distribution)
    cpu_of = machine.cpu_of(n_processes)
    n_cpus = int(min(machine.n_cpus, n_processes))
    order = np.argsort(cpu_of, kind="stable")
    cpu_offsets = np.searchsorted(cpu_of[order], np.arange(n_cpus + 1)).astype(np.int64)

    if distribution.dynamic:
        own_offsets = np.zeros(n_processes + 1, dtype=np.int64)
        own_tasks = np.zeros(0, dtype=np.int64)
    else:
        owner = np.asarray(distribution.task_process, dtype=np.int64)
        own_tasks = np.argsort(owner, kind="stable").astype(np.int64)
        own_offsets = np.searchsorted(owner[own_tasks], np.arange(n_processes + 1)).astype(np.int64)

    state = CacheState(hierarchy)
    n_levels = len(hierarchy.levels)
    # Caches per CPU, counters per process.
    caches = K.CacheArrays(np.tile(state.tags, (n_cpus, 1)), np.tile(state.stamps, (n_cpus, 1)),
                           np.zeros((n_processes, n_levels, K.N_COUNTERS), dtype=np.int64))
    counts = caches.counts
    latency = np.array([level.latency for level in hierarchy.levels] + [hierarchy.memory_latency],
                       dtype=np.float64)
    line_shift = min(level.line_size for level in hierarchy.levels).bit_length() - 1

    out_cycles = np.zeros((n_processes, N_CYCLE_COLUMNS), dtype=np.float64)
    task_owner = np.full(distribution.n_tasks, -1, dtype=np.int64)
    _run(PixelReads(np.asarray(trace.pixel_offsets, dtype=np.int64), np.asarray(trace.records),
                    placed.placement, line_shift),
         state.geometry, caches, PixelCost(compute, latency),
         Schedule(distribution.task_offsets, distribution.task_pixels, own_offsets, own_tasks,
                  distribution.dynamic, float(distribution.dispatch_cycles), int(distribution.take_ahead)),
         CpuSharing(order, cpu_offsets, float(machine.quantum_cycles), float(machine.switch_cycles)),
         out_cycles, task_owner)

    pixel_owner = np.empty(n_pixels, dtype=np.int64)
    task_sizes = np.diff(distribution.task_offsets)
    pixel_owner[distribution.task_pixels] = np.repeat(task_owner, task_sizes)
    frame = {
        "process": np.arange(n_processes, dtype=np.int64),
        "cpu": cpu_of,
        "tasks": np.bincount(task_owner, minlength=n_processes).astype(np.int64),
        "pixels": np.bincount(pixel_owner, minlength=n_processes).astype(np.int64),
    }
    for column, name in enumerate(counter_names):
        frame[name] = np.bincount(pixel_owner, weights=counters[:, column],
                                  minlength=n_processes).round().astype(np.int64)
    for index, level in enumerate(hierarchy.levels):
        frame[f"{level.name}_accesses"] = counts[:, index, K.ACCESSES]
        frame[f"{level.name}_hits"] = counts[:, index, K.HITS]
        frame[f"{level.name}_misses"] = counts[:, index, K.MISSES]
    frame["memory_accesses"] = counts[:, -1, K.MISSES]
    frame["compute_cycles"] = out_cycles[:, COMPUTE_CYCLES]
    frame["memory_cycles"] = out_cycles[:, MEMORY_CYCLES]
    frame["dispatch_cycles"] = out_cycles[:, DISPATCH_CYCLES]
    frame["user_cycles"] = (out_cycles[:, COMPUTE_CYCLES] + out_cycles[:, MEMORY_CYCLES]
                            + out_cycles[:, DISPATCH_CYCLES])
    frame["user_seconds"] = frame["user_cycles"] / cost.clock_hz
    frame["finish_cycles"] = out_cycles[:, FINISH_CYCLES]
    processes = pd.DataFrame(frame)
    real = processor_sharing_time(processes["user_cycles"].to_numpy(), machine.n_cpus, machine.background_load)
    return Run(processes, task_owner, real)


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


def processor_sharing_time(user_cycles, n_cpus: int, background_load: int) -> float:
    """Wall time of jobs of the given CPU times under processor sharing.

    With ``k`` jobs left and ``background_load`` endless jobs on ``n_cpus``
    CPUs, each job runs at ``min(1, n_cpus / (k + background_load))``.
    """
    remaining = np.sort(np.asarray(user_cycles, dtype=np.float64))
    wall = 0.0
    done = 0.0
    for index, finish in enumerate(remaining):
        active = remaining.size - index
        rate = min(1.0, n_cpus / (active + background_load))
        wall += (finish - done) / rate
        done = finish
    return wall


@njit(cache=True, nogil=True)
def _run(reads, geometry, caches, cost, schedule, cpus, out_cycles, task_owner):
    """The event loop (see the module docstring).

    Parameters
    ----------
    reads : PixelReads
    geometry : cachesim.kernels.CacheGeometry
    caches : cachesim.kernels.CacheArrays
        ``tags``/``stamps`` (C, W): one state per CPU; ``counts``
        (n, L, N_COUNTERS): counters per process. Updated in place.
    cost : PixelCost
    schedule : Schedule
    cpus : CpuSharing
    out_cycles : ndarray of float64, shape (n, N_CYCLE_COLUMNS)
        Receives compute, memory, dispatch and finish cycles per process.
    task_owner : ndarray of int64, shape (T,)
        Receives the process that rendered each task.
    """
    # Bundle fields are read once here: a read inside the per-pixel loop
    # would cost a reference-count update each time.
    counts = caches.counts
    tags = caches.tags
    stamps = caches.stamps
    records = reads.records
    pixel_offsets = reads.pixel_offsets
    placement = reads.placement
    line_shift = reads.line_shift
    compute = cost.compute
    latency = cost.latency
    task_offsets = schedule.task_offsets
    task_pixels = schedule.task_pixels
    own_offsets = schedule.own_offsets
    dynamic = schedule.dynamic
    cpu_processes = cpus.cpu_processes
    cpu_offsets = cpus.cpu_offsets
    quantum = cpus.quantum
    n_processes = counts.shape[0]
    n_cpus = cpu_offsets.shape[0] - 1
    n_levels = counts.shape[1]
    cpu_clock = np.zeros(n_cpus)
    cache_clock = np.zeros(n_cpus, dtype=np.int64)
    cpu_current = cpu_offsets[:n_cpus].copy()  # index into cpu_processes
    slice_used = np.zeros(n_cpus)
    cpu_live = cpu_offsets[1:] - cpu_offsets[:-1]
    done = np.zeros(n_processes, dtype=np.bool_)
    own_next = own_offsets[:n_processes].copy()
    # The task each process renders (-1: none) and where it is in it.
    current_task = np.full(n_processes, -1, dtype=np.int64)
    position = np.zeros(n_processes, dtype=np.int64)
    # Dynamic take-ahead: tasks held, a small ring per process; and the
    # global queue's next task (an array, so that _take_task can advance it).
    held = np.full((n_processes, max(schedule.take_ahead, 1)), -1, dtype=np.int64)
    held_count = np.zeros(n_processes, dtype=np.int64)
    next_task = np.zeros(1, dtype=np.int64)
    buffer = np.empty(4096, dtype=np.uint64)
    work = K.chunk_buffers()
    served = np.zeros(0, dtype=np.uint8)
    hits_before = np.zeros(n_levels, dtype=np.int64)
    while True:
        cpu = _lowest_clock_cpu(cpu_clock, cpu_live)
        if cpu < 0:
            break
        clock = cpu_clock[cpu]
        slot = cpu_current[cpu]
        process = cpu_processes[slot]
        if done[process] or (quantum > 0 and slice_used[cpu] >= quantum and cpu_live[cpu] > 1):
            slot = _next_live_slot(cpu_processes, cpu_offsets[cpu], cpu_offsets[cpu + 1], slot, done)
            if cpu_processes[slot] != process:
                clock += cpus.switch_cycles
            process = cpu_processes[slot]
            cpu_current[cpu] = slot
            slice_used[cpu] = 0.0
        cache = K.CacheArrays(tags[cpu], stamps[cpu], counts[process])
        process_counts = counts[process]
        while True:
            task = current_task[process]
            if task < 0 or position[process] == task_offsets[task + 1]:
                if task >= 0 and dynamic:
                    current_task[process] = -1
                    break  # back to the event loop: the next hand-out in time order
                task, waited = _take_task(process, schedule, own_next, held, held_count, next_task, task_owner)
                clock += waited
                out_cycles[process, DISPATCH_CYCLES] += waited
                slice_used[cpu] += waited
                if task < 0:
                    _retire(process, cpu, clock, done, cpu_live, out_cycles)
                    break
                task_owner[task] = process
                current_task[process] = task
                position[process] = task_offsets[task]
                continue  # the task may be empty (more processes than rows or pixels)
            pixel = task_pixels[position[process]]
            position[process] += 1
            buffer, n_addresses = record_lines(records, pixel_offsets[pixel], pixel_offsets[pixel + 1],
                                               placement, line_shift, buffer)
            for level in range(n_levels):
                hits_before[level] = process_counts[level, K.HITS]
            misses_before = process_counts[n_levels - 1, K.MISSES]
            cache_clock[cpu] = K.simulate_into(buffer[:n_addresses], geometry, cache, cache_clock[cpu],
                                               served, False, work)
            memory = _memory_cycles(process_counts, hits_before, misses_before, latency)
            cycles = compute[pixel] + memory
            out_cycles[process, COMPUTE_CYCLES] += compute[pixel]
            out_cycles[process, MEMORY_CYCLES] += memory
            clock += cycles
            slice_used[cpu] += cycles
            if (not dynamic and position[process] == task_offsets[task + 1]
                    and own_next[process] == own_offsets[process + 1]):
                # A static process is done with its last pixel, not when it
                # next gets the CPU.
                _retire(process, cpu, clock, done, cpu_live, out_cycles)
                break
            if quantum > 0 and slice_used[cpu] >= quantum and cpu_live[cpu] > 1:
                break
        cpu_clock[cpu] = clock


@njit(cache=True, inline="always")
def _lowest_clock_cpu(cpu_clock, cpu_live):
    """The CPU with live processes whose clock is lowest (-1: all done)."""
    cpu = -1
    for c in range(cpu_clock.shape[0]):
        if cpu_live[c] > 0 and (cpu < 0 or cpu_clock[c] < cpu_clock[cpu]):
            cpu = c
    return cpu


@njit(cache=True, inline="always")
def _next_live_slot(cpu_processes, first, stop, slot, done):
    """Round robin: the slot of the next live process of a CPU after ``slot``."""
    count = stop - first
    for step in range(1, count + 1):
        candidate = first + (slot - first + step) % count
        if not done[cpu_processes[candidate]]:
            break
    return candidate


@njit(cache=True, inline="always")
def _retire(process, cpu, clock, done, cpu_live, out_cycles):
    """``process`` has no work left: it finished at ``clock``."""
    done[process] = True
    cpu_live[cpu] -= 1
    out_cycles[process, FINISH_CYCLES] = clock


@njit(cache=True, nogil=True)
def _take_task(process, schedule, own_next, held, held_count, next_task, task_owner):
    """The next task of ``process`` (-1: none left) and the cycles it waited for it.

    Static: the process's next own task (``own_next`` advances). Dynamic: a
    held take-ahead task, else a hand-out from the global queue
    (``next_task[0]`` advances; costs ``dispatch_cycles``); then the
    take-ahead is refilled from the queue, its tasks owned at once.
    """
    task = -1
    waited = 0.0
    if schedule.dynamic:
        n_tasks = schedule.task_offsets.shape[0] - 1
        if held_count[process] > 0:
            task = held[process, 0]
            for h in range(held_count[process] - 1):
                held[process, h] = held[process, h + 1]
            held_count[process] -= 1
        elif next_task[0] < n_tasks:
            task = next_task[0]
            next_task[0] += 1
            waited = schedule.dispatch_cycles
        while task >= 0 and held_count[process] < schedule.take_ahead and next_task[0] < n_tasks:
            held[process, held_count[process]] = next_task[0]
            task_owner[next_task[0]] = process
            held_count[process] += 1
            next_task[0] += 1
    elif own_next[process] < schedule.own_offsets[process + 1]:
        task = schedule.own_tasks[own_next[process]]
        own_next[process] += 1
    return task, waited


@njit(cache=True, inline="always")
def _memory_cycles(process_counts, hits_before, misses_before, latency):
    """Latency of the accesses counted since the snapshot: each level's new
    hits at its latency, the last level's new misses at memory's."""
    n_levels = process_counts.shape[0]
    memory = (process_counts[n_levels - 1, K.MISSES] - misses_before) * latency[n_levels]
    for level in range(n_levels):
        memory += (process_counts[level, K.HITS] - hits_before[level]) * latency[level]
    return memory
