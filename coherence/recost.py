"""Re-costing a simulated run from its stored miss counts, without replaying it.

A run's cycles are a sum over its accesses and pixels: compute cycles (the
cost model's weights times the trace's counters), each level's read hits at
that level's latency, the last level's read misses at memory's, every write
at the first level's latency and every TLB miss at the TLB's penalty
(:mod:`coherence.scheduler`). When the counts themselves do not depend on
cycles, a change of cost alone is a new weighted sum of the same counts.

They do not depend on cycles exactly when no CPU that runs one of our
processes ever runs another process (:func:`fixed_schedule`):

- the distribution is static, or dynamic with one process (its hand-outs
  then all go to that process, in task order, whatever they cost);
- ``shared-queue`` scheduler: our processes plus the other users' fit the
  CPUs (``n + background_load <= n_cpus``): every process takes a CPU of its
  own at time 0 (one without pixels finishes at once and hands its CPU,
  untouched, to the next) and no run queue ever holds a process waiting
  for a CPU, so a slice's end changes nothing;
- ``static`` scheduler: our processes are pinned to distinct CPUs and no
  background process is pinned to one of them.

Then each of our processes renders its own pixels, in its own order, on
caches and a TLB no other process touches, from when it first gets its CPU
to its finish without a pause. Its counts are the same for every cost
model, latency and time slice, and its finish is its user time plus the
switches its CPU made before it (a cost fixed by the machine). One more
condition is checked on the run itself (:func:`recost_run`): every process
that has pixels takes more than zero cycles, before and after; one that
finished at time 0 would hand its CPU, warm, to the next in the queue.

Everything else (DB with more than one process, more processes than CPUs,
background load that time-slices with ours) is simulated again: a latency
changes when slices end and which process takes which DB block. A change to
the caches' geometry, the memory layout, the page placement, the
background (for a run whose schedule depends on cycles) or the trace is
never a cost change.

:class:`RunStore` keeps the runs of one trace between studies
(:class:`coherence.studies.Execution` ``store``) and counts which path each
run took.
"""
from __future__ import annotations

import hashlib
from concurrent.futures import Future
from dataclasses import asdict, dataclass, replace
from typing import NamedTuple

import numpy as np

from rtcommon.validate import InputError

__all__ = ["READ_HITS", "READ_MISSES", "WRITE_HITS", "WRITE_MISSES", "N_ACCESS_COLUMNS", "MissCounts", "ReplayKey",
           "fixed_schedule", "first_cpus", "recost_run", "RunStore", "CYCLE_COLUMNS", "LINES_KEPT",
           "COMPUTE_KEPT", "PLACED_KEPT", "BACKGROUND_FIELDS", "compute_digest"]

#: Columns of :attr:`MissCounts.accesses`: read hits and misses, write hits and misses.
READ_HITS, READ_MISSES, WRITE_HITS, WRITE_MISSES = 0, 1, 2, 3
N_ACCESS_COLUMNS = 4

#: Columns of a run's process table that depend on the costs; every other column is a count.
CYCLE_COLUMNS = ("tlb_cycles", "compute_cycles", "memory_cycles", "user_cycles", "user_seconds", "finish_cycles")

#: Placed layouts whose pixels' line addresses a :class:`RunStore` keeps (the most recently used ones).
LINES_KEPT = 2

#: Cost models' compute cycles per pixel a :class:`RunStore` keeps (the most recently used ones).
COMPUTE_KEPT = 2

#: Placed layouts (before their page placement) a :class:`RunStore` keeps, the most recently used ones: as
#: many as the memory images a study of one trace samples.
PLACED_KEPT = 3

#: Fields of :class:`coherence.simulation.Machine` that describe the other users' processes.
BACKGROUND_FIELDS = ("background_load", "background_footprint", "background_seed")


@dataclass(frozen=True)
class MissCounts:
    """What a run's cycles are made of, per process.

    Attributes
    ----------
    accesses : ndarray of int64, shape (n, L, N_ACCESS_COLUMNS)
        Per process and cache level (``hierarchy.levels`` order): columns
        :data:`READ_HITS`, :data:`READ_MISSES`, :data:`WRITE_HITS`,
        :data:`WRITE_MISSES`.
    tlb_misses : ndarray of int64, shape (n,)
        Data TLB misses per process (zero without a TLB).
    counters : ndarray of int64, shape (n, K)
        The trace's counters summed over each process's pixels.
    counter_names : tuple of str
        Names of the ``K`` counter columns.
    fixed_schedule : bool
        :func:`fixed_schedule` of the run's distribution and machine: the
        counts do not depend on cycles.
    """

    accesses: np.ndarray
    tlb_misses: np.ndarray
    counters: np.ndarray
    counter_names: tuple
    fixed_schedule: bool


def fixed_schedule(distribution, machine) -> bool:
    """Whether a run's counts do not depend on cycles (the rule of the module's docstring).

    Parameters
    ----------
    distribution : coherence.distribution.Distribution
    machine : coherence.simulation.Machine
    """
    return _fixed(bool(distribution.dynamic), int(distribution.n_processes), machine)


def _fixed(dynamic: bool, n: int, machine) -> bool:
    """:func:`fixed_schedule` of ``n`` processes, dynamic or static, on ``machine``."""
    if dynamic and n > 1:
        return False
    if machine.scheduler == "static":
        ours = machine.cpu_of(n)
        background = (n + np.arange(machine.background_load, dtype=np.int64)) % machine.n_cpus
        return bool(np.unique(ours).size == n and not np.isin(background, ours).any())
    return n + machine.background_load <= machine.n_cpus


def recost_run(run, hierarchy, cost):
    """``run`` with the cycles of ``hierarchy``'s latencies and TLB penalty and of ``cost``, from its counts.

    Parameters
    ----------
    run : coherence.simulation.Run
        Simulated with a hierarchy of the same levels, TLB and geometry
        (only latencies and the TLB's ``miss_cycles`` may differ).
    hierarchy : cachesim.Hierarchy
    cost : coherence.cost.CostModel

    Returns
    -------
    coherence.simulation.Run or None
        The run as :func:`~coherence.simulation.simulate_run` would give it
        with these costs (cycle columns of :data:`CYCLE_COLUMNS` and
        ``real_cycles`` recomputed, equal to a simulation's up to the order
        of floating-point additions; every count unchanged); None when the
        run cannot be re-costed (no stored counts, a schedule that depends
        on cycles, or a process with pixels at zero cycles), so that the
        caller simulates it.
    """
    counts = run.miss_counts
    if counts is None or not counts.fixed_schedule:
        return None
    n_levels = len(hierarchy.levels)
    if counts.accesses.shape[1] != n_levels or ("tlb_misses" in run.processes) != (hierarchy.tlb is not None):
        raise InputError(f"recost_run: the run was simulated on {counts.accesses.shape[1]} cache levels "
                         f"{'with' if 'tlb_misses' in run.processes else 'without'} a TLB; the hierarchy has "
                         f"{n_levels} {'with' if hierarchy.tlb is not None else 'without'} one")
    processes = run.processes
    has_pixels = processes["pixels"].to_numpy() > 0
    if (processes["user_cycles"].to_numpy()[has_pixels] <= 0).any():
        return None
    latency = np.array([level.latency for level in hierarchy.levels], dtype=np.float64)
    accesses = counts.accesses
    compute = counts.counters.astype(np.float64) @ cost.weights(counts.counter_names)
    memory = accesses[:, :, READ_HITS] @ latency + accesses[:, -1, READ_MISSES] * float(hierarchy.memory_latency)
    memory = memory + (accesses[:, 0, WRITE_HITS] + accesses[:, 0, WRITE_MISSES]) * latency[0]
    frame = processes.copy()
    if hierarchy.tlb is not None:
        tlb_cycles = counts.tlb_misses * float(hierarchy.tlb.miss_cycles)
        frame["tlb_cycles"] = tlb_cycles
        memory = memory + tlb_cycles
    dispatch = processes["dispatch_cycles"].to_numpy(dtype=np.float64)
    user = compute + memory + dispatch
    if (user[has_pixels] <= 0).any():
        return None
    frame["compute_cycles"] = compute
    frame["memory_cycles"] = memory
    frame["user_cycles"] = user
    frame["user_seconds"] = user / cost.clock_hz
    # the finish moves with the user time; what lies before it (switches) does not depend on costs
    frame["finish_cycles"] = processes["finish_cycles"].to_numpy() + (user - processes["user_cycles"].to_numpy())
    return replace(run, processes=frame, real_cycles=float(frame["finish_cycles"].max()))


def first_cpus(n_processes: int, machine) -> np.ndarray:
    """The CPU each of ``n_processes`` of ours starts on when the run has a fixed schedule, int64 (n,).

    Static scheduler: the CPU it is pinned to. Shared queue: the other
    users' processes enter the queue first and take CPUs ``0 .. B-1`` at
    time 0, ours the next ``n`` (all fit the CPUs).
    """
    if machine.scheduler == "static":
        return machine.cpu_of(n_processes)
    return machine.background_load + np.arange(n_processes, dtype=np.int64)


def _on_cpus(run, cpus):
    """``run`` with the ``cpu`` column ``cpus`` (unchanged when None or equal)."""
    if cpus is None or run.processes["cpu"].tolist() == list(cpus):
        return run
    return replace(run, processes=run.processes.assign(cpu=np.asarray(cpus, dtype=np.int64)))


class ReplayKey(NamedTuple):
    """What a run replays (:func:`coherence.studies.study` builds it): equal keys, equal runs.

    ``details`` holds the digests of each process's pixels (static) or of
    the tasks, their order and hand-out costs (dynamic).
    """

    dynamic: bool
    n_processes: int
    details: tuple


class RunStore:
    """Runs of one trace kept between studies, to re-cost or reuse instead of simulating.

    A run is stored under what decides its counts: the distribution's
    replay (see :func:`coherence.studies.study`), the cache hierarchy
    without its latencies and TLB penalty, the placed memory layout and the
    machine without its time slice; without the other users' footprint and
    seed when there are none; and without any of :data:`BACKGROUND_FIELDS`
    when the run has a fixed schedule (:func:`fixed_schedule`): the other
    users then run on CPUs of their own, and only the CPU each of our
    processes starts on depends on how many there are
    (:func:`first_cpus`, set on the run served). A later run with the
    same key is

    - *reused* as stored when its costs are identical too (latencies, TLB
      penalty, time slice, clock and every pixel's compute
      cycles): the simulation would be the same;
    - *re-costed* (:func:`recost_run`) when only costs differ and the stored
      run's schedule does not depend on cycles;
    - *simulated* otherwise, and stored in place of the earlier one.

    It also keeps the line addresses of every pixel
    (:func:`coherence.pixel_lines.pixel_lines`) of the last
    :data:`LINES_KEPT` placed layouts it was asked for: studies that differ
    in costs, latencies or the machine's schedule but place the trace alike
    read the same addresses (:meth:`pixel_lines`). And it keeps what
    studies of the trace work out alike: compute cycles per pixel of the
    last :data:`COMPUTE_KEPT` cost models (:meth:`compute_cycles`), each
    mapping's replay key per process count (:meth:`replay_of`) and the
    last :data:`PLACED_KEPT` memory layouts placed for the trace
    (:meth:`placed_layout`).

    Attributes
    ----------
    simulated, re_costed, reused : int
        Runs that took each path so far.
    """

    def __init__(self):
        self._runs = {}
        self._lines = {}  # placed layout's key -> PixelLines or None, least recently used first
        self._compute = {}  # cost weights -> (compute cycles per pixel, their digest), least recently used first
        self._replays = {}  # (id of a mapping, process count) -> (the mapping, what replay_of worked out)
        self._placed = {}  # (layout's repr, id of the scene) -> (the scene, placed layout, _records_digest)
        self._trace = None
        self.simulated = 0
        self.re_costed = 0
        self.reused = 0

    def bind(self, trace) -> None:
        """Serve ``trace``; a store refuses a second trace (its keys do not name the trace)."""
        if self._trace is None:
            self._trace = trace
        elif self._trace is not trace:
            raise InputError("RunStore: this store holds runs of another trace; use one store per trace")

    @staticmethod
    def keys_of(replay_keys, hierarchy, layout, machine, cost, compute_key: bytes) -> list:
        """Per run of one study (each of ``replay_keys``, a :class:`ReplayKey`): the key of what decides its
        counts, the key of its costs, and its processes' first CPUs (:func:`first_cpus` for a run with a
        fixed schedule, None for any other). ``compute_key`` is the :func:`compute_digest` of the study's
        compute cycles per pixel; the parts the runs share are worked out once."""
        levels = tuple(replace(level, latency=0.0) for level in hierarchy.levels)
        tlb = None if hierarchy.tlb is None else replace(hierarchy.tlb, miss_cycles=0.0)
        geometry = repr(replace(hierarchy, levels=levels, memory_latency=0.0, tlb=tlb, name=""))
        placed = repr(layout)
        machine_fields = {k: v for k, v in asdict(machine).items() if k != "quantum_cycles"}
        cost_key = (repr(hierarchy), float(machine.quantum_cycles), float(cost.clock_hz), compute_key)
        out = []
        for replay_key in replay_keys:
            n = int(replay_key.n_processes)
            fixed = _fixed(bool(replay_key.dynamic), n, machine)
            fields = machine_fields
            if fixed:  # the other users run on CPUs of their own
                fields = {k: v for k, v in fields.items() if k not in BACKGROUND_FIELDS}
                fields["fixed_schedule"] = True
            elif machine.background_load == 0:  # no other users: their footprint and seed do nothing
                fields = {k: v for k, v in fields.items() if k not in BACKGROUND_FIELDS[1:]}
            counts_key = (replay_key, geometry, placed, repr(fields))
            out.append((counts_key, cost_key, (tuple(first_cpus(n, machine).tolist()) if fixed else None)))
        return out

    def compute_cycles(self, trace, cost) -> tuple:
        """``cost``'s compute cycles of every pixel of ``trace`` (float64 (P,)) and their
        :func:`compute_digest`, worked out once per set of weights (they depend on nothing else; the last
        :data:`COMPUTE_KEPT` are kept)."""
        from tracer.trace.access import COUNTER_NAMES

        self.bind(trace)
        key = cost.weights(COUNTER_NAMES).tobytes()
        if key in self._compute:
            self._compute[key] = self._compute.pop(key)  # most recently used last
            return self._compute[key]
        while len(self._compute) >= COMPUTE_KEPT:
            self._compute.pop(next(iter(self._compute)))
        compute = cost.compute_cycles(trace.counters, COUNTER_NAMES)
        self._compute[key] = (compute, compute_digest(compute))
        return self._compute[key]

    def replay_of(self, trace, mapping, n_processes: int, work_out):
        """``work_out()`` (what a study needs of ``mapping``'s distribution of ``trace`` among
        ``n_processes``: its :class:`ReplayKey`, say), worked out once per mapping object and count: a
        mapping is a frozen recipe, so its distribution of one image is always the same."""
        self.bind(trace)
        key = (id(mapping), int(n_processes))
        kept = self._replays.get(key)
        if kept is None or kept[0] is not mapping:
            kept = (mapping, work_out())  # the mapping is kept alive with it: its id is not reused
            self._replays[key] = kept
        return kept[1]

    def serve(self, keys, hierarchy, cost):
        """How the run for ``keys`` (:meth:`keys_of`) is had without simulating it: a callable, or None (simulate).

        The callable returns the run, reused or re-costed, waiting for the
        stored run if it is still being simulated (:meth:`add` of a
        future), or None when the stored run turns out not to be
        re-costable (a process with pixels at zero cycles): the caller then
        simulates it. Which of the two paths is taken is decided here from
        the keys alone, so a later run can be planned before an earlier one
        has finished. The path is counted now (a re-costing that returns
        None is taken back then).
        """
        counts_key, cost_key, cpus = keys
        if counts_key not in self._runs:
            return None
        stored_cost_key, stored = self._runs[counts_key]
        if isinstance(stored, Future) and stored.done() and stored.exception() is not None:
            return None  # its simulation failed: simulate again
        if stored_cost_key == cost_key:
            self.reused += 1
            return lambda: _on_cpus(_finished(stored), cpus)
        if cpus is None:  # a schedule that depends on cycles (:meth:`keys_of` gives first CPUs to fixed ones only)
            return None

        self.re_costed += 1

        def recosted():
            run = recost_run(_finished(stored), hierarchy, cost)
            if run is None:
                self.re_costed -= 1
                return None
            return _on_cpus(run, cpus)

        return recosted

    def add(self, keys, run) -> None:
        """Keep a simulated run under ``keys``: a :class:`~coherence.simulation.Run`, or a
        :class:`concurrent.futures.Future` of one still being simulated (runs served from it wait for it)."""
        self.simulated += 1
        self._runs[keys[0]] = (keys[1], run)

    def placed_layout(self, trace, layout, scene=None):
        """:func:`coherence.studies.place_layout` of ``layout`` for ``trace`` and ``scene``, worked out once per
        layout and scene (the last :data:`PLACED_KEPT` are kept): the placement depends on nothing else. It
        has no page placement; :meth:`~coherence.layout.PlacedLayout.with_pages` of it shares its arrays."""
        from coherence.studies import place_layout

        self.bind(trace)
        key = (repr(layout), id(scene))
        kept = self._placed.pop(key, None)
        if kept is None or kept[0] is not scene:  # the scene is kept alive with it: its id is not reused
            while len(self._placed) >= PLACED_KEPT:
                self._placed.pop(next(iter(self._placed)))
            placed = place_layout(layout, trace, scene)
            kept = (scene, placed, _records_digest(placed))
        self._placed[key] = kept  # most recently used last
        return kept[1]

    def _lines_key(self, placed, line_size: int, budget_bytes, hierarchy) -> tuple:
        """:func:`_lines_key`, with the digest of the records of a placed layout this store keeps not worked
        out again."""
        for _, kept, digest in self._placed.values():
            if kept.record_start is placed.record_start and kept.record_size is placed.record_size \
                    and kept.kind_first is placed.kind_first:
                return _lines_key(placed, line_size, budget_bytes, hierarchy, digest)
        return _lines_key(placed, line_size, budget_bytes, hierarchy)

    def holds_lines(self, trace, placed, line_size: int, budget_bytes: int | None = None, hierarchy=None) -> bool:
        """Whether :meth:`pixel_lines` of these arguments is served without working anything out."""
        return self._lines_key(placed, line_size, budget_bytes, hierarchy) in self._lines and self._trace is trace

    def lines_kept_with_new(self) -> list:
        """The line addresses still kept once :meth:`pixel_lines` works out a new placement's: the
        ``LINES_KEPT - 1`` served last (a caller that must not hold more than :data:`LINES_KEPT` placements'
        addresses lets go of any other first)."""
        return list(self._lines.values())[len(self._lines) - (LINES_KEPT - 1):] if LINES_KEPT > 1 else []

    def pixel_lines(self, trace, placed, line_size: int, budget_bytes: int | None = None, hierarchy=None):
        """:func:`coherence.pixel_lines.pixel_lines` of ``trace`` on ``placed``, worked out once per placement.

        The key is everything the addresses depend on: every record's address
        and size, the page table, ``line_size``, ``budget_bytes`` (which
        decides whether there is a result at all) and, with ``hierarchy``,
        which of its certain first-level hits are taken out.
        """
        from coherence.pixel_lines import pixel_lines

        self.bind(trace)
        key = self._lines_key(placed, line_size, budget_bytes, hierarchy)
        if key in self._lines:
            self._lines[key] = self._lines.pop(key)  # most recently used last
            return self._lines[key]
        while len(self._lines) >= LINES_KEPT:  # let go first: at most LINES_KEPT are ever held
            self._lines.pop(next(iter(self._lines)))
        lines = pixel_lines(trace, placed, line_size, budget_bytes, hierarchy=hierarchy)
        self._lines[key] = lines
        return lines


def _lines_key(placed, line_size: int, budget_bytes, hierarchy=None, records_digest: bytes | None = None) -> tuple:
    """The key of :meth:`RunStore.pixel_lines`: every record's address and size (``records_digest``, their
    :func:`_records_digest` if already worked out), the page table, ``line_size``, ``budget_bytes`` (which
    decides whether there is a result at all) and which accesses ``hierarchy`` takes out
    (:func:`coherence.pixel_lines.skip_key`; "" for none)."""
    from coherence.pixel_lines import skip_key, skips_certain_hits

    skips = skip_key(hierarchy) if hierarchy is not None and skips_certain_hits(hierarchy, line_size) else ""
    if records_digest is None:
        records_digest = _records_digest(placed)
    frames = hashlib.blake2b(np.ascontiguousarray(placed.pages.frame, dtype=np.int64).tobytes(), digest_size=16)
    return (records_digest, frames.digest(), int(placed.end), int(placed.pages.first_page),
            int(placed.pages.page_shift), int(line_size), budget_bytes, skips)


def _records_digest(placed) -> bytes:
    """A digest of every record's address and size and of the kinds' first rows of a placed layout."""
    digest = hashlib.blake2b(digest_size=16)
    for array in (placed.record_start, placed.record_size, placed.kind_first):
        digest.update(np.ascontiguousarray(array, dtype=np.int64).tobytes())
        digest.update(b"|")
    return digest.digest()


def compute_digest(compute) -> bytes:
    """The digest of compute cycles per pixel (float64 (P,)) that the cost key of :meth:`RunStore.keys_of` holds."""
    return hashlib.blake2b(np.ascontiguousarray(compute, dtype=np.float64).tobytes(), digest_size=16).digest()


def _finished(run):
    """``run``, or the result of ``run`` if it is a future (waiting for it)."""
    return run.result() if isinstance(run, Future) else run
