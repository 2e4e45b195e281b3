"""A slow, obvious model of the schedule on shared cache levels, to check coherence.shared_schedule.

Written from the rules in coherence.shared_schedule's and coherence.os_rules'
docstrings with Python lists and deques; every access goes through
reference_multicore_prefetch.ReferenceThreads (explicit ways with ghosts, one
instance per group of hardware threads sharing a level; no prefetcher here).

- The scheduler's CPU ``c`` is hardware thread ``(c % cores) * smt + c // cores``.
- The CPU whose clock is lowest (ties: lowest index) takes a turn. Between two
  pixels the operating system decides first (free CPU or slice over: the queue's
  head, the old process to the tail; a switch to another process costs
  ``switch_cycles``; a background process reads its slice's lines at once and
  takes a whole quantum, one turn).
- In a turn the process makes its pixel's accesses until the clock has advanced
  by Q since the turn began or the pixel ends; each access costs the pixel's
  compute cycles divided by its accesses plus its latency (a read: the level that
  served it, memory's if none; a write: the first level's). A pixel without
  accesses takes its compute cycles at once. After a pixel: a dynamic task that
  ended, a static process with nothing left, a slice over or Q reached end the turn.
- Private kinds of process ``p`` lie at their layout address plus ``(p + 1) * span``.
- Every task a dynamic process takes from the queue is a write of the task counter (4 bytes of the
  auxiliary kind at coherence.thread_streams.counter_address) at the hand-out; it waits for the level
  that served it (memory's if none), counted as dispatch cycles and among the process's accesses.

Compute cycles in the tests are chosen so that every cost is a whole number of
cycles: sums are then exact in any order and the clocks must agree exactly.
"""
from collections import deque

import numpy as np

from coherence.shared_schedule import COUNTER_ACCESS
from coherence.thread_streams import COUNTER_BYTES, counter_address, record_pieces
from reference_multicore_prefetch import ReferenceThreads
from reference_scheduler import ReferenceOS
from tracer.trace.records import AUXILIARY_KIND


def pixel_accesses(trace, placed, pixel, process, line_size):
    """Pixel ``pixel``'s accesses made by ``process``: (address, bytes, kind, write) per line a record spans."""
    rows = slice(int(trace.pixel_offsets[pixel]), int(trace.pixel_offsets[pixel + 1]))
    records = np.asarray(trace.records)[rows]
    stream = record_pieces(records, np.full(records.size, process, dtype=np.int64), placed, line_size)
    return [(int(a), int(s), int(k), bool(w))
            for a, s, k, w in zip(stream.addresses, stream.sizes, stream.kinds, stream.writes)]


def reference_shared_schedule(trace, distribution, machine, placed, compute, os_machine, interleave_cycles):
    """Per-process results, the machine's counts and the order of every access of one run.

    Parameters
    ----------
    trace, distribution, placed
        As :func:`coherence.shared_run.simulate_shared_run` takes them.
    machine : cachesim.sharing.SharedHierarchy
    compute : sequence of float, shape (P,)
    os_machine : coherence.simulation.Machine
    interleave_cycles : float

    Returns
    -------
    dict
        ``compute``, ``memory``, ``dispatch``, ``finish`` (per process), ``cpu``,
        ``migrations``, ``task_owner``, ``accesses`` (n, L, 4: read hits, read misses,
        write hits, write misses), ``log`` (list of (address, thread, pixel, index in the
        pixel) in the order the machine served them, pixel -1 for a background read and
        COUNTER_ACCESS for a hand-out's write of the task counter: the
        turn order), ``pixel_misses`` (P, L: the misses of each pixel's own accesses per level, an
        access served by level ``l`` missing at every level above; counter writes belong to no pixel),
        ``reference`` (the ReferenceThreads: ``counts``, ``served``).
    """
    n = distribution.n_processes
    levels = machine.hierarchy.levels
    n_levels = len(levels)
    latency = [level.latency for level in levels] + [machine.hierarchy.memory_latency]
    line_size = levels[0].line_size
    q = interleave_cycles
    caches = ReferenceThreads(machine)
    system = ReferenceOS(distribution, os_machine, line_size)

    n_cpus = os_machine.n_cpus
    thread_of = [(c % machine.n_cores) * machine.smt + c // machine.n_cores for c in range(n_cpus)]
    cpus = [{"clock": 0.0, "running": None, "last": None, "used": 0.0, "active": True,
             "pixel": None, "pending": None, "share": 0.0} for _ in range(n_cpus)]
    result = system.result()
    result["accesses"] = np.zeros((n, n_levels, 4), dtype=np.int64)
    result["log"] = []
    result["pixel_misses"] = np.zeros((trace.width * trace.height, n_levels), dtype=np.int64)
    finished = [False] * n

    def access(thread, address, size, kind, write):
        """One access through the thread's instances; the level that served it (L: memory)."""
        before = caches.served[thread].copy()
        caches.access(address, thread, write, kind, address, address + size)
        return int(np.flatnonzero(caches.served[thread] - before)[0])

    def count(p, served, write):
        """Process ``p``'s access served by level ``served``: a miss above, a hit there."""
        column = 2 if write else 0
        for level in range(min(served + 1, n_levels)):
            result["accesses"][p, level, column + (level != served)] += 1
        return latency[0] if write else latency[served]

    counter = counter_address(placed)

    while not all(finished):
        cpu = system.lowest_clock_cpu(cpus)
        if cpu is None:
            break
        state = cpus[cpu]
        thread = thread_of[cpu]
        turn_start = state["clock"]
        p = state["running"]
        if state["pending"] is None:  # between pixels: the operating system decides
            p = system.decide(cpu, state)
            if p is None:
                continue
            if p >= n:
                for line in system.background_slice(p, state):
                    access(thread, line * line_size, 0, 0, False)
                    result["log"].append((line * line_size, thread, -1, -1))
                continue
            system.place(p, cpu, result)
        done = False
        while True:
            if state["pending"] is None:  # the next pixel
                waiting = len(system.handout) if distribution.dynamic else 0
                pixel = system.next_pixel(p, state, result)
                for _ in range(waiting - (len(system.handout) if distribution.dynamic else 0)):
                    served = access(thread, counter, COUNTER_BYTES, AUXILIARY_KIND, True)
                    result["log"].append((counter, thread, COUNTER_ACCESS, -1))
                    count(p, served, True)
                    state["clock"] += latency[served]  # the atomic update waits for its line
                    state["used"] += latency[served]
                    result["dispatch"][p] += latency[served]
                if pixel is None:
                    done = True
                    break
                pieces = pixel_accesses(trace, placed, pixel, p, line_size)
                state["pixel"], state["pending"] = pixel, deque(enumerate(pieces))
                result["compute"][p] += compute[pixel]
                if pieces:
                    state["share"] = compute[pixel] / len(pieces)
                else:
                    state["clock"] += compute[pixel]
                    state["used"] += compute[pixel]
            while state["pending"] and state["clock"] - turn_start < q:
                index, (address, size, kind, write) = state["pending"].popleft()
                served = access(thread, address, size, kind, write)
                result["log"].append((address, thread, state["pixel"], index))
                result["pixel_misses"][state["pixel"], :served] += 1
                cycles = count(p, served, write)
                result["memory"][p] += cycles
                state["clock"] += state["share"] + cycles
                state["used"] += state["share"] + cycles
            if state["pending"]:
                break  # the turn ends inside the pixel
            state["pending"] = None
            stop, done = system.after_pixel(p, state)
            if stop or state["clock"] - turn_start >= q:
                break
        if done:
            finished[p] = True
            result["finish"][p] = state["clock"]
            state["running"] = None
    result["task_owner"] = system.task_owner
    result["reference"] = caches
    return result
