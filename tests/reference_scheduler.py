"""A slow, obvious model of the simulated operating system, to check coherence.scheduler.

Written from the rules in coherence.scheduler's docstring with Python lists,
deques and the dict-based reference caches of tests/reference_cache.py: one
cache per CPU, FIFO run queues, a loop that always moves the CPU whose clock
is lowest (lowest index on ties). It returns the same per-process numbers as
``simulate_run``; with integer cycle costs both must agree exactly.
"""
from collections import deque

import numpy as np

from reference_cache import ReferenceLevel
from reference_tlb import ReferenceTlb
from tracer.trace.records import WRITE_FLAG

BACKGROUND_BASE = 1 << 56
BACKGROUND_SPACING = 1 << 48
BACKGROUND_OFFSET_RANGE = 1 << 40


class ReferenceCaches:
    """One CPU's hierarchy, kept between calls (reference_simulate's rules)."""

    def __init__(self, hierarchy):
        self.hierarchy = hierarchy
        self.levels = [ReferenceLevel(level, index) for index, level in enumerate(hierarchy.levels)]
        self.clock = 0

    def access(self, address, write=False):
        """Run one byte access through the levels; return the level that served it (L: memory).

        A write fills only the levels that allocate on writes (``write_allocate``).
        """
        self.clock += 1
        levels = self.levels
        lines = [address // level.line_size for level in levels]
        served = len(levels)
        for index, level in enumerate(levels):
            if level.lookup(lines[index]):
                served = index
                break
        if served == 0:
            return served
        if self.hierarchy.inclusion == "exclusive":
            if served < len(levels):
                levels[served].remove(lines[served])
            line = lines[0]
            for level in levels:
                line = level.insert(line, self.clock)
                if line is None:
                    break
            return served
        for index in range(served - 1, -1, -1):
            if write and not self.hierarchy.levels[index].write_allocate:
                continue
            evicted = levels[index].insert(lines[index], self.clock)
            if evicted is not None and self.hierarchy.inclusion == "inclusive":
                for upper in range(index):
                    ratio = levels[index].line_size // levels[upper].line_size
                    for sub in range(evicted * ratio, (evicted + 1) * ratio):
                        levels[upper].remove(sub)
        return served


def reference_schedule(trace, distribution, hierarchy, placed, compute, machine):
    """Per-process results of one run, as plain Python.

    Returns
    -------
    dict
        ``user``, ``compute``, ``memory``, ``dispatch``, ``finish`` (lists of
        float per process), ``hits``/``misses`` (lists of per-level lists),
        ``cpu`` (first CPU), ``migrations``, ``task_owner`` (list),
        ``real`` (float), ``pixel_misses`` (a list per pixel of its misses per
        level, reads and writes) and, with a TLB, ``tlb_accesses``/``tlb_misses``
        (lists per process).

    A hierarchy's data TLB is one per CPU, like its caches: every access,
    ours and the background's, is looked up in the TLB of the CPU it runs
    on, and a miss of ours adds the TLB's ``miss_cycles`` to its memory.
    """
    n = distribution.n_processes
    n_background = machine.background_load
    levels = hierarchy.levels
    n_levels = len(levels)
    latency = [level.latency for level in levels] + [hierarchy.memory_latency]
    line_size = min(level.line_size for level in levels)
    quantum = machine.quantum_cycles

    tasks = [list(distribution.task(t)) for t in range(distribution.n_tasks)]
    task_owner = [-1] * distribution.n_tasks
    if distribution.dynamic:
        handout = deque(range(distribution.n_tasks))
        own = None
    else:
        own = [deque(t for t in range(distribution.n_tasks) if distribution.task_process[t] == p)
               for p in range(n)]
        task_owner = [int(p) for p in distribution.task_process]
    held = [deque() for _ in range(n)]
    remaining = [deque() for _ in range(n)]  # pixels left of the current task
    has_task = [False] * n

    # Which queue each process waits in; background processes are n .. n+B-1.
    if machine.scheduler == "static":
        queue_of = {p: machine.cpu_of(n)[p] for p in range(n)}
        queue_of.update({n + b: (n + b) % machine.n_cpus for b in range(n_background)})
    else:
        queue_of = {p: 0 for p in range(n + n_background)}
    queues = {}
    for p in [n + b for b in range(n_background)] + list(range(n)):
        queues.setdefault(queue_of[p], deque()).append(p)

    rng = np.random.default_rng(machine.background_seed)
    offsets = rng.integers(0, BACKGROUND_OFFSET_RANGE // line_size, n_background, dtype=np.int64)
    stream_line = [(BACKGROUND_BASE + BACKGROUND_SPACING * b) // line_size + int(offsets[b])
                   for b in range(n_background)]
    footprint_lines = -(-machine.background_footprint // line_size)

    n_cpus = machine.n_cpus
    tlb = hierarchy.tlb
    cpus = [{"clock": 0.0, "running": None, "last": None, "used": 0.0, "active": True,
             "caches": ReferenceCaches(hierarchy),
             "tlb": ReferenceTlb(tlb.entries, tlb.page_size, tlb.policy) if tlb else None} for _ in range(n_cpus)]
    tlb_accesses = [0] * n
    tlb_misses = [0] * n

    def queue_index(cpu):
        return cpu if machine.scheduler == "static" else 0

    result = {key: [0.0] * n for key in ("compute", "memory", "dispatch", "finish")}
    result["hits"] = [[0] * n_levels for _ in range(n)]
    result["misses"] = [[0] * n_levels for _ in range(n)]
    result["pixel_misses"] = [[0] * n_levels for _ in range(trace.width * trace.height)]
    result["cpu"] = [-1] * n
    result["migrations"] = [0] * n
    last_cpu = [None] * n
    finished = [False] * n

    def next_task(p):
        """(task or None, cycles waited); empty tasks are skipped."""
        waited = 0.0
        while True:
            if not distribution.dynamic:
                task = own[p].popleft() if own[p] else None
            elif held[p]:
                task = held[p].popleft()
            elif handout:
                task = handout.popleft()
                waited += distribution.dispatch_cycles
            else:
                task = None
            if task is None:
                return None, waited
            if distribution.dynamic:
                while len(held[p]) < distribution.take_ahead and handout:
                    ahead = handout.popleft()
                    held[p].append(ahead)
                    task_owner[ahead] = p
            task_owner[task] = p
            if tasks[task]:
                return task, waited

    def pixels_left(p):
        if remaining[p]:
            return True
        if distribution.dynamic:
            return True  # unknown until the master answers
        return any(tasks[t] for t in own[p])

    while not all(finished):
        candidates = [c for c in range(n_cpus) if cpus[c]["active"]]
        if not candidates:
            break
        cpu = min(candidates, key=lambda c: (cpus[c]["clock"], c))
        state = cpus[cpu]
        queue = queues.setdefault(queue_index(cpu), deque())
        p = state["running"]
        if p is None or (quantum > 0 and state["used"] >= quantum):
            if queue:
                if p is not None:
                    queues[queue_of[p]].append(p)
                p = queue.popleft()
            elif p is None:
                state["active"] = False
                continue
            if state["last"] is not None and state["last"] != p:
                state["clock"] += machine.switch_cycles
            state["running"], state["last"], state["used"] = p, p, 0.0
        if p >= n:
            ours_waiting = any(q < n for q in queue)
            if not ours_waiting and (machine.scheduler == "static" or not queue):
                state["active"] = False
                continue
            b = p - n
            for line in range(stream_line[b], stream_line[b] + footprint_lines):
                state["caches"].access(line * line_size)
                if tlb:
                    state["tlb"].lookup(line * line_size)
            stream_line[b] += footprint_lines
            state["clock"] += quantum
            state["used"] = quantum
            continue
        if last_cpu[p] is None:
            result["cpu"][p] = cpu
        elif last_cpu[p] != cpu:
            result["migrations"][p] += 1
        last_cpu[p] = cpu
        done = False
        while True:
            if not remaining[p]:
                task, waited = next_task(p)
                state["clock"] += waited
                state["used"] += waited
                result["dispatch"][p] += waited
                if task is None:
                    done = True
                    break
                remaining[p] = deque(tasks[task])
            pixel = remaining[p].popleft()
            memory = 0.0
            records = trace.records[trace.pixel_offsets[pixel]:trace.pixel_offsets[pixel + 1]]
            for address, write in zip(placed.addresses(records, line_size), _line_writes(records, placed, line_size)):
                served = state["caches"].access(int(address), write)
                for level in range(min(served + 1, n_levels)):
                    if level == served:
                        result["hits"][p][level] += 1
                    else:
                        result["misses"][p][level] += 1
                        result["pixel_misses"][pixel][level] += 1
                memory += latency[0] if write else latency[served]  # a store goes to the write buffer
                if tlb:
                    tlb_accesses[p] += 1
                    if not state["tlb"].lookup(int(address)):
                        tlb_misses[p] += 1
                        memory += tlb.miss_cycles
            result["compute"][p] += compute[pixel]
            result["memory"][p] += memory
            state["clock"] += compute[pixel] + memory
            state["used"] += compute[pixel] + memory
            if not remaining[p]:
                if distribution.dynamic:
                    break  # ask the master when this CPU moves next
                if not pixels_left(p):
                    done = True
                    break
            if quantum > 0 and state["used"] >= quantum:
                break
        if done:
            finished[p] = True
            result["finish"][p] = state["clock"]
            state["running"] = None
    result["user"] = [result["compute"][p] + result["memory"][p] + result["dispatch"][p] for p in range(n)]
    result["task_owner"] = task_owner
    if tlb:
        result["tlb_accesses"], result["tlb_misses"] = tlb_accesses, tlb_misses
    result["real"] = max(result["finish"])
    return result


def _line_writes(records, placed, line_size):
    """Each line access's write flag: a written record's flag, once per line it spans."""
    flags = []
    for record in records:
        lines = len(placed.addresses(np.array([record], dtype=np.uint32), line_size))
        flags += [bool(int(record) & WRITE_FLAG)] * lines
    return flags
