"""The schedule on a machine whose hardware threads share cache levels: processes that run at the same time interleave.

:func:`run_shared_schedule` is the event loop of :mod:`coherence.scheduler`
with the operating system's rules of :mod:`coherence.os_rules` (run queues,
time slices, dynamic hand-outs, take-ahead, context switches, background
slices: the same rules, in the same order) on the hardware
threads of a :class:`cachesim.sharing.SharedHierarchy`. A CPU of the
scheduler is a hardware thread (:func:`cpu_threads`: free CPUs are taken
in CPU order, and the CPUs go over the cores before their SMT siblings, so
the first ``n_cores`` processes get a core each, as an operating system
spreads work over idle cores before it pairs SMT threads). Every access goes through the shared
machine's one state (:func:`cachesim.multicore.shared_access`): the instances
of each level that serve the thread, write-invalidate coherence between
instances on, so processes running on different cores at the same time warm
and evict each other's lines at the levels they share and take lines from
each other's private levels. Reads that hit the thread's first level
take a loop of their own (:mod:`coherence.turn_reads`), with the same
counts, stamps and cycles. On a machine whose levels have prefetchers
every access goes through
:func:`cachesim.multicore_prefetch.prefetching_access` instead, which also
trains and issues the prefetchers of the levels it reaches (each issued
prefetch advances the access clock by one, and costs no cycles).

**Interleaving granularity** ``interleave_cycles`` (``Q``): the hardware
thread whose clock is lowest (ties: the lowest index) takes a *turn*: it
runs accesses until its clock has advanced by ``Q`` cycles or more since
the turn began, or its pixel ends (an end of pixel is where the operating
system decides: slice ends, dynamic hand-outs, a process finishing). A
pixel is split between turns: its compute cycles are spread evenly over
its accesses, so access ``k`` of a pixel of ``n`` accesses and ``C``
compute cycles advances the thread's clock by ``C / n`` plus its own
latency (a read: the latency of the level that served it, memory's if none
did; a write: the first level's, a store retired into a store buffer). A
pixel without accesses takes its compute cycles at once. With ``Q = 1`` a
turn is one access whenever an access costs at least one cycle, so the
threads interleave access by access in clock order. SMT threads of one
core are hardware threads like any other: each has its own clock and they
interleave at the same ``Q`` (at ``Q = 1`` access by access).

Other users' background processes take whole slices as in
:mod:`coherence.os_rules`; a background slice is one turn, its reads
(one per line of its stream, kind 0) going through the thread's instances
at once.

Per-ray data is private to a process: the records of
:data:`coherence.thread_streams.PRIVATE_KINDS` of process ``p`` lie at
their layout address plus ``(p + 1) * span`` (``span`` from
:func:`coherence.thread_streams.private_span`); the scene and the frame
buffer are shared, and each record's accesses carry its bytes in the line
(:func:`coherence.thread_streams.record_pieces`), so false sharing shows.

**The task counter.** A dynamic mapping (DB) hands its tasks out through
one shared counter: every task a process takes from the queue (take-ahead
tasks included) is an atomic read-modify-write of the counter's
:data:`coherence.thread_streams.COUNTER_BYTES` bytes at
:attr:`SharedMachine.counter_address`, made at the hand-out on the thread
the process runs on: one write access of the auxiliary record kind
(:data:`tracer.trace.records.AUXILIARY_KIND`), so that the counter's line
moves between cores (coherence misses and invalidations of that kind: DB's
counter traffic). The operation waits for its line: it costs the latency of
the level that served it (memory's if none did), counted as dispatch
cycles, and is counted among the process's accesses. Static mappings never
touch it.

User time of a process = its compute cycles + its memory cycles + its
dispatch waits; real time = when the last of ours finished.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cachesim.multicore import HITS, shared_access
from cachesim.multicore_prefetch import prefetching_access
from cachesim.sets import LRU
from coherence.os_rules import (COMPUTE_CYCLES, DISPATCH_CYCLES, MEMORY_CYCLES, after_pixel, background_slice, decide,
                                finish, lowest_clock_cpu, next_pixel, os_state, place)
from coherence.piece_words import KIND_MASK, KIND_SHIFT, PRIVATE_BIT, SIZE_MASK, WRITE_BIT
from coherence.recost import READ_HITS, READ_MISSES, WRITE_HITS, WRITE_MISSES
from coherence.thread_streams import COUNTER_BYTES
from coherence.turn_reads import FirstLevel, TurnPace, first_level_reads
from rtcommon.jit import NO_REFCOUNTS
from tracer.trace.records import AUXILIARY_KIND

#: Piece index the access log gives a background read.
BACKGROUND_READ = -1
#: Piece index the access log gives an access of the task counter.
COUNTER_ACCESS = -2



class SharedMachine(NamedTuple):
    """The shared machine's kernel view and state (:class:`cachesim.multicore_state.SharedState`).

    Attributes
    ----------
    geometry : cachesim.sets.CacheGeometry
    machine : cachesim.multicore_state.MachineGeometry
    state : cachesim.multicore_state.SharedArrays
        Updated in place.
    line_shift : int
        log2 of the first level's line size.
    thread_of : ndarray of int64, shape (C,)
        The hardware thread that is the scheduler's CPU ``c``.
    counter_address : int
        First byte of the dynamic mappings' shared task counter
        (:func:`coherence.thread_streams.counter_address`).
    """

    geometry: object
    machine: object
    state: object
    line_shift: int
    thread_of: np.ndarray
    counter_address: int


class SharedOutputs(NamedTuple):
    """What the shared event loop writes.

    Attributes
    ----------
    cycles : ndarray of float64, shape (n, N_CYCLE_COLUMNS)
        Compute, memory, dispatch and finish cycles per process.
    placement : ndarray of int64, shape (n, N_PLACEMENT_COLUMNS)
        First hardware thread (-1: never ran) and migrations per process.
    task_owner : ndarray of int64, shape (T,)
    accesses : ndarray of int64, shape (n, L, coherence.recost.N_ACCESS_COLUMNS)
        Read hits, read misses, write hits and write misses of each process at each
        level (columns :data:`coherence.recost.READ_HITS` ...; a miss column is its hit column + 1).
    log_addresses : ndarray of uint64, shape (M,), or (0,)
        When not empty, the address of every access in the order the
        machine served it (ours and the background's); room for all of them.
    log_threads : ndarray of int64, shape (M,) or (0,)
        Hardware thread of each logged access.
    log_pieces : ndarray of int64, shape (M,) or (0,)
        Index into :class:`coherence.piece_words.PixelPieces` of each logged access (:data:`BACKGROUND_READ`: a
        background read, :data:`COUNTER_ACCESS`: a task hand-out's access of the counter).
    log_length : ndarray of int64, shape (1,)
        Accesses logged.
    pixel_misses : ndarray of int64, shape (P, L), or (0, L)
        With a row per pixel: the misses of each pixel's own accesses at each level (an access served by
        level ``l`` misses at every level above it), made by whichever thread replayed them; a task
        hand-out's access of the counter belongs to no pixel. Summed over a process's pixels: its misses in
        ``accesses`` less those of its counter accesses.
    """

    cycles: np.ndarray
    placement: np.ndarray
    task_owner: np.ndarray
    accesses: np.ndarray
    log_addresses: np.ndarray
    log_threads: np.ndarray
    log_pieces: np.ndarray
    log_length: np.ndarray
    pixel_misses: np.ndarray


def cpu_threads(n_cores: int, smt: int) -> np.ndarray:
    """The hardware thread (``core * smt + sibling``) of each scheduler CPU: the first sibling of every core,
    then the second of every core, and so on; int64 (n_cores * smt,)."""
    cpus = np.arange(n_cores * smt, dtype=np.int64)
    return (cpus % n_cores) * smt + cpus // n_cores


class _LoopState(NamedTuple):
    """The event loop's own arrays, allocated by :func:`run_shared_schedule` (the loop allocates nothing).

    Attributes
    ----------
    system : coherence.os_rules.OsState
        Run queues, clocks, slices, what each CPU runs and where each process is in its tasks.
    compute_share : ndarray of float64, shape (C,)
        Compute cycles each access of the CPU's pixel carries.
    cpu_pixel, next_piece : ndarray of int64, shape (C,)
        Each CPU's pixel and the pixel's next access (-1: between pixels).
    scratch : ndarray of int64, shape (3, L)
        Work space of :func:`cachesim.multicore.shared_access`.
    """

    system: object
    compute_share: np.ndarray
    cpu_pixel: np.ndarray
    next_piece: np.ndarray
    scratch: np.ndarray


@njit(cache=True, nogil=True)
def run_shared_schedule(pieces, shared, cost, schedule, queues, background, out, interleave_cycles, prefetchers):
    """The event loop on shared levels (see the module docstring).

    Parameters
    ----------
    pieces : coherence.piece_words.PixelPieces
    shared : SharedMachine
        Updated in place.
    cost : coherence.simulation.PixelCost
        ``latency`` (L + 1,): cycles of an access served by each level, memory last.
    schedule : coherence.simulation.Schedule
    queues : coherence.os_rules.RunQueues
        ``n_queues`` 1 (shared queue) or one per CPU (static).
    background : coherence.os_rules.BackgroundLoad
        ``skip`` and page placement are not used: every background read is made.
    out : SharedOutputs
    interleave_cycles : float
        ``Q`` >= 1: the cycles a turn lasts at least (unless its pixel ends).
    prefetchers : cachesim.multicore_prefetch.ThreadPrefetchers or None
        The levels' prefetchers (updated in place); None: the machine has none
        (the loop is then compiled without the prefetching path).

    Returns
    -------
    int
        The access clock after the run (accesses made, ours and the background's).
    """
    n_ours = out.cycles.shape[0]
    n_cpus = shared.thread_of.shape[0]
    loop = _LoopState(os_state(queues, schedule, n_ours, n_cpus), np.zeros(n_cpus), np.zeros(n_cpus, dtype=np.int64),
                      np.full(n_cpus, -1, dtype=np.int64), np.empty((3, cost.latency.shape[0] - 1), dtype=np.int64))
    return _event_loop(pieces, shared, cost, schedule, queues, background, out, interleave_cycles, loop, prefetchers)


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _event_loop(pieces, shared, cost, schedule, queues, background, out, interleave_cycles, loop, prefetchers):
    """:func:`run_shared_schedule`'s loop, on the arrays of ``loop`` (a :class:`_LoopState`)."""
    geometry = shared.geometry
    machine = shared.machine
    state = shared.state
    thread_of = shared.thread_of
    line_shift = shared.line_shift
    piece_offsets = pieces.piece_offsets
    piece_addresses = pieces.addresses
    piece_words = pieces.words
    span = np.uint64(pieces.private_span)
    counter = np.uint64(shared.counter_address)
    compute = cost.compute
    latency = cost.latency
    footprint_lines = background.footprint_lines
    out_cycles = out.cycles
    accesses = out.accesses
    log_addresses = out.log_addresses
    logging = log_addresses.shape[0] > 0
    pixel_misses = out.pixel_misses
    mapping_pixels = pixel_misses.shape[0] > 0
    system = loop.system
    cpu_clock = system.cpu_clock
    slice_used = system.slice_used
    compute_share = loop.compute_share
    cpu_pixel = loop.cpu_pixel
    next_piece = loop.next_piece
    scratch = loop.scratch
    n_ours = out_cycles.shape[0]
    counts = state.counts
    served = state.served
    first_instance = machine.instance_of[0]
    allocate0 = geometry.write_allocate[0]
    first_shift = np.uint64(geometry.line_shift)
    fast_reads = prefetchers is None and not logging  # every access trains prefetchers; a log takes each one

    ours_left = n_ours
    access_clock = 0
    logged = 0
    while ours_left > 0:
        cpu = lowest_clock_cpu(cpu_clock, system.active)
        if cpu < 0:
            break
        clock = cpu_clock[cpu]
        turn_start = clock
        thread = thread_of[cpu]
        process = system.running[cpu]
        if next_piece[cpu] < 0:  # between pixels: the operating system decides
            process, clock = decide(system, queues, cpu, clock, n_ours)
            if process < 0:
                continue
            if process >= n_ours:
                start = background_slice(system, queues, background, process, n_ours, cpu, clock)
                for i in range(footprint_lines):  # one turn: the slice's reads at once
                    address = np.uint64((start + i) << line_shift)
                    access_clock += 1
                    if prefetchers is not None:  # a branch numba prunes when compiling for None
                        _, access_clock = prefetching_access(thread, address, False, 0, 0, geometry, machine, state,
                                                             access_clock, prefetchers)
                    else:
                        shared_access(thread, address, False, 0, 0, geometry, machine, state, access_clock, scratch)
                    if logging:
                        logged = _log(out, logged, address, thread, BACKGROUND_READ)
                continue
            place(system, out.placement, process, cpu)

        finished = False
        offset = np.uint64(process + 1) * span
        instance0 = first_instance[thread]
        first_level = FirstLevel(state.tags, state.stamps, geometry.offset[0] + instance0 * machine.level_ways[0],
                                 geometry.set_mask[0], geometry.n_sets[0], geometry.ways[0],
                                 geometry.policy[0] == LRU, first_shift)
        # A line this thread's previous access of the turn left in its first
        # level, as its set's most recent entry (-1: none).
        previous_line = np.int64(-1)
        while True:
            if next_piece[cpu] < 0:  # the next pixel
                handed_before = system.next_task[0]
                pixel, clock = next_pixel(system, schedule, out, process, cpu, clock)
                for _ in range(system.next_task[0] - handed_before):  # each hand-out: the counter's atomic update
                    access_clock += 1
                    if prefetchers is not None:
                        level_served, access_clock = prefetching_access(thread, counter, True, COUNTER_BYTES,
                                                                        AUXILIARY_KIND, geometry, machine, state,
                                                                        access_clock, prefetchers)
                    else:
                        level_served = shared_access(thread, counter, True, COUNTER_BYTES, AUXILIARY_KIND, geometry,
                                                     machine, state, access_clock, scratch)
                    if logging:
                        logged = _log(out, logged, counter, thread, COUNTER_ACCESS)
                    _count_access(accesses, process, level_served, True)
                    wait = latency[level_served]
                    clock += wait
                    out_cycles[process, DISPATCH_CYCLES] += wait
                    slice_used[cpu] += wait
                    previous_line = np.int64(-1)
                if pixel < 0:
                    finished = True
                    break
                cpu_pixel[cpu] = pixel
                first = piece_offsets[pixel]
                n_pieces = piece_offsets[pixel + 1] - first
                next_piece[cpu] = first
                out_cycles[process, COMPUTE_CYCLES] += compute[pixel]
                if n_pieces > 0:
                    compute_share[cpu] = compute[pixel] / n_pieces
                else:
                    clock += compute[pixel]
                    slice_used[cpu] += compute[pixel]
            pixel = cpu_pixel[cpu]
            stop = piece_offsets[pixel + 1]
            k = next_piece[cpu]
            share = compute_share[cpu]
            memory = 0.0
            advance = 0.0
            if mapping_pixels:  # the process's misses before, in the pixel's row; the change after
                _add_misses(pixel_misses, pixel, accesses, process, -1)
            while k < stop and clock + advance - turn_start < interleave_cycles:
                if fast_reads:  # the reads that hit the first level, in a loop of their own
                    k, advance, memory, access_clock, previous_line, hits = first_level_reads(
                        pieces, k, stop, first_level, TurnPace(clock, turn_start, interleave_cycles, share,
                                                                   latency[0], offset),
                        counts[0, instance0, :, HITS], (advance, memory, access_clock, previous_line))
                    served[thread, 0] += hits
                    accesses[process, 0, READ_HITS] += hits
                    if k >= stop or clock + advance - turn_start >= interleave_cycles:
                        break
                address = piece_addresses[k]
                word = piece_words[k]
                if word & PRIVATE_BIT:
                    address += offset
                is_write = (word & WRITE_BIT) != 0
                kind = np.int64((word >> KIND_SHIFT) & KIND_MASK)
                size = np.int64(word & SIZE_MASK) + 1
                line0 = np.int64(address >> first_shift)
                access_clock += 1
                if prefetchers is not None:  # every access trains the prefetchers: no shortcut
                    level_served, access_clock = prefetching_access(thread, address, is_write, size, kind, geometry,
                                                                    machine, state, access_clock, prefetchers)
                elif line0 == previous_line and not is_write:
                    # a read hit that changes nothing but the counts (nothing else ran since)
                    counts[0, instance0, kind, HITS] += 1
                    served[thread, 0] += 1
                    level_served = 0
                else:
                    level_served = shared_access(thread, address, is_write, size, kind, geometry, machine, state,
                                                 access_clock, scratch)
                previous_line = line0 if (allocate0 or not is_write) else np.int64(-1)
                if logging:
                    logged = _log(out, logged, address, thread, k)
                _count_access(accesses, process, level_served, is_write)
                cycles = latency[0] if is_write else latency[level_served]
                memory += cycles
                advance += share + cycles
                k += 1
            if mapping_pixels:
                _add_misses(pixel_misses, pixel, accesses, process, 1)
            out_cycles[process, MEMORY_CYCLES] += memory
            clock += advance
            slice_used[cpu] += advance
            next_piece[cpu] = k
            if k < stop:
                break  # the turn is over inside the pixel
            next_piece[cpu] = -1
            back, finished = after_pixel(system, schedule, queues, process, cpu)
            if back or clock - turn_start >= interleave_cycles:
                break
        if finished:
            finish(system, out, process, cpu, clock)
            ours_left -= 1
        cpu_clock[cpu] = clock
    out.log_length[0] = logged
    return access_clock


@njit(cache=True, inline="always")
def _log(out, logged, address, thread, piece):
    """Log one access at entry ``logged`` of ``out``'s log; the next entry."""
    out.log_addresses[logged] = address
    out.log_threads[logged] = thread
    out.log_pieces[logged] = piece
    return logged + 1


@njit(cache=True, inline="always")
def _add_misses(pixel_misses, pixel, accesses, process, sign):
    """Add ``sign`` times ``process``'s read and write misses at each level so far to ``pixel``'s row."""
    for level in range(pixel_misses.shape[1]):
        pixel_misses[pixel, level] += sign * (accesses[process, level, READ_MISSES]
                                              + accesses[process, level, WRITE_MISSES])


@njit(cache=True, inline="always")
def _count_access(accesses, process, level_served, is_write):
    """Count one access of ``process`` served by ``level_served`` (the level count: memory): a miss at
    every level above, a hit there."""
    hit_column = WRITE_HITS if is_write else READ_HITS
    for level in range(level_served):
        accesses[process, level, hit_column + 1] += 1
    if level_served < accesses.shape[1]:
        accesses[process, level_served, hit_column] += 1


__all__ = ["BACKGROUND_READ", "COUNTER_ACCESS", "SharedMachine", "SharedOutputs", "cpu_threads",
           "run_shared_schedule"]
