"""The event loop on private caches: every mapping on every scheduler, each CPU with caches of its own.

:func:`run_schedule` applies the operating system's rules of
:mod:`coherence.os_rules` (run queues, time slices, background slices,
context switches, event order) and replays each pixel's records on the
caches of the CPU that runs it:

- **Caches stay with the CPU.** A process that moves starts on the caches
  its new CPU's previous processes left. Cache counters are kept per process.
- **Data TLB** (optional). Each CPU has one; every access, ours and the
  background's, is looked up in the TLB of the CPU it runs on, and a miss of
  ours costs a fixed penalty on top of its memory cycles.

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
from coherence.os_rules import (COMPUTE_CYCLES, MEMORY_CYCLES, after_pixel, background_slice, decide, finish,
                                lowest_clock_cpu, next_pixel, os_state, place)
from coherence.page_placement import translate_stream
from coherence.record_lines import FILL_AHEAD, line_span_bound, record_lines_and_writes

# Line accesses a run's pixel buffer is made to hold at the start (36 MB with
# their write flags) before it knows a pixel needs more.
MAX_PIXEL_LINES = 1 << 22



class CpuTlbs(NamedTuple):
    """One data TLB per CPU, its counters per process (a TLB, like the caches, stays with its CPU).

    Attributes
    ----------
    enabled : bool
        False: no TLB (the arrays are placeholders and never read).
    geometry : cachesim.tlb.TlbGeometry
    pages, stamps : ndarray of int64, shape (C, E)
        Each CPU's entries (:class:`cachesim.tlb.TlbArrays` fields).
    cursor : ndarray of int64, shape (C, N_CURSOR + HINTS)
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



@njit(cache=True, inline="always")
def _tlb_misses(tlbs, cpu, process, addresses, skip_mask):
    # look the addresses up in the CPU's TLB, counting for the process
    if not tlbs.enabled:
        return 0
    return T.tlb_lookup(addresses, tlbs.geometry,
                        T.TlbArrays(tlbs.pages[cpu], tlbs.stamps[cpu], tlbs.cursor[cpu], tlbs.counts[process]),
                        skip_mask)


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
    # certain first-level read hits taken out of the shared lines, counted in their low bits; the TLB then
    # looks up every access in the pixel's page runs
    skip_mask = reads.lines.skip_mask if shared else 0
    page_offsets = reads.lines.page_offsets
    page_runs = reads.lines.page_runs
    run_mask = (1 << reads.lines.page_shift) - 1
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
        cpu = lowest_clock_cpu(cpu_clock, system.active)
        if cpu < 0:
            break
        # A decision point: a free CPU, or a slice that ended.
        process, clock = decide(system, queues, cpu, cpu_clock[cpu], n_ours)
        if process < 0:
            continue
        if process >= n_ours:
            start = background_slice(system, queues, background, process, n_ours, cpu, clock)
            cache = K.CacheArrays(tags[cpu], stamps[cpu], counts[process])
            if skip_background:  # fresh lines: the state after them is known without walking them
                cache_clock[cpu] = skip_fresh_lines(start, footprint_lines, geometry, cache, cache_clock[cpu])
                if tlbs.enabled:  # and the TLB looks up each page once, counting its other lines as repeats
                    n_runs = _fresh_page_runs(start, footprint_lines, line_shift, tlbs.geometry.page_shift, buffer)
                    _tlb_misses(tlbs, cpu, process, buffer[:n_runs], (1 << tlbs.geometry.page_shift) - 1)
            else:
                for i in range(footprint_lines):
                    buffer[i] = np.uint64((start + i) << line_shift)
                if place_background:
                    b = process - n_ours
                    translate_stream(buffer, footprint_lines, b, first_line[b] << line_shift, background_pages)
                cache_clock[cpu] = K.simulate_into(buffer[:footprint_lines], geometry, cache, cache_clock[cpu],
                                                   served, record_served, work)
                _tlb_misses(tlbs, cpu, process, buffer[:footprint_lines], 0)
            continue

        place(system, out_placement, process, cpu)
        cache = K.CacheArrays(tags[cpu], stamps[cpu], counts[process])
        process_counts = counts[process]
        finished = False
        while True:
            pixel, clock = next_pixel(system, schedule, out, process, cpu, clock)
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
            if skip_mask:
                cache_clock[cpu] = K.simulate_skips_into(addresses, flags if n_writes else no_writes, skip_mask,
                                                         geometry, cache, cache_clock[cpu], work)
            else:
                cache_clock[cpu] = K.simulate_writes_into(addresses, flags if n_writes else no_writes, geometry,
                                                          cache, cache_clock[cpu], served, record_served, work)
            if record_pixel_misses:
                for level in range(n_levels):
                    pixel_misses[pixel, level] = process_counts[level, K.MISSES] - pixel_misses[pixel, level]
            memory = _memory_cycles(process_counts, hits_before, misses_before, latency) + n_writes * latency[0]
            if skip_mask:
                memory += _tlb_misses(tlbs, cpu, process, page_runs[page_offsets[pixel]:page_offsets[pixel + 1]],
                                      run_mask) * tlb_miss_cycles
            else:
                memory += _tlb_misses(tlbs, cpu, process, addresses, 0) * tlb_miss_cycles
            cycles = compute[pixel] + memory
            out_cycles[process, COMPUTE_CYCLES] += compute[pixel]
            out_cycles[process, MEMORY_CYCLES] += memory
            clock += cycles
            slice_used[cpu] += cycles
            stop, finished = after_pixel(system, schedule, queues, process, cpu)
            if stop:
                break
        if finished:
            finish(system, out, process, cpu, clock)
            ours_left -= 1
        cpu_clock[cpu] = clock



@njit(cache=True, inline="always")
def _fresh_page_runs(first_line, n_lines, line_shift, page_shift, runs):
    """Write the page runs (:attr:`coherence.pixel_lines.PixelLines.page_runs`) of the consecutive lines
    ``first_line .. first_line + n_lines - 1`` of ``2**line_shift`` bytes to ``runs``; returns how many.
    The runs are one per page: a page's lines are fewer than its bytes, which its run's count field holds."""
    lines_per_page = np.int64(1) << (page_shift - line_shift)
    last_line = first_line + n_lines - 1
    n_runs = 0
    for page in range(first_line >> (page_shift - line_shift), (last_line >> (page_shift - line_shift)) + 1):
        first = max(first_line, page * lines_per_page)
        last = min(last_line, (page + 1) * lines_per_page - 1)
        runs[n_runs] = np.uint64((page << page_shift) + (last - first))
        n_runs += 1
    return n_runs


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
