"""A what-if over the path-traced workload: where does reordering rays pay for itself?

Every grid point renders (or takes from the trace cache) a path-traced trace,
runs the study's mappings at 1 and the base's one process count, and
computes the report's ray-order section on it
(:func:`analyses.report_orders.order_section`): per ray order, the
reordering gain (how much less the caches made the processes work), the
reordering overhead (what the order's own buffer and queue traffic and its
sorting cost) and, added here, ``net_speedup``: the depth-first order's
slowest process time over the order's (above 1 when the order pays for
itself at the point).

Grid parameters (:data:`GRID_KEYS`; each optional):

================ ==========================================================
``scene``        a built-in scene or NFF/OBJ file (the million-triangle
                 scene is ``tetra`` at ``scene_size`` 10: 4^10 triangles)
``scene_size``   SPD size factor of the scene (balls, tetra, shell only)
``spp``          samples per pixel
``max_depth``    the bounce limit (the path's ray-tree depth)
``<level>.size`` bytes of a cache level (``L1.size``, ``L2.size``, ...)
================ ==========================================================

Under a platform (the base's ``platform``), the study and every order run on
its shared levels (:func:`coherence.ordered_runs.simulate_ordered_shared`),
an ``<level>.size`` being the size of one whole level.

Python API: ``order_whatif(base, grid)`` gives the table and
``save_order_whatif(table, base, grid, folder)`` writes ``whatif-orders.csv``
and its ``.meta.json``.
"""
from __future__ import annotations

import itertools
import os
from dataclasses import replace
from pathlib import Path

import pandas as pd

from analyses.experiment import Experiment
from rtcommon.validate import InputError, require_int

#: The base unless told otherwise: path-traced balls at 32x32, one sample a pixel, pixel interleaving (P) at
#: 8 processes on 8 idle CPUs.
ORDER_WHATIF_EXPERIMENT = Experiment(size=32, workload="pathtrace", mappings=("P",), n_processes=(8,),
                                     background=0, progress=False)

#: Grid parameters besides ``<level>.size``.
GRID_KEYS = ("scene", "scene_size", "spp", "max_depth")

#: The table's columns after the grid's: as :func:`analyses.report_orders.order_section`'s, then these.
EXTRA_COLUMNS = ("net_speedup",)

#: The file :func:`save_order_whatif` writes.
ORDER_WHATIF_FILE = "whatif-orders.csv"


def grid_points(grid: dict) -> list[dict]:
    """Every combination of ``grid`` (a dict of parameter to list of values), checked.

    Raises
    ------
    InputError
        An empty grid or value list, or a parameter other than :data:`GRID_KEYS` and ``<level>.size``.
    """
    if not grid:
        raise InputError("order what-if: the grid is empty; give at least one of "
                         f"{', '.join(GRID_KEYS)} or <level>.size")
    for key, values in grid.items():
        if key not in GRID_KEYS and not (key.count(".") == 1 and key.endswith(".size")):
            raise InputError(f"order what-if: grid parameter {key!r}: expected one of {', '.join(GRID_KEYS)} "
                             "or <level>.size")
        if not list(values):
            raise InputError(f"order what-if: grid parameter {key!r} has no values")
    keys = list(grid)
    return [dict(zip(keys, combination)) for combination in itertools.product(*(list(grid[k]) for k in keys))]


def parse_order_grid(flags) -> dict:
    """``["spp=1,4", "L1.size=8KB,32KB"]`` -> ``{"spp": [1, 4], "L1.size": [8192, 32768]}`` (values as
    :func:`analyses.whatif.parse_value` reads them), checked as :func:`grid_points` checks a grid.

    Raises
    ------
    InputError
        A flag without ``=`` or values, a parameter given twice, or one :func:`grid_points` refuses.
    """
    from analyses.whatif import parse_value

    grid = {}
    for flag in flags:
        key, sep, values = flag.partition("=")
        key = key.strip()
        if not sep or not values.strip():
            raise InputError(f"--grid {flag!r}: expected NAME=VALUE[,VALUE...], e.g. spp=1,4")
        if key in grid:
            raise InputError(f"--grid {key} is given more than once; list every value in one flag")
        grid[key] = [parse_value(value) for value in values.split(",")]
    grid_points(grid)
    return grid


def order_whatif(base: Experiment = ORDER_WHATIF_EXPERIMENT, grid: dict | None = None, *, orders=None,
                 n_jobs: int | None = None) -> pd.DataFrame:
    """The ray orders' table at every grid point.

    Each distinct trace of the grid is rendered (or found in the trace cache)
    once here; then the points run as the other what-ifs' do: on the base's
    Dask scheduler (``base.dask``; every worker must read the trace cache
    under the same path), else in a local process pool, else one after
    another. The table does not depend on which.

    Parameters
    ----------
    base : analyses.experiment.Experiment
        Scene, image size, spp, seed, bounce limit, mappings, the one process count, caches, layout, cost,
        machine and trace cache; the workload must be ``pathtrace``.
    grid : dict of str to list
        Values per parameter (module docstring); the study runs every combination.
    orders : sequence of str or RayOrder, optional
        Default every registered order (:func:`analyses.report_orders.report_orders`).
    n_jobs : int, optional
        Local worker processes (default: CPUs; 1 runs the points in this process).

    Returns
    -------
    DataFrame
        One row per point, mapping and order: the grid's columns, then the columns of
        :func:`analyses.report_orders.order_section` and :data:`EXTRA_COLUMNS`.

    Raises
    ------
    InputError
        A base that is not path-traced or has other than one process count, or a bad grid or point.
    """
    if base.workload != "pathtrace":
        raise InputError(f"order what-if: the base's workload must be 'pathtrace', got {base.workload!r}")
    if len(base.n_processes) != 1:
        raise InputError(f"order what-if: the base needs one process count, got {list(base.n_processes)}")
    points = grid_points(grid or {})
    local = replace(base, dask=None)
    workers = min((os.cpu_count() or 1) if n_jobs is None else require_int("order what-if n_jobs", n_jobs, 1),
                  len(points))
    if base.dask is None and workers == 1:
        tables = [_point_table(local, point, orders, None) for point in points]
    else:
        # each distinct trace rendered once, before the tasks that read it from the cache run at once
        for point in {_trace_key(point): point for point in points}.values():
            _point_trace(local, point)
        # one thread per task: the tasks already take every CPU
        tasks = [(replace(local, progress=False), point, orders, 1) for point in points]
        tables = _run_tasks(tasks, base.dask, workers)
    return pd.concat(tables, ignore_index=True)


def _run_tasks(tasks: list, dask, workers: int) -> list:
    """``_point_table(*task)`` of every task, in order: on the Dask scheduler ``dask``, else in a pool of
    ``workers`` local processes."""
    if dask is not None:
        from analyses.cluster import dask_executor

        with dask_executor(dask) as executor:
            futures = [executor.submit(_point_table, *task) for task in tasks]
            return [future.result() for future in futures]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(_point_table, *task) for task in tasks]
        return [future.result() for future in futures]


def _trace_key(point: dict) -> tuple:
    """What decides a point's trace: its scene, scene size, samples per pixel and bounce limit."""
    return tuple(point.get(key) for key in ("scene", "scene_size", "spp", "max_depth"))


def _point_experiment(base: Experiment, point: dict) -> Experiment:
    """``base`` with the point's scene, samples per pixel and bounce limit."""
    try:
        return replace(base, **{key: point[key] for key in ("scene", "spp", "max_depth") if key in point})
    except ValueError as error:
        raise InputError(f"order what-if point {point}: {error}") from None


def _point_trace(base: Experiment, point: dict) -> tuple:
    """The point's scene and path-traced trace, from the trace cache (rendered there first if missing)."""
    from analyses.traces import cached_trace
    from analyses.whatif import _sized_scene_file

    experiment = _point_experiment(base, point)
    scene_name = experiment.scene
    if "scene_size" in point:
        scene_name = _sized_scene_file(str(experiment.scene), point["scene_size"], experiment.cache_dir)
    scene, trace, _ = cached_trace(scene_name, experiment.size, cache_dir=experiment.cache_dir,
                                   kd=experiment.kd_builder(), max_depth=experiment.max_depth,
                                   progress=experiment.progress, workload=experiment.trace_workload(),
                                   tree_variant=experiment.tree_variant,
                                   path_samples=(experiment.spp, experiment.seed))
    return scene, trace


def _point_table(base: Experiment, point: dict, orders, n_threads: int | None) -> pd.DataFrame:
    """One grid point's rows (:func:`order_whatif`), its study's runs on ``n_threads`` threads (None: one per
    CPU)."""
    from analyses.report_orders import order_section
    from coherence.studies import Execution, place_layout, study

    experiment = _point_experiment(base, point)
    scene, trace = _point_trace(base, point)
    hierarchy = _levels_of(experiment, {k: v for k, v in point.items() if "." in k})
    layout, cost, machine = experiment.layout_object(), experiment.cost_model(), experiment.machine()
    mappings = experiment.mapping_objects()
    n_processes = int(experiment.n_processes[0])
    runs = study(trace, mappings, sorted({1, n_processes}), hierarchy=hierarchy, layout=layout, cost=cost,
                 machine=machine, scene=scene, progress=False,
                 execution=Execution() if n_threads is None else Execution(n_jobs=n_threads)).runs
    setup = {"mappings": mappings, "hierarchy": hierarchy, "placed": place_layout(layout, trace, scene),
             "cost": cost, "machine": machine, "scene": scene}
    table = order_section(trace, runs, setup, n_processes, orders)
    depth_first = table[table["order"] == "depth-first"].set_index("mapping")["user_seconds_max"]
    table["net_speedup"] = table["mapping"].map(depth_first) / table["user_seconds_max"]
    for key, value in reversed(list(point.items())):
        table.insert(0, key, value)
    return table


def _levels_of(experiment: Experiment, sizes: dict):
    """What a point's runs simulate on, its ``<level>.size`` applied: the experiment's hierarchy, or under a
    platform its shared levels, each size that of one whole level (an ``L3.size`` is one L3's)."""
    from analyses.whatif import _point_levels
    from coherence.shared_run import SharedLevels

    levels = experiment.study_hierarchy()
    if not isinstance(levels, SharedLevels):
        return _point_levels(levels, sizes)
    resized = _point_levels(levels.machine.hierarchy, sizes)
    try:
        machine = replace(levels.machine, hierarchy=resized)
    except ValueError as error:
        raise InputError(f"order what-if point {sizes}: {error}") from None
    return replace(levels, machine=machine)


def save_order_whatif(table: pd.DataFrame, base: Experiment, grid: dict, folder) -> Path:
    """Write ``table`` as ``<folder>/whatif-orders.csv`` with its ``.meta.json`` (the base's parameters and
    the grid), both atomically; returns the CSV's path."""
    from coherence.provenance import provenance, write_csv_atomic

    path = Path(folder) / ORDER_WHATIF_FILE
    meta = provenance(study="orders", experiment=base.as_parameters(),
                      grid={key: [str(v) for v in values] for key, values in grid.items()})
    return write_csv_atomic(table, path, meta)
