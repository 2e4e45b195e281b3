"""The operating system of the simulated machine: run queues, time slices, background load.

One compiled event loop (:func:`run_schedule`) runs every mapping on every
scheduler. Its rules, in the order it applies them:

- **Processes.** Ours (``0 .. n-1``) render pixels; other users' background
  processes (``n .. n+B-1``) are always runnable and never finish.
- **Run queues.** Every process waits in one FIFO run queue. With the
  ``shared-queue`` scheduler there is one queue for all CPUs (a process runs
  on whichever CPU is free when its turn comes); with ``static`` each CPU has
  its own queue of the processes pinned to it. At time 0 the queues are
  filled in :attr:`RunQueues.start_order` (background processes first: they
  were running before our run started), and free CPUs take their heads in
  CPU order.
- **Time slices.** A process runs until its slice of ``quantum`` cycles ends
  (checked after each pixel: a pixel is never split), it finishes, or (a
  dynamic process) its task ends and it must ask the master for the next.
  At a slice end it goes to the tail of its queue only if another process is
  waiting there; the CPU then takes the queue's head. Otherwise it runs on
  (an OS does not preempt a process nobody waits for). A CPU whose process
  finished takes its queue's head, or stays idle if the queue is empty.
- **Caches stay with the CPU.** A process that moves starts on the caches
  its new CPU's previous processes left. Cache counters are kept per process.
- **Background slices.** A background process runs for exactly one quantum
  and reads ``footprint_lines`` distinct lines of its own address region, a
  fresh stretch each slice (see :class:`BackgroundLoad`): it evicts our data
  from the CPU's caches as another user's job would.
- **Context switches.** When a CPU starts a process other than the one it
  ran last, ``switch_cycles`` pass (counted in no process's user time).
- **Event order.** The CPU whose clock is lowest always moves next (ties: the
  lowest CPU index), so queue hand-overs and dynamic hand-outs happen in
  time order. The run is over when the last of our processes finishes.

- **Data TLB** (optional). Each CPU has one; every access, ours and the
  background's, is looked up in the TLB of the CPU it runs on, and a miss of
  ours costs a fixed penalty on top of its memory cycles.

The rules that do not touch caches (:class:`OsState` and the helpers that
take it: decisions, background slices, placement, hand-outs, a pixel's end)
are shared with :mod:`coherence.shared_schedule`'s event loop.

User time of a process = its compute cycles + its memory cycles (on whichever
CPU's caches it ran, TLB misses included) + its dispatch waits; real time =
when the last of ours finished.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim import kernels as K
from cachesim import tlb as T
from cachesim.fresh import skip_fresh_lines
from coherence.record_lines import FILL_AHEAD, line_span_bound, record_lines_and_writes
from coherence.page_placement import BackgroundPages, translate_stream
from rtcommon.jit import NO_REFCOUNTS

# Columns of the per-process cycle totals the event loop writes.
COMPUTE_CYCLES, MEMORY_CYCLES, DISPATCH_CYCLES, FINISH_CYCLES = 0, 1, 2, 3
N_CYCLE_COLUMNS = 4
# Columns of the per-process placement record.
FIRST_CPU, MIGRATIONS = 0, 1
N_PLACEMENT_COLUMNS = 2
# A CPU that runs nothing.
NO_PROCESS = -1
# Line accesses a run's pixel buffer is made to hold at the start (36 MB with
# their write flags) before it knows a pixel needs more.
MAX_PIXEL_LINES = 1 << 22


class RunQueues(NamedTuple):
    """Who waits where, and how long a slice is.

    Attributes
    ----------
    process_queue : ndarray of int64, shape (n + B,)
        The run queue each process waits in (ours first, then background).
    start_order : ndarray of int64, shape (n + B,)
        Processes in the order they enter their queues at time 0.
    n_queues : int
        1 for a shared queue, the CPU count for static placement (queue
        ``c`` is CPU ``c``'s).
    quantum : float
        Time slice in cycles (``0``: a process runs until it finishes).
    switch_cycles : float
        Cycles a CPU spends starting a process other than its last one.
    """

    process_queue: np.ndarray
    start_order: np.ndarray
    n_queues: int
    quantum: float
    switch_cycles: float


class BackgroundLoad(NamedTuple):
    """Other users' processes and the lines their slices read.

    Attributes
    ----------
    first_line : ndarray of int64, shape (B,)
        First line number (address >> ``line_shift``) of each background
        process's stream; slice ``k`` of process ``b`` reads lines
        ``first_line[b] + k * footprint_lines`` onwards, ``footprint_lines``
        of them.
    footprint_lines : int
        Distinct lines one background slice reads.
    skip : bool
        Apply each slice with :func:`cachesim.fresh.skip_fresh_lines`
        instead of walking it access by access: the caller has checked
        that it is exact (:func:`cachesim.fresh.skips_exactly`), that no TLB
        is looked up, and that lines are the first level's.
    pages : BackgroundPages
        Where the streams' pages lie in physical memory (``colour_bits``
        -1: as they are; see :func:`coherence.page_placement.translate_stream`).
    """

    first_line: np.ndarray
    footprint_lines: int
    skip: bool = False
    pages: BackgroundPages = BackgroundPages(13, -1, 0)


class CpuTlbs(NamedTuple):
    """One data TLB per CPU, its counters per process (a TLB, like the caches, stays with its CPU).

    Attributes
    ----------
    enabled : bool
        False: no TLB (the arrays are placeholders and never read).
    geometry : cachesim.tlb.TlbGeometry
    pages, stamps : ndarray of int64, shape (C, E)
        Each CPU's entries (:class:`cachesim.tlb.TlbArrays` fields).
    cursor : ndarray of int64, shape (C, N_CURSOR)
    counts : ndarray of int64, shape (n + B, N_TLB_COUNTERS)
        Lookups, hits and misses per process. Updated in place.
    miss_cycles : float
        Cycles of one miss (a fixed penalty, added to memory cycles).
    """

    enabled: bool
    geometry: T.TlbGeometry
    pages: np.ndarray
    stamps: np.ndarray
    cursor: np.ndarray
    counts: np.ndarray
    miss_cycles: float


class RunOutputs(NamedTuple):
    """What the event loop writes, per process and per task.

    Attributes
    ----------
    cycles : ndarray of float64, shape (n, N_CYCLE_COLUMNS)
        Compute, memory, dispatch and finish cycles per process.
    placement : ndarray of int64, shape (n, N_PLACEMENT_COLUMNS)
        Each process's first CPU (-1: never ran) and migrations.
    task_owner : ndarray of int64, shape (T,)
        The process that rendered each task.
    pixel_misses : ndarray of int64, shape (P, L), or (0, L) when not wanted
        Misses of each pixel at each cache level, reads and writes: the
        change of the level's ``MISSES`` counter of the process that
        rendered it while it did (a pixel is never split across slices and
        counters are per process, so the change is the pixel's alone).
        Shape (0, L): nothing is written.
    """

    cycles: np.ndarray
    placement: np.ndarray
    task_owner: np.ndarray
    pixel_misses: np.ndarray


class OsState(NamedTuple):
    """The operating system's state in an event loop (:func:`run_schedule`, :mod:`coherence.shared_schedule`).

    Attributes
    ----------
    queue_items : ndarray of int64, shape (Q, n + B)
        Run queues as FIFO rings, one row per queue.
    queue_head, queue_length, ours_waiting : ndarray of int64, shape (Q,)
        Each queue's head, length and how many of ours wait in it.
    cpu_clock, slice_used : ndarray of float64, shape (C,)
        Each CPU's clock and the cycles of its current slice.
    running, last_ran : ndarray of int64, shape (C,)
        The process each CPU runs and the one it ran last (:data:`NO_PROCESS`: none).
    active : ndarray of bool, shape (C,)
        False once none of ours can reach the CPU again.
    previous_cpu, own_next, current_task, position, held_count : ndarray of int64, shape (n,)
        Per process of ours: last CPU, next own task (static), task rendered (-1: none), next pixel of it
        (index into ``task_pixels``), take-ahead tasks held.
    held : ndarray of int64, shape (n, max(take_ahead, 1))
        Take-ahead tasks held, a small ring per process.
    next_task : ndarray of int64, shape (1,)
        The dynamic queue's next task.
    background_slices : ndarray of int64, shape (B,)
        Slices each background process has run.
    """

    queue_items: np.ndarray
    queue_head: np.ndarray
    queue_length: np.ndarray
    ours_waiting: np.ndarray
    cpu_clock: np.ndarray
    slice_used: np.ndarray
    running: np.ndarray
    last_ran: np.ndarray
    active: np.ndarray
    previous_cpu: np.ndarray
    own_next: np.ndarray
    current_task: np.ndarray
    position: np.ndarray
    held_count: np.ndarray
    held: np.ndarray
    next_task: np.ndarray
    background_slices: np.ndarray


@njit(cache=True)
def os_state(queues, schedule, n_ours, n_cpus):
    """A fresh :class:`OsState` for ``n_ours`` processes of ours on ``n_cpus`` CPUs, every process in its run
    queue in ``queues.start_order``, every CPU free at clock 0.

    Parameters
    ----------
    queues : RunQueues
    schedule : coherence.simulation.Schedule
    n_ours : int
    n_cpus : int

    Returns
    -------
    OsState
    """
    n_queues = queues.n_queues
    n_all = queues.process_queue.shape[0]
    state = OsState(
        np.empty((n_queues, n_all), dtype=np.int64), np.zeros(n_queues, dtype=np.int64),
        np.zeros(n_queues, dtype=np.int64), np.zeros(n_queues, dtype=np.int64),
        np.zeros(n_cpus), np.zeros(n_cpus),
        np.full(n_cpus, NO_PROCESS, dtype=np.int64), np.full(n_cpus, NO_PROCESS, dtype=np.int64),
        np.ones(n_cpus, dtype=np.bool_),
        np.full(n_ours, -1, dtype=np.int64), schedule.own_offsets[:n_ours].copy(), np.full(n_ours, -1, dtype=np.int64),
        np.zeros(n_ours, dtype=np.int64), np.zeros(n_ours, dtype=np.int64),
        np.full((n_ours, max(schedule.take_ahead, 1)), -1, dtype=np.int64), np.zeros(1, dtype=np.int64),
        np.zeros(n_all - n_ours, dtype=np.int64))
    for process in queues.start_order:
        _push(state.queue_items, state.queue_head, state.queue_length, state.ours_waiting,
              queues.process_queue[process], process, n_ours)
    return state


@njit(cache=True, inline="always")
def _decide(system, queues, cpu, clock, n_ours):
    """At a free CPU or between two pixels: the process ``cpu`` runs now and its clock.

    A free CPU, or one whose slice is over while another process waits in
    its queue, takes the queue's head (the slice's process goes to the tail);
    starting a process other than the last one costs ``switch_cycles``.
    Returns :data:`NO_PROCESS` when the CPU goes idle for good: nothing waits
    for a free CPU, or it would run a background process while none of ours
    can reach it again.
    """
    queue = cpu if queues.n_queues > 1 else 0
    queue_items = system.queue_items
    queue_head = system.queue_head
    queue_length = system.queue_length
    ours_waiting = system.ours_waiting
    process = system.running[cpu]
    slice_over = process >= 0 and queues.quantum > 0 and system.slice_used[cpu] >= queues.quantum
    if process < 0 or slice_over:
        if queue_length[queue] > 0:
            if process >= 0:
                _push(queue_items, queue_head, queue_length, ours_waiting, queues.process_queue[process], process,
                      n_ours)
            process = _pop(queue_items, queue_head, queue_length, ours_waiting, queue, n_ours)
        elif process < 0:
            system.active[cpu] = False  # nothing will ever wait here again
            return NO_PROCESS, clock
        system.running[cpu] = process
        system.slice_used[cpu] = 0.0
        if system.last_ran[cpu] >= 0 and system.last_ran[cpu] != process:
            clock += queues.switch_cycles
        system.last_ran[cpu] = process
    if process >= n_ours and ours_waiting[queue] == 0 and (queues.n_queues > 1 or queue_length[queue] == 0):
        system.active[cpu] = False  # none of ours can reach this CPU again
        return NO_PROCESS, clock
    return process, clock


@njit(cache=True, inline="always")
def _background_slice(system, queues, background, process, n_ours, cpu, clock):
    """Background ``process`` takes a whole slice on ``cpu`` from ``clock`` (the CPU's clock is set past it);
    returns the first line its slice reads (``footprint_lines`` of them)."""
    b = process - n_ours
    start = background.first_line[b] + system.background_slices[b] * background.footprint_lines
    system.background_slices[b] += 1
    system.slice_used[cpu] = queues.quantum
    system.cpu_clock[cpu] = clock + queues.quantum
    return start


@njit(cache=True, inline="always")
def _place(system, placement, process, cpu):
    """Record that ``process`` of ours runs on ``cpu``: its first CPU, or a migration."""
    if system.previous_cpu[process] < 0:
        placement[process, FIRST_CPU] = cpu
    elif system.previous_cpu[process] != cpu:
        placement[process, MIGRATIONS] += 1
    system.previous_cpu[process] = cpu


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _next_pixel(system, schedule, out, process, cpu, clock):
    """The next pixel of ``process`` (-1: it has none left) and the clock after any hand-out.

    Called once per pixel and compiled without reference counting, not
    inlined: inlined into :func:`run_schedule` (which counts references),
    each read of a bundle's field takes and drops a reference per pixel.

    A process without a task takes its next one first (:func:`_next_task`);
    the wait counts as its dispatch cycles and in the CPU's slice.
    """
    task = system.current_task[process]
    if task < 0:
        task, waited = _next_task(process, schedule, system.own_next, system.held, system.held_count, system.next_task,
                                  out.task_owner)
        clock += waited
        out.cycles[process, DISPATCH_CYCLES] += waited
        system.slice_used[cpu] += waited
        if task < 0:
            return -1, clock
        system.current_task[process] = task
        system.position[process] = schedule.task_offsets[task]
    pixel = schedule.task_pixels[system.position[process]]
    system.position[process] += 1
    return pixel, clock


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _after_pixel(system, schedule, queues, process, cpu):
    """After a pixel of ``process`` on ``cpu``: (whether the CPU goes back to the event loop, whether the
    process has finished). Compiled as :func:`_next_pixel` is, for the same reason.

    A dynamic task's end goes back (the next hand-out comes in time order);
    a static process is done with its last pixel, not when it next gets the
    CPU; a slice over goes back.
    """
    task = system.current_task[process]
    if system.position[process] == schedule.task_offsets[task + 1]:
        system.current_task[process] = -1
        if schedule.dynamic:
            return True, False
        if system.own_next[process] == schedule.own_offsets[process + 1] or not _has_pixels(
                schedule, system.own_next[process], schedule.own_offsets[process + 1]):
            return True, True
    return queues.quantum > 0 and system.slice_used[cpu] >= queues.quantum, False


@njit(cache=True, inline="always")
def _finish(system, out, process, cpu, clock):
    """``process`` finished at ``clock`` on ``cpu``, which is free again."""
    out.cycles[process, FINISH_CYCLES] = clock
    system.running[cpu] = NO_PROCESS


@njit(cache=True, inline="always")
def _tlb_misses(tlbs, cpu, process, addresses):
    # look the addresses up in the CPU's TLB, counting for the process
    if not tlbs.enabled:
        return 0
    return T.tlb_lookup(addresses, tlbs.geometry,
                        T.TlbArrays(tlbs.pages[cpu], tlbs.stamps[cpu], tlbs.cursor[cpu], tlbs.counts[process]))


@njit(cache=True, nogil=True)
def run_schedule(reads, geometry, caches, tlbs, cost, schedule, queues, background, out):
    """The event loop (see the module docstring).

    Parameters
    ----------
    reads : coherence.simulation.PixelReads
    geometry : cachesim.kernels.CacheGeometry
    caches : cachesim.kernels.CacheArrays
        ``tags``/``stamps`` (C, W): one state per CPU; ``counts``
        (n + B, L, N_COUNTERS): counters per process. Updated in place.
    tlbs : CpuTlbs
        Every access (ours and the background's) is looked up in the CPU's
        TLB when enabled; a miss of ours adds ``miss_cycles`` to its memory
        cycles.
    cost : coherence.simulation.PixelCost
    schedule : coherence.simulation.Schedule
    queues : RunQueues
    background : BackgroundLoad
    out : RunOutputs
        Receives the cycles, placements and task owners, and each pixel's
        misses per level if ``out.pixel_misses`` has a row per pixel.
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
    line_offsets = reads.lines.line_offsets
    shared_addresses = reads.lines.addresses
    shared_writes = reads.lines.writes
    pixel_writes = reads.lines.pixel_writes
    shared = line_offsets.shape[0] > 0
    compute = cost.compute
    latency = cost.latency
    first_line = background.first_line
    footprint_lines = background.footprint_lines
    skip_background = background.skip
    background_pages = background.pages
    place_background = background_pages.colour_bits >= 0
    out_cycles = out.cycles
    out_placement = out.placement
    pixel_misses = out.pixel_misses
    record_pixel_misses = pixel_misses.shape[0] > 0
    tlb_miss_cycles = tlbs.miss_cycles
    n_ours = out_cycles.shape[0]
    n_cpus = tags.shape[0]
    n_levels = counts.shape[1]

    system = os_state(queues, schedule, n_ours, n_cpus)
    cpu_clock = system.cpu_clock
    slice_used = system.slice_used
    cache_clock = np.zeros(n_cpus, dtype=np.int64)
    ours_left = n_ours
    # Room for any pixel's lines, so that record_lines_and_writes need not
    # count them before it fills the buffer (within a cap: a pixel beyond it
    # is counted, and the buffer grown, when it comes).
    most_records = 0
    for pixel in range(pixel_offsets.shape[0] - 1):
        most_records = max(most_records, pixel_offsets[pixel + 1] - pixel_offsets[pixel])
    room = min(most_records * line_span_bound(placement, line_shift) + FILL_AHEAD, MAX_PIXEL_LINES)
    buffer = np.empty(max(4096, footprint_lines, room), dtype=np.uint64)
    write_flags = np.empty(buffer.shape[0], dtype=np.bool_)
    no_writes = np.zeros(0, dtype=np.bool_)
    work = K.chunk_buffers()
    served = np.zeros(0, dtype=np.uint8)
    record_served = served.shape[0] > 0  # False, but not a literal: no kernel specialised for it
    hits_before = np.zeros(n_levels, dtype=np.int64)
    while ours_left > 0:
        cpu = _lowest_clock_cpu(cpu_clock, system.active)
        if cpu < 0:
            break
        # A decision point: a free CPU, or a slice that ended.
        process, clock = _decide(system, queues, cpu, cpu_clock[cpu], n_ours)
        if process < 0:
            continue
        if process >= n_ours:
            start = _background_slice(system, queues, background, process, n_ours, cpu, clock)
            cache = K.CacheArrays(tags[cpu], stamps[cpu], counts[process])
            if skip_background:  # fresh lines: the state after them is known without walking them
                cache_clock[cpu] = skip_fresh_lines(start, footprint_lines, geometry, cache, cache_clock[cpu])
            else:
                for i in range(footprint_lines):
                    buffer[i] = np.uint64((start + i) << line_shift)
                if place_background:
                    b = process - n_ours
                    translate_stream(buffer, footprint_lines, b, first_line[b] << line_shift, background_pages)
                cache_clock[cpu] = K.simulate_into(buffer[:footprint_lines], geometry, cache, cache_clock[cpu],
                                                   served, record_served, work)
                _tlb_misses(tlbs, cpu, process, buffer[:footprint_lines])
            continue

        _place(system, out_placement, process, cpu)
        cache = K.CacheArrays(tags[cpu], stamps[cpu], counts[process])
        process_counts = counts[process]
        finished = False
        while True:
            pixel, clock = _next_pixel(system, schedule, out, process, cpu, clock)
            if pixel < 0:
                finished = True
                break
            if shared:  # worked out once for the whole study
                first = line_offsets[pixel]
                n_addresses = line_offsets[pixel + 1] - first
                n_writes = pixel_writes[pixel]
                addresses = shared_addresses[first:first + n_addresses]
                flags = shared_writes[first:first + n_addresses]
            else:
                buffer, write_flags, n_addresses, n_writes = record_lines_and_writes(
                    records, pixel_offsets[pixel], pixel_offsets[pixel + 1], placement, line_shift, buffer,
                    write_flags)
                addresses = buffer[:n_addresses]
                flags = write_flags[:n_addresses]
            for level in range(n_levels):
                hits_before[level] = process_counts[level, K.HITS] - process_counts[level, K.WRITE_HITS]
            misses_before = process_counts[n_levels - 1, K.MISSES] - process_counts[n_levels - 1, K.WRITE_MISSES]
            if record_pixel_misses:  # the counters before, in the pixel's own row; the change after
                for level in range(n_levels):
                    pixel_misses[pixel, level] = process_counts[level, K.MISSES]
            # a pixel without writes keeps the read-only (fast) path
            cache_clock[cpu] = K.simulate_writes_into(addresses, flags if n_writes else no_writes,
                                                      geometry, cache, cache_clock[cpu], served, record_served, work)
            if record_pixel_misses:
                for level in range(n_levels):
                    pixel_misses[pixel, level] = process_counts[level, K.MISSES] - pixel_misses[pixel, level]
            memory = _memory_cycles(process_counts, hits_before, misses_before, latency) + n_writes * latency[0]
            memory += _tlb_misses(tlbs, cpu, process, addresses) * tlb_miss_cycles
            cycles = compute[pixel] + memory
            out_cycles[process, COMPUTE_CYCLES] += compute[pixel]
            out_cycles[process, MEMORY_CYCLES] += memory
            clock += cycles
            slice_used[cpu] += cycles
            stop, finished = _after_pixel(system, schedule, queues, process, cpu)
            if stop:
                break
        if finished:
            _finish(system, out, process, cpu, clock)
            ours_left -= 1
        cpu_clock[cpu] = clock


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _has_pixels(schedule, first, stop):
    """Whether static own tasks ``own_tasks[first:stop]`` hold any pixel."""
    for k in range(first, stop):
        task = schedule.own_tasks[k]
        if schedule.task_offsets[task + 1] > schedule.task_offsets[task]:
            return True
    return False


@njit(cache=True, inline="always")
def _push(queue_items, queue_head, queue_length, ours_waiting, queue, process, n_ours):
    """Append ``process`` to the tail of run queue ``queue``."""
    capacity = queue_items.shape[1]
    queue_items[queue, (queue_head[queue] + queue_length[queue]) % capacity] = process
    queue_length[queue] += 1
    if process < n_ours:
        ours_waiting[queue] += 1


@njit(cache=True, inline="always")
def _pop(queue_items, queue_head, queue_length, ours_waiting, queue, n_ours):
    """Remove and return the head of run queue ``queue`` (which is not empty)."""
    process = queue_items[queue, queue_head[queue]]
    queue_head[queue] = (queue_head[queue] + 1) % queue_items.shape[1]
    queue_length[queue] -= 1
    if process < n_ours:
        ours_waiting[queue] -= 1
    return process


@njit(cache=True, inline="always")
def _lowest_clock_cpu(cpu_clock, active):
    """The active CPU whose clock is lowest, the lowest index on ties (-1: none)."""
    cpu = -1
    for c in range(cpu_clock.shape[0]):
        if active[c] and (cpu < 0 or cpu_clock[c] < cpu_clock[cpu]):
            cpu = c
    return cpu


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _next_task(process, schedule, own_next, held, held_count, next_task, task_owner):
    """The next non-empty task of ``process`` (-1: none left) and the cycles it waited.

    Static: the process's next own task (``own_next`` advances). Dynamic: a
    held take-ahead task, else a hand-out from the global queue
    (``next_task[0]`` advances; costs ``dispatch_cycles``); then the
    take-ahead is refilled from the queue, its tasks owned at once. Empty
    tasks (more processes than rows, say) are owned and skipped.
    """
    waited = 0.0
    while True:
        task = -1
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
                waited += schedule.dispatch_cycles
            while task >= 0 and held_count[process] < schedule.take_ahead and next_task[0] < n_tasks:
                held[process, held_count[process]] = next_task[0]
                task_owner[next_task[0]] = process
                held_count[process] += 1
                next_task[0] += 1
        elif own_next[process] < schedule.own_offsets[process + 1]:
            task = schedule.own_tasks[own_next[process]]
            own_next[process] += 1
        if task < 0:
            return task, waited
        task_owner[task] = process
        if schedule.task_offsets[task + 1] > schedule.task_offsets[task]:
            return task, waited


@njit(cache=True, inline="always")
def _memory_cycles(process_counts, hits_before, misses_before, latency):
    """Latency of the reads counted since the snapshot: each level's new read
    hits at its latency, the last level's new read misses at memory's.

    Writes are left out here: the 21164 retires a store into its write
    buffer (the D-cache is write-through), so a store costs the first
    level's latency whatever serves it; the caller adds that. The levels
    still allocate on writes as the hierarchy says (cachesim.by_access).
    """
    n_levels = process_counts.shape[0]
    last = n_levels - 1
    memory = (process_counts[last, K.MISSES] - process_counts[last, K.WRITE_MISSES] - misses_before) \
        * latency[n_levels]
    for level in range(n_levels):
        memory += (process_counts[level, K.HITS] - process_counts[level, K.WRITE_HITS] - hits_before[level]) \
            * latency[level]
    return memory
