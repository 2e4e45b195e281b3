"""One call for a whole study: mappings x process counts on one trace.

>>> from coherence import study                                   # doctest: +SKIP
>>> result = study(trace, ["S", "P", "R", "B", "DB"], [1, 2, 4, 8, 16])
>>> result.runs[["mapping", "n_processes", "speedup_user", "load_balance", "coherence_factor"]]
"""
from __future__ import annotations

import hashlib
import os
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from functools import partial

import numpy as np
import pandas as pd

from cachesim import Hierarchy, get_hierarchy
from cachesim.config import DEFAULT_HIERARCHY
from coherence.cost import DEFAULT_COST_MODEL, CostModel, get_cost_model
from coherence.layout import DEFAULT_LAYOUT, MemoryLayout, PlacedLayout, get_layout, record_counts_of
from coherence.mappings import DEFAULT_MAPPINGS, get_mapping
from coherence.metrics import add_speedups, run_summary
from coherence.pixel_lines import SHARED_LINES_BUDGET, pixel_lines
from coherence.recost import ReplayKey, RunStore
from coherence.shared_run import SharedLevels, pixel_pieces, shared_run_row, simulate_shared_run
from coherence.simulation import Machine, simulate_run
from rtcommon.validate import InputError, require_int
from tracer.trace.access import COUNTER_NAMES, RecordKind
from tracer.trace.check import META_FILE


@dataclass(frozen=True)
class StudyResult:
    """Tables of a study.

    Attributes
    ----------
    runs : DataFrame
        One row per (mapping, n_processes): times, speed-ups, efficiency and
        its factors, hit rates and misses per ray per level.
    processes : DataFrame
        One row per process of every run (see :func:`simulate_run`), with
        ``mapping`` and ``n_processes`` columns.
    parameters : dict
        Hierarchy, layout, cost model and machine, as plain data.
    kinds : DataFrame or None
        On shared levels (:class:`coherence.shared_run.SharedLevels`), one row per (mapping, n_processes,
        level, record kind): ``mapping``, ``n_processes`` and the columns of
        :func:`coherence.kind_misses.shared_misses_by_kind` (accesses and misses summed over the level's
        instances, background reads in kind 0); None on private caches, whose runs count no kinds.
    pixel_misses : dict
        On shared levels, for each run at a process count of :attr:`Execution.pixel_misses_at`:
        ``(mapping name, n_processes)`` -> its :attr:`coherence.simulation.Run.pixel_misses` (H, W, L), each
        pixel's misses per level. Empty otherwise.
    """

    runs: pd.DataFrame
    processes: pd.DataFrame
    parameters: dict
    kinds: pd.DataFrame | None = None
    pixel_misses: dict = field(default_factory=dict)


def place_layout(layout: MemoryLayout, trace, scene=None) -> PlacedLayout:
    """Place ``layout`` for a trace's scene.

    Record counts come from the trace (its metadata, or the records read);
    with ``scene``, polygons and patches get their true vertex counts (else
    4 each). Texels are placed by the levels in the trace's ``textures``
    metadata. A layout with a heap (``malloc1997``) places records in the
    order the tracer created them, from the scene and its tree
    (:func:`coherence.malloc_image.trace_creation_order`; without ``scene``,
    the catalogue's scene the trace names).
    """
    counts = record_counts_of(trace)
    vertices = {}
    if scene is not None:
        for kind, offsets in ((RecordKind.POLYGON, scene.polygon_offsets), (RecordKind.PATCH, scene.patch_offsets)):
            sizes = np.diff(np.asarray(offsets, dtype=np.int64))
            if sizes.size < counts.get(kind, 0):
                raise InputError(f"the trace reads {kind.name.lower()} records the scene does not have: "
                                 "is it the trace of this scene?")
            counts[kind] = sizes.size
            vertices[kind] = sizes
    textures = trace.metadata.get("textures") if hasattr(trace, "metadata") else None
    if layout.heap is None:
        return layout.place(counts, vertices, textures)
    from coherence.malloc_image import trace_creation_order

    return layout.place(counts, vertices, textures, trace_creation_order(trace, scene))


@dataclass(frozen=True)
class Execution:
    """Where and how a study's runs are simulated; the results are the same whatever it says.

    Parameters
    ----------
    n_jobs : int, optional
        Runs simulated at once (threads; default: the number of CPUs).
    executor : concurrent.futures.Executor, optional
        Simulate the runs there instead (a Dask cluster's
        ``Client.get_executor()``, say); each run is a task that loads the
        trace from ``trace_folder`` where it executes.
    trace_folder : path, optional
        Where the trace was saved (:meth:`~tracer.trace.access.AccessTrace.save`);
        needed with ``executor``, and must be readable there.
    shared_lines_budget : int
        Bytes the runs may share in line addresses worked out once
        (:mod:`coherence.pixel_lines`); beyond it each run converts its
        pixels' records itself. The counts are the same either way.
    store : coherence.recost.RunStore, optional
        Runs of earlier studies of the same trace: a run whose counts they
        already hold is re-costed or reused instead of simulated
        (:mod:`coherence.recost`; the cycles equal a simulation's up to the
        order of floating-point additions), and every simulated run is
        added to it.
    pixel_misses_at : tuple of int
        Process counts whose runs on shared levels also keep each pixel's misses
        (:attr:`StudyResult.pixel_misses`, the map :func:`coherence.missmap.miss_map` would simulate again);
        only with a :class:`coherence.shared_run.SharedLevels` hierarchy.
    """

    n_jobs: int | None = None
    executor: object = None
    trace_folder: object = None
    shared_lines_budget: int = SHARED_LINES_BUDGET
    store: RunStore | None = None
    pixel_misses_at: tuple = ()

    def __post_init__(self):
        if self.n_jobs is not None:
            require_int("Execution.n_jobs", self.n_jobs, 1)
        require_int("Execution.shared_lines_budget", self.shared_lines_budget, 0)
        if self.executor is not None and self.trace_folder is None:
            raise InputError("Execution: runs on an executor load the trace where they execute; give "
                             "trace_folder, the folder the trace was saved in")
        if self.store is not None and not isinstance(self.store, RunStore):
            raise InputError(f"Execution.store must be a coherence.recost.RunStore, got {type(self.store).__name__}")
        if not isinstance(self.pixel_misses_at, tuple):
            raise InputError(f"Execution.pixel_misses_at must be a tuple of process counts, "
                             f"got {type(self.pixel_misses_at).__name__}")
        for n in self.pixel_misses_at:
            require_int("Execution.pixel_misses_at", n, 1)


def study(trace, mappings=DEFAULT_MAPPINGS, n_processes=(1, 2, 4, 8, 16), *,
          hierarchy: Hierarchy | str = DEFAULT_HIERARCHY, layout: MemoryLayout | str = DEFAULT_LAYOUT,
          cost: CostModel | str = DEFAULT_COST_MODEL, machine: Machine | None = None, scene=None,
          progress: bool = True, execution: Execution | None = None) -> StudyResult:
    """Simulate every mapping at every process count on one trace.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    mappings : sequence of str or Mapping
        Names (``S``, ``P``, ``R``, ``B``, ``DB``, ``hilbert``, ...) or
        mapping objects.
    n_processes : sequence of int
        Process counts; 1 is always added (speed-ups need it).
    hierarchy, layout, cost : object or preset name
        ``hierarchy`` may be a :class:`coherence.shared_run.SharedLevels`:
        every run is then simulated on its shared levels
        (:func:`coherence.shared_run.simulate_shared_run`), locally (an
        executor or a store in ``execution`` is not used), and each row of
        ``runs`` gets the machine's coherence counts per level
        (:func:`coherence.shared_run.shared_run_row`).
    machine : Machine, optional
        CPUs, time slice, scheduler and background load (default: 8 idle
        CPUs sharing one run queue; see :class:`~coherence.simulation.Machine`).
    scene : tracer.scenes.model.Scene, optional
        For exact polygon sizes in the layout.
    progress : bool
        Show a progress bar on stderr.
    execution : Execution, optional
        Threads, a cluster's executor, and the memory the runs may share
        (default: one thread per CPU, here). The results are the same.

    Returns
    -------
    StudyResult
    """
    call = StudyCall(trace, mappings, n_processes, hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
                     scene=scene, execution=execution)
    plan = _StudyPlan(call)
    n_jobs = plan.execution.n_jobs
    with ThreadPoolExecutor(max_workers=n_jobs or os.cpu_count() or 1) as pool:
        plan.start(pool)
        return plan.result(_progress(len(plan.to_simulate), progress))


@dataclass(frozen=True)
class StudyCall:
    """The arguments of one :func:`study` (but ``progress``), for :func:`study_stream`."""

    trace: object
    mappings: tuple = DEFAULT_MAPPINGS
    n_processes: tuple = (1, 2, 4, 8, 16)
    hierarchy: object = DEFAULT_HIERARCHY
    layout: object = DEFAULT_LAYOUT
    cost: object = DEFAULT_COST_MODEL
    machine: Machine | None = None
    scene: object = None
    execution: Execution | None = None


#: Studies of :func:`study_stream` whose runs may be under way at once.
STREAM_WINDOW = 4


def study_stream(calls, *, n_jobs: int | None = None, window: int = STREAM_WINDOW):
    """The results of many studies, in order, their runs simulated on one pool of threads.

    :func:`study` waits for a study's last run before the next study starts,
    and a core idles while it runs; here the next studies' runs start on
    the free threads meanwhile. Each result equals :func:`study` of its
    :class:`StudyCall` made in the same order: a study's runs are looked up
    in its ``execution.store`` when the study is planned, after every
    earlier call's runs were put there (as futures while they are
    simulated), so each run is reused, re-costed or simulated exactly as
    one study after another would have it (but for a stored run found not
    re-costable only once it is simulated: that run is then simulated
    itself, and later studies already planned keep re-costing from the
    earlier run, equal up to the order of floating-point additions).

    Parameters
    ----------
    calls : iterable of StudyCall
        Read one at a time, as the window lets; ``execution.n_jobs`` of the
        calls is not used.
    n_jobs : int, optional
        Threads simulating the runs (default: the number of CPUs).
    window : int
        Studies planned whose results were not yet given, at most; >= 1.

    Yields
    ------
    StudyResult
        One per call, in order.

    Notes
    -----
    A study's line addresses (:mod:`coherence.pixel_lines`) are worked out
    when it is planned; before a new placement's are, the studies under way
    that use any other than those its store keeps are waited for, so no
    more placements' addresses are held than one study after another holds
    (:data:`coherence.recost.LINES_KEPT`).
    """
    require_int("window", window, 1)
    if n_jobs is not None:
        require_int("n_jobs", n_jobs, 1)
    under_way = deque()
    with ThreadPoolExecutor(max_workers=n_jobs or os.cpu_count() or 1) as pool:
        for call in calls:
            plan = _StudyPlan(call)
            if plan.lines_are_new():
                kept = plan.store.lines_kept_with_new() if plan.store is not None else []
                _wait_for(study for study in under_way
                          if study.lines is not None and not any(study.lines is lines for lines in kept))
            plan.start(pool)
            under_way.append(plan)
            while len(under_way) >= window + 1 or (under_way and under_way[0].done()):
                yield under_way.popleft().result()
        while under_way:
            yield under_way.popleft().result()


def _wait_for(plans) -> None:
    """Wait until every run of ``plans`` (:class:`_StudyPlan`) is simulated (a point :func:`study_stream`
    waits at)."""
    for plan in plans:
        plan.wait()


class _StudyPlan:
    """One study: its runs, which of them are simulated, and its result once they are.

    Made from a :class:`StudyCall`: validates it, builds the runs' keys and
    looks them up in the store (:class:`coherence.recost.RunStore`);
    :meth:`submit` puts the runs to simulate on a pool (or the execution's
    executor), :meth:`result` waits for them and makes the tables.
    """

    def __init__(self, call: StudyCall):
        if not isinstance(call, StudyCall):
            raise InputError(f"study_stream: every call must be a coherence.studies.StudyCall, "
                             f"got {type(call).__name__}")
        trace = call.trace
        hierarchy = call.hierarchy
        self.shared = hierarchy if isinstance(hierarchy, SharedLevels) else None
        self.hierarchy = get_hierarchy(hierarchy) if self.shared is None else self.shared.hierarchy
        self.layout = get_layout(call.layout)
        self.cost = get_cost_model(call.cost)
        self.machine = call.machine or Machine()
        self.mapping_objects = [get_mapping(mapping) for mapping in call.mappings]
        self.names = [mapping.name for mapping in self.mapping_objects]
        if len(set(self.names)) != len(self.names):
            raise InputError(f"mappings must have distinct names, got {self.names}")
        self.counts = sorted({1, *(require_int("n_processes", n, 1) for n in call.n_processes)})
        self.execution = call.execution or Execution()
        if not isinstance(self.execution, Execution):
            raise InputError(f"study: execution must be a coherence.studies.Execution, "
                             f"got {type(self.execution).__name__}")
        if self.execution.pixel_misses_at and self.shared is None:
            raise InputError("study: Execution.pixel_misses_at keeps the misses per pixel of runs on shared levels; "
                             "give a coherence.shared_run.SharedLevels hierarchy")
        self.trace = trace
        self.store = self.execution.store if self.shared is None else None  # a store keeps private-cache runs only
        placed = (place_layout(self.layout, trace, call.scene) if self.store is None
                  else self.store.placed_layout(trace, self.layout, call.scene))
        self.placed = placed.with_pages(self.machine.page_placement, self.hierarchy)
        if self.store is None:
            self.compute = self.cost.compute_cycles(trace.counters, COUNTER_NAMES)
        else:
            self.compute, compute_key = self.store.compute_cycles(trace, self.cost)
        self.jobs = [(mapping, n) for mapping in self.mapping_objects for n in self.counts]
        # Runs that replay the same pixels in the same order on every process
        # (S, P and R at one process, say) are simulated once. A distribution holds
        # arrays per pixel, so each is built when needed and not kept: a study of
        # 80 runs at 2048x2048 held 2.5 GB of them.
        replays = []  # per run: its replay key, process count and tasks per process (None if dynamic)
        for index, (mapping, n) in enumerate(self.jobs):
            work_out = partial(self._replay, index)
            replays.append(work_out() if self.store is None else self.store.replay_of(trace, mapping, n, work_out))
        self.keys = [key for key, _, _ in replays]
        self.process_counts = [n for _, n, _ in replays]
        self.task_counts = [tasks for _, _, tasks in replays]  # the one column a static run's key leaves out
        self.first_of = {}
        for index, key in enumerate(self.keys):
            self.first_of.setdefault(key, index)
        distinct = sorted(self.first_of.values())
        self.store_keys = {}
        if self.store is not None:
            self.store_keys = dict(zip(distinct, self.store.keys_of([self.keys[index] for index in distinct],
                                                                    self.hierarchy, self.layout, self.machine,
                                                                    self.cost, compute_key)))
        self.served = _from_store(self.store, trace, self.store_keys, self.hierarchy, self.cost)
        self.to_simulate = [index for index in distinct if index not in self.served]
        self.futures = {}
        self.passed_on = set()  # runs whose store future follows a submitted simulation
        self.lines = None
        if self.store is not None:
            for index in self.to_simulate:  # later studies find these runs while they are simulated
                future = Future()
                self.futures[index] = future
                self.store.add(self.store_keys[index], future)

    def _replay(self, index) -> tuple:
        """The replay key, process count and tasks per process (None if dynamic) of run ``index``."""
        distribution = self.distribution_of(index)
        tasks = None if distribution.dynamic else np.bincount(
            distribution.task_process, minlength=distribution.n_processes).astype(np.int64)
        return _replay_key(distribution), distribution.n_processes, tasks

    def distribution_of(self, index):
        mapping, n = self.jobs[index]
        return mapping.build(self.trace.width, self.trace.height, n)

    def _lines_wanted(self) -> bool:
        # every run reads the same pixels' line addresses: work them out once, if they fit the budget
        return self.shared is None and self.execution.executor is None and len(self.to_simulate) > 1

    def _line_size(self) -> int:
        return min(level.line_size for level in self.hierarchy.levels)

    def lines_are_new(self) -> bool:
        """Whether :meth:`work_out_lines` works out line addresses no store holds."""
        if not self._lines_wanted():
            return False
        return self.store is None or not self.store.holds_lines(self.trace, self.placed, self._line_size(),
                                                                self.execution.shared_lines_budget, self.hierarchy)

    def work_out_lines(self):
        """The line addresses the runs share (None when not worked out)."""
        if not self._lines_wanted():
            return None
        work = pixel_lines if self.store is None else self.store.pixel_lines
        return work(self.trace, self.placed, self._line_size(), self.execution.shared_lines_budget,
                    hierarchy=self.hierarchy)

    def start(self, pool) -> None:
        """Work out the line addresses and :meth:`submit` the runs. If that fails, the store's futures of
        the runs not submitted fail with the same error, so a later study simulates them again instead of
        waiting for them for ever."""
        try:
            self.submit(pool, self.work_out_lines())
        except BaseException as error:
            for index in self.to_simulate:
                future = self.futures.get(index)
                if index not in self.passed_on and future is not None and not future.done():
                    future.set_exception(error)
            raise

    def submit(self, pool, lines) -> None:
        """Simulate the runs to simulate: on the shared levels or privately on ``pool``, or on the
        execution's executor."""
        self.lines = lines
        if self.shared is not None:
            pieces = pixel_pieces(self.trace, self.placed, self.hierarchy.levels[0].line_size)
            submitted = {index: pool.submit(self._simulate_shared, index, pieces) for index in self.to_simulate}
        elif self.execution.executor is not None:
            submitted = {index: self.execution.executor.submit(
                simulate_stored, str(self.execution.trace_folder), self.distribution_of(index), self.hierarchy,
                self.placed, self.cost, self.machine, self.compute) for index in self.to_simulate}
        else:
            submitted = {index: pool.submit(self._simulate, index) for index in self.to_simulate}
        for index, future in submitted.items():
            if index in self.futures:  # the store's future follows the pool's
                future.add_done_callback(partial(_pass_on, self.futures[index]))
                self.passed_on.add(index)
            else:
                self.futures[index] = future

    def _simulate(self, index):
        return simulate_run(self.trace, self.distribution_of(index), self.hierarchy, self.placed, self.cost,
                            self.machine, compute=self.compute, lines=self.lines)

    def _simulate_shared(self, index, pieces):
        """The run's table, its row of machine counts and its misses per kind: all the study reads of a run on
        shared levels. The machine's state (tens of MB) is let go as the run ends, not held until every run
        is done."""
        from coherence.kind_misses import shared_misses_by_kind

        keep = self.jobs[index][1] in self.execution.pixel_misses_at
        run = simulate_shared_run(self.trace, self.distribution_of(index), self.shared.machine, self.placed,
                                  self.cost, self.machine, interleave_cycles=self.shared.interleave_cycles,
                                  compute=self.compute, pieces=pieces, record=("pixel_misses",) if keep else ())
        return run.run, shared_run_row(run.shared), shared_misses_by_kind(run.shared)

    def done(self) -> bool:
        return all(future.done() for future in self.futures.values())

    def wait(self) -> None:
        """Wait until every run is simulated, and let go of the line addresses (no run reads them now; a
        stored run found not re-costable is then simulated without them, with the same counts)."""
        for future in self.futures.values():
            future.exception()
        self.lines = None

    def result(self, bar=None) -> StudyResult:
        """The study's tables, once its runs are simulated (``bar`` counts them)."""
        simulated = {}
        shared_rows = {}
        shared_kinds = {}
        for index in self.to_simulate:
            run = self.futures[index].result()
            if self.shared is not None:
                run, shared_rows[index], shared_kinds[index] = run
            simulated[index] = run
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        for index, serve in self.served.items():
            run = serve()
            if run is None:  # the stored run was not re-costable after all: simulate it
                run = self._simulate(index)
                self.store.add(self.store_keys[index], run)
            simulated[index] = run
        hierarchy, cost, machine = self.hierarchy, self.cost, self.machine
        results = []
        for (mapping, _), key, tasks, n in zip(self.jobs, self.keys, self.task_counts, self.process_counts):
            run = simulated[self.first_of[key]]
            processes = run.processes
            if tasks is not None:  # the one column that depends on how pixels are cut into tasks
                processes = processes.assign(tasks=tasks.copy())  # the array is kept for later studies
            row = {"mapping": mapping.name, **run_summary(processes, hierarchy.level_names, cost.clock_hz,
                                                            run.real_cycles)}
            row["n_cpus"] = machine.n_cpus
            row.update(shared_rows.get(self.first_of[key], {}))
            results.append((row, processes.assign(mapping=mapping.name, n_processes=n)))
        runs = add_speedups(pd.DataFrame([row for row, _ in results]))
        front = ["mapping", "n_processes", "n_cpus"]
        runs = runs[front + [c for c in runs.columns if c not in front]]
        processes = pd.concat([frame for _, frame in results], ignore_index=True)
        processes = processes[["mapping", "n_processes"] + [c for c in processes.columns
                                                            if c not in ("mapping", "n_processes")]]
        parameters = {"hierarchy": hierarchy.to_dict(), "layout": self.layout.name, "cost": cost.to_dict(),
                      "machine": asdict(machine), "mappings": self.names, "n_processes": self.counts}
        kinds = None
        pixel_misses = {(mapping.name, n): simulated[self.first_of[key]].pixel_misses
                        for (mapping, n), key in zip(self.jobs, self.keys) if n in self.execution.pixel_misses_at}
        if self.shared is not None:
            parameters["shared_levels"] = self.shared.to_dict()
            kinds = pd.concat([shared_kinds[self.first_of[key]].assign(mapping=mapping.name, n_processes=n)
                               for (mapping, _), key, n in zip(self.jobs, self.keys, self.process_counts)],
                              ignore_index=True)
            kinds = kinds[["mapping", "n_processes", "level", "kind", "accesses", "misses"]]
        return StudyResult(runs, processes, parameters, kinds, pixel_misses)


def _pass_on(target: Future, source: Future) -> None:
    """Give ``target`` the outcome of ``source`` (a done callback)."""
    if source.exception() is not None:
        target.set_exception(source.exception())
    else:
        target.set_result(source.result())


def _from_store(store, trace, store_keys: dict, hierarchy, cost) -> dict:
    """Run index -> a callable giving the run (:meth:`coherence.recost.RunStore.serve`), for the runs of
    ``store_keys`` (run index -> :meth:`~coherence.recost.RunStore.keys_of`) that ``store`` re-costs or reuses
    (none without a store)."""
    if store is None:
        return {}
    store.bind(trace)
    found = {}
    for index, keys in store_keys.items():
        served = store.serve(keys, hierarchy, cost)
        if served is not None:
            found[index] = served
    return found


#: traces loaded by :func:`simulate_stored` in this process, by folder (a worker runs many runs of one trace)
_STORED = {}


def simulate_stored(trace_folder: str, distribution, hierarchy, placed, cost, machine, compute):
    """:func:`~coherence.simulation.simulate_run` of the trace saved in ``trace_folder``.

    A task for an executor: the trace is loaded (memory-mapped, checked) where
    the task runs, once per process, instead of travelling with the task.
    """
    from tracer.trace.access import AccessTrace

    folder = os.path.abspath(trace_folder)
    key = (folder, os.stat(os.path.join(folder, META_FILE)).st_mtime_ns)  # a trace saved again is loaded again
    if key not in _STORED:
        _STORED.clear()  # one trace at a time: a worker's memory holds one study
        _STORED[key] = AccessTrace.load(folder, mmap=True)
    return simulate_run(_STORED[key], distribution, hierarchy, placed, cost, machine, compute=compute)


def _replay_key(distribution) -> ReplayKey:
    """What a run replays: equal keys, equal runs (every count and cycle).

    A static run depends only on each process's pixels in order (how they
    are cut into tasks changes nothing but the ``tasks`` column); a dynamic
    one on its tasks, their order and the hand-out costs.
    """
    def digest(array):
        return hashlib.blake2b(np.ascontiguousarray(array, dtype=np.int64).tobytes(), digest_size=16).digest()

    if distribution.dynamic:
        return ReplayKey(True, int(distribution.n_processes),
                         (float(distribution.dispatch_cycles), int(distribution.take_ahead),
                          digest(distribution.task_offsets), digest(distribution.task_pixels)))
    owner = np.asarray(distribution.task_process, dtype=np.int64)
    pixel_owner = np.repeat(owner, distribution.task_lengths)
    order = np.argsort(pixel_owner, kind="stable")  # each process's pixels, in its render order
    return ReplayKey(False, int(distribution.n_processes),
                     (digest(distribution.task_pixels[order]),
                      digest(np.bincount(pixel_owner, minlength=distribution.n_processes))))


def _progress(total: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="simulating runs", unit="run", disable=not enabled, leave=False)

