"""The per-scene coherence report: did coherence or load balance decide the speed-up?

>>> from analyses.report import make_report                 # doctest: +SKIP
>>> rep = make_report("balls", out="report-balls")           # doctest: +SKIP
>>> print(rep.verdict.text)                                  # doctest: +SKIP

:func:`build_report` renders the scene once (through the trace cache of
:mod:`analyses.traces`), simulates every mapping at the
:class:`~analyses.experiment.Experiment`'s process counts (:func:`coherence.study`),
computes miss-ratio curves from reuse
distances, simulates one more run for a per-pixel miss map
(:func:`coherence.miss_map`; under a platform on its shared levels, as the
study's runs), and returns a :class:`Report`;
:func:`write_report` writes its files into a folder:

``index.html``
    One self-contained page (figures embedded as base64 PNG, styles inline,
    no external references).
``results.csv``
    Every number of the report in tidy long form, one row per
    (section, mapping, n_processes, item, metric) with its ``value``; see
    :data:`RESULT_COLUMNS` and :data:`SECTIONS`.
``summary.json``
    Parameters, package versions, scene summary, headline numbers per
    mapping and the verdict.
``miss_map.npy``
    Misses per pixel per cache level of one run (the miss map's mapping and
    process count are in ``summary.json``): a (H, W, L) array, rows from the
    image's top, levels first level first; uint32 (int64 if a count does
    not fit), readable with ``numpy.load``.
``miss_map.png``
    The miss map drawn, one panel per level (also in ``index.html``).

Outputs are deterministic: no timestamps or timings, floats rounded to six
significant digits, figures saved without metadata; the files are written to
temporary names and renamed together.
"""
from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.cluster import dask_executor
from analyses.experiment import Experiment
from analyses.memory_budget import memory_shares, runs_at_once, trace_pages_limited
from analyses.output import check_output_folder, prepare_output_folder
from analyses.report_curves import miss_ratio_curves
from analyses.report_html import miss_map_png, report_html
from analyses.report_tables import (MISS_MAP_FILES, RESULT_COLUMNS, SECTIONS, ReportInputs, miss_map_dtype,
                                    results_table, summary)
from analyses.warmup import simulation_warm_up
from coherence.mappings import DEFAULT_MAPPINGS
from rtcommon.files import write_files_atomic
from rtcommon.validate import InputError, require_int

__all__ = ["Report", "build_report", "write_report", "make_report", "check_output_folder", "prepare_output_folder",
           "parse_miss_map", "RESULT_COLUMNS", "SECTIONS", "DEFAULT_MAPPINGS", "REPORT_FILES", "MISS_MAP_FILES",
           "Experiment"]


@dataclass
class Report:
    """Everything a coherence report shows.

    Attributes
    ----------
    results : DataFrame
        The long-form table written to ``results.csv`` (:data:`RESULT_COLUMNS`).
    summary : dict
        What ``summary.json`` holds.
    html : str
        The page ``index.html``.
    runs, processes : DataFrame
        The study's tables.
    curves : DataFrame
        Miss-ratio curves: order, line_size, size, capacity_lines, misses, miss_ratio.
    scene_bytes : DataFrame
        kind, bytes.
    cost_map : ndarray, shape (H, W)
        Compute cycles per pixel.
    verdict : analyses.verdict.Verdict
    render_info : dict
        From :func:`analyses.traces.cached_trace` (``cached`` tells whether
        the trace came from the cache).
    miss_map : coherence.missmap.MissMap or None
        Misses per pixel per level of the miss map's run.
    miss_map_png : bytes
        Its figure, one panel per level (written as ``miss_map.png``).
    """

    results: pd.DataFrame
    summary: dict
    html: str
    runs: pd.DataFrame
    processes: pd.DataFrame
    curves: pd.DataFrame
    scene_bytes: pd.DataFrame
    cost_map: np.ndarray
    verdict: object
    render_info: dict = field(default_factory=dict)
    miss_map: object = None
    miss_map_png: bytes = b""


# --------------------------------------------------------------------------
# validation (before any long work)


def parse_miss_map(value, option: str = "miss_map"):
    """The miss map's run as ``(Mapping, n_processes)``, from ``"MAPPING:N"`` or a pair; None stays None.

    Raises
    ------
    ValueError
        Naming ``option``: not of the form MAPPING:N, an unknown mapping, or N not an integer >= 1.
    """
    from coherence.mappings import get_mapping

    if value is None:
        return None
    if isinstance(value, str):
        name, colon, count = value.rpartition(":")
        if not colon or not name or not count.strip().isdigit():
            raise InputError(f"{option} must be MAPPING:N, a mapping and a process count such as P:8, "
                             f"got {value!r}")
        value = (name, int(count))
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"{option} must be 'MAPPING:N' or a (mapping, n_processes) pair, got {value!r}")
    try:
        mapping = get_mapping(value[0])
    except ValueError as error:
        raise InputError(f"{option}: {error}") from None
    return mapping, require_int(f"{option} process count", value[1], 1)


# --------------------------------------------------------------------------
# building


@dataclass(frozen=True)
class _Setup:
    """A report's choices resolved into the simulation's objects, before any long work."""

    experiment: Experiment
    mappings: list
    counts: list
    hierarchy: object
    layout: object
    cost: object
    machine: object
    kd: str
    miss_map: tuple | None
    shares: dict
    n_jobs: int


def build_report(experiment: Experiment, *, out=None, miss_map=None) -> Report:
    """Render (or load) a scene's trace, simulate the mappings and assemble the report.

    Parameters
    ----------
    experiment : analyses.experiment.Experiment
        Scene, image size, workload, mappings, process counts (1 is always
        added), machine, memory layout, cost model, trace cache, Dask
        scheduler, memory budget and progress bars. The runs are the same
        on a Dask scheduler as locally, and no result depends on the memory
        budget: it only decides how much of the trace is resident
        (:func:`analyses.memory_budget.memory_shares`).
    out : path, optional
        Output folder to create and check for writing once the arguments
        are valid, before the long work (:func:`write_report` writes it).
    miss_map : str or (str or Mapping, int), optional
        The run whose misses per pixel the report maps, as ``"MAPPING:N"``
        or ``(mapping, n_processes)`` (any mapping, not only the compared
        ones). Default: the compared mapping that loses most to coherence at
        the verdict's process count (8 if simulated, else the largest), at
        that count: its misses are the ones the verdict weighs.

    Returns
    -------
    Report
    """
    from analyses.traces import _scene_identity, cached_trace, check_cache_dir

    if not isinstance(experiment, Experiment):
        raise InputError(f"build_report needs an analyses.experiment.Experiment, got {type(experiment).__name__}; "
                         "make_report(scene, out, **choices) builds one")
    # everything that can be wrong with the arguments fails here, before rendering
    pixels = experiment.size * experiment.size
    n_jobs = runs_at_once(experiment.memory_budget, pixels, os.cpu_count() or 1)  # the same with dask: same outputs
    setup = _Setup(experiment=experiment, mappings=experiment.mapping_objects(),
                   counts=sorted({1, *experiment.n_processes}), hierarchy=experiment.hierarchy_object(),
                   layout=experiment.layout_object(), cost=experiment.cost_model(), machine=experiment.machine(),
                   kd=experiment.kd_builder(), miss_map=parse_miss_map(miss_map),
                   shares=memory_shares(experiment.memory_budget, pixels, n_jobs), n_jobs=n_jobs)
    _scene_identity(experiment.scene)  # unknown name or missing file
    check_cache_dir(experiment.cache_dir)
    if out is not None:
        prepare_output_folder(out)

    # a first run compiles the simulation's kernels in a second process while this one renders
    progress = experiment.progress
    with simulation_warm_up(setup.hierarchy, setup.layout, setup.cost, setup.machine, setup.mappings,
                            enabled=experiment.dask is None) as warm:
        scene, trace, info = cached_trace(experiment.scene, experiment.size, cache_dir=experiment.cache_dir,
                                          kd=setup.kd, max_depth=experiment.max_depth, progress=progress,
                                          workload=experiment.trace_workload(),
                                          tree_variant=experiment.tree_variant,
                                          path_samples=(experiment.spp, experiment.seed),
                                          memory_budget=setup.shares["render_records"])
        warm.wait(progress=progress)
    with dask_executor(experiment.dask) as executor, trace_pages_limited(trace, setup.shares):
        return _assemble(setup, scene, trace, info, executor)


def _assemble(setup: _Setup, scene, trace, info, executor) -> Report:
    from coherence.missmap import MissMap, miss_map
    from coherence.studies import Execution, place_layout, study
    from tracer.trace.access import COUNTER_NAMES

    from analyses.verdict import verdict as compute_verdict, verdict_process_count

    experiment, hierarchy, layout, cost, counts = setup.experiment, setup.hierarchy, setup.layout, setup.cost, \
        setup.counts
    names = [m.name for m in setup.mappings]
    placed = place_layout(layout, trace, scene)
    verdict_n = verdict_process_count(counts)
    # under a platform the study's runs at the miss map's count keep their misses per pixel: the map is one of them
    mapped_n = verdict_n if setup.miss_map is None else setup.miss_map[1]
    execution = Execution(n_jobs=setup.n_jobs, executor=executor, trace_folder=Path(info["path"]) / "trace",
                          shared_lines_budget=setup.shares["shared_lines"],
                          pixel_misses_at=() if experiment.platform is None else (mapped_n,))
    result = study(trace, setup.mappings, counts, hierarchy=experiment.study_hierarchy(), layout=layout, cost=cost,
                   machine=setup.machine, scene=scene, progress=experiment.progress, execution=execution)
    runs = result.runs

    verdict = compute_verdict(runs, verdict_n, order=names)

    miss_map_choice = setup.miss_map
    if miss_map_choice is None:
        worst = verdict.worst["coherence_loss"][0]
        miss_map_choice = (next(m for m in setup.mappings if m.name == worst), verdict_n)
        chosen_by = f"default: the mapping that loses most to coherence at {verdict_n} processes"
    else:
        chosen_by = "given"
    kept = result.pixel_misses.get((miss_map_choice[0].name, miss_map_choice[1]))
    if kept is not None:
        misses = MissMap(kept, tuple(experiment.study_hierarchy().hierarchy.level_names), scene.name,
                         miss_map_choice[0].name, miss_map_choice[1])
    else:  # under a platform the run on its shared levels, as the study's
        misses = miss_map(trace, *miss_map_choice, layout=layout, cost=cost, machine=setup.machine, scene=scene,
                          hierarchy=hierarchy if experiment.platform is None else experiment.study_hierarchy())

    texture = None
    if trace.metadata.get("textures"):
        from analyses.report_texture import texture_section

        # under a platform its share and layouts come from runs on the shared levels, as the study's
        texture = texture_section(trace, scene, layout, hierarchy, setup.mappings, verdict_n, cost,
                                  shared=None if experiment.platform is None else experiment.study_hierarchy(),
                                  machine=setup.machine)
    ray_orders = None
    if trace.segments is not None and not setup.machine.page_placement.translates:
        from analyses.report_orders import order_section

        worst = next(m for m in setup.mappings if m.name == verdict.worst["coherence_loss"][0])
        # on the levels the study ran on: under a platform its shared levels, as the depth-first row's run
        ray_orders = order_section(trace, runs, {"mappings": [worst], "hierarchy": experiment.study_hierarchy(),
                                                 "placed": placed, "cost": cost, "machine": setup.machine,
                                                 "scene": scene}, verdict_n)
    cost_map = cost.compute_cycles(trace.counters, COUNTER_NAMES).reshape(trace.height, trace.width)
    region = placed.region_bytes()
    scene_bytes = pd.DataFrame({"kind": [k for k, v in region.items() if v > 0] + ["total"],
                                "bytes": [v for v in region.values() if v > 0] + [placed.scene_bytes]})
    recorded = experiment.recorded_hierarchy()  # under a platform: whole shared levels, not one thread's share
    caches = pd.DataFrame({"level": [lv.name for lv in recorded.levels], "size": [lv.size for lv in recorded.levels],
                           "line_size": [lv.line_size for lv in recorded.levels],
                           "ways": [lv.ways for lv in recorded.levels],
                           "latency": [lv.latency for lv in recorded.levels]})

    # the experiment's record, with what this run resolved (the scene's name and depth, 1 among the counts)
    parameters = {
        **experiment.as_parameters(),
        "scene": scene.name, "size": int(experiment.size), "kd": setup.kd,
        "workload": info.get("workload", "modern"), "max_depth": int(scene.max_depth),
        "mappings": names, "n_processes": counts, "verdict_n_processes": verdict_n,
        "machine": result.parameters["machine"], "hierarchy": recorded.to_dict(), "layout": layout.name,
        "cost": cost.to_dict(), "trace_key": info["key"], "memory_shares": setup.shares,
        "runs_at_once": setup.n_jobs,
        "miss_map": {"mapping": misses.mapping, "n_processes": misses.n_processes, "chosen_by": chosen_by},
    }
    if texture is not None:
        parameters["texture"] = {"texel_order": layout.texels.label, "n_processes": verdict_n,
                                 "filter": trace.metadata.get("texture_filter"),
                                 "textures": trace.metadata["textures"]}
    inputs = ReportInputs(
        experiment=experiment, scene=scene, trace=trace, info=info, mappings=setup.mappings, names=names,
        hierarchy=hierarchy, counts=counts, verdict_n=verdict_n, top_n=max(counts), runs=runs,
        processes=result.processes, verdict=verdict,
        # the curves take no machine; their sizes and line sizes are those of the levels the runs used
        curves=miss_ratio_curves(trace, placed, setup.mappings, hierarchy if experiment.platform is None else recorded,
                                 experiment.progress),
        cost_map=cost_map, scene_bytes=scene_bytes, caches=caches, misses=misses, miss_totals=misses.totals(),
        scene_summary=scene.summary(), tree={k: v for k, v in info["tree"].items() if not k.endswith("_seconds")},
        totals=dict(info["totals"]), parameters=parameters, texture=texture, ray_orders=ray_orders)
    miss_png = miss_map_png(misses)
    return Report(results=results_table(inputs), summary=summary(inputs), html=report_html(inputs, miss_png),
                  runs=runs, processes=result.processes, curves=inputs.curves, scene_bytes=scene_bytes,
                  cost_map=cost_map, verdict=verdict, render_info=info, miss_map=misses, miss_map_png=miss_png)


# --------------------------------------------------------------------------
# writing


#: The files :func:`write_report` always writes, by what they hold (with a miss map
#: also :data:`MISS_MAP_FILES`): the names readers, tests and ``--help`` use.
REPORT_FILES = {"page": "index.html", "results": "results.csv", "summary": "summary.json"}


def write_report(report: Report, out) -> Path:
    """Write ``index.html``, ``results.csv``, ``summary.json`` (:data:`REPORT_FILES`) and, with a miss map,
    ``miss_map.npy`` and ``miss_map.png`` (:data:`MISS_MAP_FILES`) into ``out`` as one unit (see
    :func:`rtcommon.files.write_files_atomic`)."""
    path = prepare_output_folder(out)
    files = {path / REPORT_FILES["results"]: report.results.to_csv(index=False, lineterminator="\n"),
             path / REPORT_FILES["summary"]: json.dumps(report.summary, indent=2, allow_nan=False) + "\n",
             path / REPORT_FILES["page"]: report.html}
    if report.miss_map is not None:
        buffer = io.BytesIO()
        np.save(buffer, report.miss_map.misses.astype(miss_map_dtype(report.miss_map)), allow_pickle=False)
        files[path / MISS_MAP_FILES[0]] = buffer.getvalue()
        files[path / MISS_MAP_FILES[1]] = report.miss_map_png
    # one unit: all are complete before any is renamed into place
    write_files_atomic(files)
    return path


def make_report(scene="balls", out=None, *, miss_map=None, **choices) -> Report:
    """Build the report of ``Experiment(scene=scene, **choices)`` and write it to ``out``.

    ``out`` defaults to ``report-<scene>``; ``choices`` are fields of
    :class:`analyses.experiment.Experiment` (``size``, ``mappings``,
    ``n_processes``, ``background``, ...); see :func:`build_report`.
    """
    if out is None:
        out = f"report-{Path(os.fspath(scene)).stem.lower()}"
    report = build_report(Experiment(scene=scene, **choices), out=out, miss_map=miss_map)
    write_report(report, out)
    return report
