"""One call for a whole study: mappings x process counts on one trace.

>>> from coherence import study                                   # doctest: +SKIP
>>> result = study(trace, ["S", "P", "R", "B", "DB"], [1, 2, 4, 8, 16])
>>> result.runs[["mapping", "n_processes", "speedup_user", "load_balance", "coherence_factor"]]
"""
from __future__ import annotations

import hashlib
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass

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
    """

    runs: pd.DataFrame
    processes: pd.DataFrame
    parameters: dict


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
    """

    n_jobs: int | None = None
    executor: object = None
    trace_folder: object = None
    shared_lines_budget: int = SHARED_LINES_BUDGET
    store: RunStore | None = None

    def __post_init__(self):
        if self.n_jobs is not None:
            require_int("Execution.n_jobs", self.n_jobs, 1)
        require_int("Execution.shared_lines_budget", self.shared_lines_budget, 0)
        if self.executor is not None and self.trace_folder is None:
            raise InputError("Execution: runs on an executor load the trace where they execute; give "
                             "trace_folder, the folder the trace was saved in")
        if self.store is not None and not isinstance(self.store, RunStore):
            raise InputError(f"Execution.store must be a coherence.recost.RunStore, got {type(self.store).__name__}")


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
    shared = hierarchy if isinstance(hierarchy, SharedLevels) else None
    hierarchy = get_hierarchy(hierarchy) if shared is None else shared.hierarchy
    layout = get_layout(layout)
    cost = get_cost_model(cost)
    machine = machine or Machine()
    mapping_objects = [get_mapping(mapping) for mapping in mappings]
    names = [mapping.name for mapping in mapping_objects]
    if len(set(names)) != len(names):
        raise InputError(f"mappings must have distinct names, got {names}")
    counts = sorted({1, *(require_int("n_processes", n, 1) for n in n_processes)})
    execution = execution or Execution()
    if not isinstance(execution, Execution):
        raise InputError(f"study: execution must be a coherence.studies.Execution, got {type(execution).__name__}")
    executor, trace_folder, n_jobs = execution.executor, execution.trace_folder, execution.n_jobs
    placed = place_layout(layout, trace, scene).with_pages(machine.page_placement, hierarchy)
    compute = cost.compute_cycles(trace.counters, COUNTER_NAMES)
    jobs = [(mapping, n) for mapping in mapping_objects for n in counts]

    def distribution_of(index):
        mapping, n = jobs[index]
        return mapping.build(trace.width, trace.height, n)

    # Runs that replay the same pixels in the same order on every process
    # (S, P and R at one process, say) are simulated once. A distribution holds
    # arrays per pixel, so each is built when needed and not kept: a study of
    # 80 runs at 2048x2048 held 2.5 GB of them.
    keys = []
    task_counts = []  # tasks per process of a static run (the one column its key leaves out); None if dynamic
    process_counts = []
    for index in range(len(jobs)):
        distribution = distribution_of(index)
        keys.append(_replay_key(distribution))
        process_counts.append(distribution.n_processes)
        task_counts.append(None if distribution.dynamic else np.bincount(
            distribution.task_process, minlength=distribution.n_processes).astype(np.int64))
    first_of = {}
    for index, key in enumerate(keys):
        first_of.setdefault(key, index)
    distinct = sorted(first_of.values())

    store = execution.store if shared is None else None  # a store keeps private-cache runs only
    simulated = _from_store(store, trace, distinct, keys, (hierarchy, layout, machine, cost, compute))
    distinct = [index for index in distinct if index not in simulated]  # the runs to simulate
    bar = _progress(len(distinct), progress)
    shared_rows = {}
    if shared is not None:  # on this machine, every run on the shared levels
        pieces = pixel_pieces(trace, placed, hierarchy.levels[0].line_size)

        def simulate_shared(index):
            return simulate_shared_run(trace, distribution_of(index), shared.machine, placed, cost, machine,
                                       interleave_cycles=shared.interleave_cycles, compute=compute, pieces=pieces)

        with ThreadPoolExecutor(max_workers=n_jobs or os.cpu_count() or 1) as pool:
            for index, run in zip(distinct, pool.map(simulate_shared, distinct)):
                simulated[index] = run.run
                shared_rows[index] = shared_run_row(run.shared)
                bar.update(1)
    elif executor is not None:
        futures = [executor.submit(simulate_stored, str(trace_folder), distribution_of(index), hierarchy, placed,
                                   cost, machine, compute) for index in distinct]
        for index, future in zip(distinct, futures):
            simulated[index] = future.result()
            bar.update(1)
    else:
        # Every run reads the same pixels' line addresses: work them out once, if they fit the budget.
        smallest_line = min(level.line_size for level in hierarchy.levels)
        lines = (pixel_lines if store is None else store.pixel_lines)(
            trace, placed, smallest_line, execution.shared_lines_budget) if len(distinct) > 1 else None

        def simulate(index):
            return simulate_run(trace, distribution_of(index), hierarchy, placed, cost, machine, compute=compute,
                                lines=lines)

        # All runs at once, the first included: numba compiles a kernel under
        # a global lock and looks for the compiled version again once it holds
        # it, so threads that reach an uncompiled kernel together compile it once.
        with ThreadPoolExecutor(max_workers=n_jobs or os.cpu_count() or 1) as pool:
            for index, run in zip(distinct, pool.map(simulate, distinct)):
                simulated[index] = run
                bar.update(1)
    bar.close()
    if store is not None:
        for index in distinct:
            store.add(store.keys(keys[index], hierarchy, layout, machine, cost, compute),
                                simulated[index])
    results = []
    for (mapping, _), key, tasks, n in zip(jobs, keys, task_counts, process_counts):
        run = simulated[first_of[key]]
        processes = run.processes
        if tasks is not None:  # the one column that depends on how pixels are cut into tasks
            processes = processes.assign(tasks=tasks)
        row = {"mapping": mapping.name, **run_summary(processes, hierarchy.level_names, cost.clock_hz,
                                                        run.real_cycles)}
        row["n_cpus"] = machine.n_cpus
        row.update(shared_rows.get(first_of[key], {}))
        results.append((row, processes.assign(mapping=mapping.name, n_processes=n)))
    runs = add_speedups(pd.DataFrame([row for row, _ in results]))
    front = ["mapping", "n_processes", "n_cpus"]
    runs = runs[front + [c for c in runs.columns if c not in front]]
    processes = pd.concat([frame for _, frame in results], ignore_index=True)
    processes = processes[["mapping", "n_processes"] + [c for c in processes.columns
                                                        if c not in ("mapping", "n_processes")]]
    parameters = {"hierarchy": hierarchy.to_dict(), "layout": layout.name, "cost": cost.to_dict(),
                  "machine": asdict(machine), "mappings": names, "n_processes": counts}
    if shared is not None:
        parameters["shared_levels"] = shared.to_dict()
    return StudyResult(runs, processes, parameters)


def _from_store(store, trace, distinct, keys, setup) -> dict:
    """Run index -> run, for the runs of ``distinct`` that ``store`` re-costs or reuses (none without a store).

    ``setup`` is (hierarchy, layout, machine, cost, compute cycles per pixel) of the study.
    """
    if store is None:
        return {}
    store.bind(trace)
    hierarchy, _, _, cost, _ = setup
    found = {}
    for index in distinct:
        run = store.find(store.keys(keys[index], *setup), hierarchy, cost)
        if run is not None:
            found[index] = run
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

