"""A slow, obvious model of the simulated operating system, to check coherence.scheduler.

Written from the rules in the docstrings of coherence.os_rules and coherence.scheduler with Python lists,
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


class ReferenceOS:
    """The operating system's rules that do not touch caches: tasks and hand-outs, run queues, the decision at
    a free CPU or a slice end, background streams and where each process ran."""

    def __init__(self, distribution, machine, line_size):
        self.distribution = distribution
        self.machine = machine
        n = self.n = distribution.n_processes
        n_background = machine.background_load
        self.tasks = [list(distribution.task(t)) for t in range(distribution.n_tasks)]
        self.task_owner = [-1] * distribution.n_tasks
        if distribution.dynamic:
            self.handout = deque(range(distribution.n_tasks))
            self.own = None
        else:
            self.own = [deque(t for t in range(distribution.n_tasks) if distribution.task_process[t] == p)
                        for p in range(n)]
            self.task_owner = [int(p) for p in distribution.task_process]
        self.held = [deque() for _ in range(n)]
        self.remaining = [deque() for _ in range(n)]  # pixels left of the current task
        # Which queue each process waits in; background processes are n .. n+B-1.
        if machine.scheduler == "static":
            self.queue_of = {p: int(machine.cpu_of(n)[p]) for p in range(n)}
            self.queue_of.update({n + b: (n + b) % machine.n_cpus for b in range(n_background)})
        else:
            self.queue_of = {p: 0 for p in range(n + n_background)}
        self.queues = {}
        for p in [n + b for b in range(n_background)] + list(range(n)):
            self.queues.setdefault(self.queue_of[p], deque()).append(p)
        rng = np.random.default_rng(machine.background_seed)
        offsets = rng.integers(0, BACKGROUND_OFFSET_RANGE // line_size, n_background, dtype=np.int64)
        self.stream_line = [(BACKGROUND_BASE + BACKGROUND_SPACING * b) // line_size + int(offsets[b])
                            for b in range(n_background)]
        self.footprint_lines = -(-machine.background_footprint // line_size)
        self.last_cpu = [None] * n

    def result(self):
        """A fresh result dict: cycle lists, first CPU and migrations per process."""
        result = {key: [0.0] * self.n for key in ("compute", "memory", "dispatch", "finish")}
        result["cpu"] = [-1] * self.n
        result["migrations"] = [0] * self.n
        return result

    def next_task(self, p):
        """(task or None, cycles waited); empty tasks are skipped."""
        distribution = self.distribution
        waited = 0.0
        while True:
            if not distribution.dynamic:
                task = self.own[p].popleft() if self.own[p] else None
            elif self.held[p]:
                task = self.held[p].popleft()
            elif self.handout:
                task = self.handout.popleft()
                waited += distribution.dispatch_cycles
            else:
                task = None
            if task is None:
                return None, waited
            if distribution.dynamic:
                while len(self.held[p]) < distribution.take_ahead and self.handout:
                    ahead = self.handout.popleft()
                    self.held[p].append(ahead)
                    self.task_owner[ahead] = p
            self.task_owner[task] = p
            if self.tasks[task]:
                return task, waited

    def next_pixel(self, p, state, result):
        """Process ``p``'s next pixel, a new task asked for first if its task is done (the wait added to the
        CPU's clock and slice and to its dispatch cycles); None when it has no pixel left."""
        if not self.remaining[p]:
            task, waited = self.next_task(p)
            state["clock"] += waited
            state["used"] += waited
            result["dispatch"][p] += waited
            if task is None:
                return None
            self.remaining[p] = deque(self.tasks[task])
        return self.remaining[p].popleft()

    def after_pixel(self, p, state):
        """After a pixel of ``p``: (whether its CPU stops running it for now, whether it has finished). A
        dynamic task's end goes back to the event loop (the next hand-out in time order); so does a slice's."""
        if not self.remaining[p]:
            if self.distribution.dynamic:
                return True, False
            if not any(self.tasks[t] for t in self.own[p]):
                return True, True
        quantum = self.machine.quantum_cycles
        return quantum > 0 and state["used"] >= quantum, False

    @staticmethod
    def lowest_clock_cpu(cpus):
        """The active CPU whose clock is lowest (lowest index on ties), or None."""
        candidates = [c for c in range(len(cpus)) if cpus[c]["active"]]
        return min(candidates, key=lambda c: (cpus[c]["clock"], c)) if candidates else None

    def decide(self, cpu, state):
        """At a free CPU or a slice's end: the process the CPU runs now (switch cycles added to its clock), or
        None when the CPU goes idle for good."""
        machine = self.machine
        queue = self.queues.setdefault(cpu if machine.scheduler == "static" else 0, deque())
        p = state["running"]
        if p is None or (machine.quantum_cycles > 0 and state["used"] >= machine.quantum_cycles):
            if queue:
                if p is not None:
                    self.queues[self.queue_of[p]].append(p)
                p = queue.popleft()
            elif p is None:
                state["active"] = False
                return None
            if state["last"] is not None and state["last"] != p:
                state["clock"] += machine.switch_cycles
            state["running"], state["last"], state["used"] = p, p, 0.0
        if p >= self.n and not any(other < self.n for other in queue) and (
                machine.scheduler == "static" or not queue):
            state["active"] = False  # none of ours can reach this CPU again
            return None
        return p

    def background_slice(self, p, state):
        """The line numbers background process ``p``'s next slice reads; the slice takes its CPU's whole quantum."""
        state["clock"] += self.machine.quantum_cycles
        state["used"] = self.machine.quantum_cycles
        b = p - self.n
        first = self.stream_line[b]
        self.stream_line[b] += self.footprint_lines
        return range(first, first + self.footprint_lines)

    def place(self, p, cpu, result):
        """Record that process ``p`` runs on ``cpu`` (its first CPU, or a migration)."""
        if self.last_cpu[p] is None:
            result["cpu"][p] = cpu
        elif self.last_cpu[p] != cpu:
            result["migrations"][p] += 1
        self.last_cpu[p] = cpu


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
    levels = hierarchy.levels
    n_levels = len(levels)
    latency = [level.latency for level in levels] + [hierarchy.memory_latency]
    line_size = min(level.line_size for level in levels)
    system = ReferenceOS(distribution, machine, line_size)

    n_cpus = machine.n_cpus
    tlb = hierarchy.tlb
    cpus = [{"clock": 0.0, "running": None, "last": None, "used": 0.0, "active": True,
             "caches": ReferenceCaches(hierarchy),
             "tlb": ReferenceTlb(tlb.entries, tlb.page_size, tlb.policy) if tlb else None} for _ in range(n_cpus)]
    tlb_accesses = [0] * n
    tlb_misses = [0] * n

    result = system.result()
    result["hits"] = [[0] * n_levels for _ in range(n)]
    result["misses"] = [[0] * n_levels for _ in range(n)]
    result["pixel_misses"] = [[0] * n_levels for _ in range(trace.width * trace.height)]
    finished = [False] * n

    while not all(finished):
        cpu = system.lowest_clock_cpu(cpus)
        if cpu is None:
            break
        state = cpus[cpu]
        p = system.decide(cpu, state)
        if p is None:
            continue
        if p >= n:
            for line in system.background_slice(p, state):
                state["caches"].access(line * line_size)
                if tlb:
                    state["tlb"].lookup(line * line_size)
            continue
        system.place(p, cpu, result)
        done = False
        while True:
            pixel = system.next_pixel(p, state, result)
            if pixel is None:
                done = True
                break
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
            stop, done = system.after_pixel(p, state)
            if stop:
                break
        if done:
            finished[p] = True
            result["finish"][p] = state["clock"]
            state["running"] = None
    result["user"] = [result["compute"][p] + result["memory"][p] + result["dispatch"][p] for p in range(n)]
    result["task_owner"] = system.task_owner
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
