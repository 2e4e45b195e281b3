"""The operating system of the simulated machine: run queues, time slices, background load.

These rules do not touch caches; both event loops apply them, in this order:
:func:`coherence.scheduler.run_schedule` (private caches) and
:func:`coherence.shared_schedule.run_shared_schedule` (levels shared by
hardware threads).

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
- **Background slices.** A background process runs for exactly one quantum
  and reads ``footprint_lines`` distinct lines of its own address region, a
  fresh stretch each slice (see :class:`BackgroundLoad`): it evicts our data
  from the CPU's caches as another user's job would.
- **Context switches.** When a CPU starts a process other than the one it
  ran last, ``switch_cycles`` pass (counted in no process's user time).
- **Event order.** The CPU whose clock is lowest always moves next (ties: the
  lowest CPU index), so queue hand-overs and dynamic hand-outs happen in
  time order. The run is over when the last of our processes finishes.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from coherence.page_placement import BackgroundPages
from rtcommon.jit import NO_REFCOUNTS

# Columns of the per-process cycle totals the event loop writes.
COMPUTE_CYCLES, MEMORY_CYCLES, DISPATCH_CYCLES, FINISH_CYCLES = 0, 1, 2, 3
N_CYCLE_COLUMNS = 4
# Columns of the per-process placement record.
FIRST_CPU, MIGRATIONS = 0, 1
N_PLACEMENT_COLUMNS = 2
# A CPU that runs nothing.
NO_PROCESS = -1


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
        instead of walking it access by access (a data TLB looking the
        slice's pages up as runs): the caller has checked that it is exact
        (:func:`cachesim.fresh.skips_exactly`), that lines are the first
        level's and that a TLB's pages hold whole lines.
    pages : BackgroundPages
        Where the streams' pages lie in physical memory (``colour_bits``
        -1: as they are; see :func:`coherence.page_placement.translate_stream`).
    """

    first_line: np.ndarray
    footprint_lines: int
    skip: bool = False
    pages: BackgroundPages = BackgroundPages(13, -1, 0)



class OsState(NamedTuple):
    """The operating system's state in an event loop (:func:`coherence.scheduler.run_schedule`,
    :mod:`coherence.shared_schedule`).

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
        push(state.queue_items, state.queue_head, state.queue_length, state.ours_waiting,
              queues.process_queue[process], process, n_ours)
    return state


@njit(cache=True, inline="always")
def decide(system, queues, cpu, clock, n_ours):
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
                push(queue_items, queue_head, queue_length, ours_waiting, queues.process_queue[process], process,
                      n_ours)
            process = pop(queue_items, queue_head, queue_length, ours_waiting, queue, n_ours)
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
def background_slice(system, queues, background, process, n_ours, cpu, clock):
    """Background ``process`` takes a whole slice on ``cpu`` from ``clock`` (the CPU's clock is set past it);
    returns the first line its slice reads (``footprint_lines`` of them)."""
    b = process - n_ours
    start = background.first_line[b] + system.background_slices[b] * background.footprint_lines
    system.background_slices[b] += 1
    system.slice_used[cpu] = queues.quantum
    system.cpu_clock[cpu] = clock + queues.quantum
    return start


@njit(cache=True, inline="always")
def place(system, placement, process, cpu):
    """Record that ``process`` of ours runs on ``cpu``: its first CPU, or a migration."""
    if system.previous_cpu[process] < 0:
        placement[process, FIRST_CPU] = cpu
    elif system.previous_cpu[process] != cpu:
        placement[process, MIGRATIONS] += 1
    system.previous_cpu[process] = cpu


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def next_pixel(system, schedule, out, process, cpu, clock):
    """The next pixel of ``process`` (-1: it has none left) and the clock after any hand-out.

    Called once per pixel and compiled without reference counting, not
    inlined: inlined into :func:`coherence.scheduler.run_schedule` (which counts references),
    each read of a bundle's field takes and drops a reference per pixel.

    A process without a task takes its next one first (:func:`take_task`);
    the wait counts as its dispatch cycles and in the CPU's slice.
    """
    task = system.current_task[process]
    if task < 0:
        task, waited = take_task(process, schedule, system.own_next, system.held, system.held_count, system.next_task,
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
def after_pixel(system, schedule, queues, process, cpu):
    """After a pixel of ``process`` on ``cpu``: (whether the CPU goes back to the event loop, whether the
    process has finished). Compiled as :func:`next_pixel` is, for the same reason.

    A dynamic task's end goes back (the next hand-out comes in time order);
    a static process is done with its last pixel, not when it next gets the
    CPU; a slice over goes back.
    """
    task = system.current_task[process]
    if system.position[process] == schedule.task_offsets[task + 1]:
        system.current_task[process] = -1
        if schedule.dynamic:
            return True, False
        if system.own_next[process] == schedule.own_offsets[process + 1] or not has_pixels(
                schedule, system.own_next[process], schedule.own_offsets[process + 1]):
            return True, True
    return queues.quantum > 0 and system.slice_used[cpu] >= queues.quantum, False


@njit(cache=True, inline="always")
def finish(system, out, process, cpu, clock):
    """``process`` finished at ``clock`` on ``cpu``, which is free again."""
    out.cycles[process, FINISH_CYCLES] = clock
    system.running[cpu] = NO_PROCESS



@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def has_pixels(schedule, first, stop):
    """Whether static own tasks ``own_tasks[first:stop]`` hold any pixel."""
    for k in range(first, stop):
        task = schedule.own_tasks[k]
        if schedule.task_offsets[task + 1] > schedule.task_offsets[task]:
            return True
    return False


@njit(cache=True, inline="always")
def push(queue_items, queue_head, queue_length, ours_waiting, queue, process, n_ours):
    """Append ``process`` to the tail of run queue ``queue``."""
    capacity = queue_items.shape[1]
    queue_items[queue, (queue_head[queue] + queue_length[queue]) % capacity] = process
    queue_length[queue] += 1
    if process < n_ours:
        ours_waiting[queue] += 1


@njit(cache=True, inline="always")
def pop(queue_items, queue_head, queue_length, ours_waiting, queue, n_ours):
    """Remove and return the head of run queue ``queue`` (which is not empty)."""
    process = queue_items[queue, queue_head[queue]]
    queue_head[queue] = (queue_head[queue] + 1) % queue_items.shape[1]
    queue_length[queue] -= 1
    if process < n_ours:
        ours_waiting[queue] -= 1
    return process


@njit(cache=True, inline="always")
def lowest_clock_cpu(cpu_clock, active):
    """The active CPU whose clock is lowest, the lowest index on ties (-1: none)."""
    cpu = -1
    for c in range(cpu_clock.shape[0]):
        if active[c] and (cpu < 0 or cpu_clock[c] < cpu_clock[cpu]):
            cpu = c
    return cpu


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def take_task(process, schedule, own_next, held, held_count, next_task, task_owner):
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

