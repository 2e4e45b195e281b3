"""The per-scene coherence report: did coherence or load balance decide the speed-up?

>>> from analyses.report import make_report                 # doctest: +SKIP
>>> rep = make_report("balls", out="report-balls")           # doctest: +SKIP
>>> print(rep.verdict.text)                                  # doctest: +SKIP

:func:`build_report` renders the scene once (through the trace cache of
:mod:`analyses.traces`), simulates every mapping at 1..``max_processes``
processes (:func:`coherence.study`), computes miss-ratio curves from reuse
distances, simulates one more run for a per-pixel miss map
(:func:`coherence.miss_map`), and returns a :class:`Report`;
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
from analyses.memory_budget import DEFAULT_MEMORY_BUDGET, memory_shares, runs_at_once, trace_pages_limited
from analyses.output import check_output_folder, prepare_output_folder
from analyses.paper_study import check_process_counts
from analyses.report_curves import miss_ratio_curves
from analyses.report_html import miss_map_png, report_html
from analyses.warmup import simulation_warm_up
from coherence.mappings import DEFAULT_MAPPINGS
from coherence.metrics import DECOMPOSITION_COLUMNS
from rtcommon.files import write_files_atomic
from rtcommon.jsonio import plain, round_number
from rtcommon.validate import require_int

__all__ = ["Report", "build_report", "write_report", "make_report", "check_output_folder", "prepare_output_folder",
           "parse_miss_map", "RESULT_COLUMNS", "SECTIONS", "DEFAULT_MAPPINGS", "MISS_MAP_FILES"]


#: Columns of ``results.csv``.
RESULT_COLUMNS = ("section", "mapping", "n_processes", "item", "metric", "value")

#: What each section of ``results.csv`` holds (``mapping``, ``n_processes``
#: and ``item`` are empty where they do not apply).
SECTIONS = {
    "scene": "scene and render figures: element counts by kind, lights, depth, tree statistics "
             "(item 'tree'), counter totals (item 'totals'), image width and height",
    "scene_bytes": "item = record kind or 'total': metric 'bytes', and 'fraction_of_<level>' = bytes / cache size",
    "cache": "item = cache level: size, line_size, ways, latency; item 'memory': latency",
    "runs": "one group per (mapping, n_processes): every numeric column of coherence.study's run table "
            "(speed-ups, efficiency and its factors and losses, hit rates, misses per ray, cycles)",
    "processes": "item = process index, at the verdict's and the largest process count: user, compute, memory "
                 "and dispatch cycles and pixels",
    "miss_ratio": "mapping = pixel order of the one-process stream, item = cache size in bytes: "
                  "metric 'miss_ratio_<line>B' of a fully associative LRU cache with <line>-byte lines",
    "cost_map": "compute cycles per pixel (cost model): min, mean, max, total",
    "texture": "textured scenes only; item = cache level, at the verdict's process count: texel_reads, "
               "texel_misses, misses_per_texel_read, texture_miss_share (texel misses / the level's misses), "
               "each process on a cold hierarchy of its own (coherence.kind_misses)",
    "texture_layouts": "textured scenes only; mapping, item = '<texel order> <level>': texel_hit_rate",
    "texture_miss_ratio": "textured scenes only; mapping = texel order (the texel reads alone, scan order), "
                          "item = cache size in bytes: metric 'miss_ratio_<line>B' (fully associative LRU)",
    "miss_map": "mapping and n_processes of the miss map's run, item = cache level: misses per pixel summed "
                "('total'), their mean and largest, and the share of the total made by the 1% of pixels "
                "that miss most ('top_1pct_share')",
    "verdict": "every number the verdict prints, exactly as printed (percentages in percent)",
}

#: Files of the miss map beside the page: the per-pixel array and its figure.
MISS_MAP_FILES = ("miss_map.npy", "miss_map.png")

_PROCESS_COLUMNS = ("pixels", "user_cycles", "compute_cycles", "memory_cycles", "dispatch_cycles")
_SIGNIFICANT = 6


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


def _process_counts(max_processes, n_processes) -> list[int]:
    if n_processes is not None:
        return check_process_counts(n_processes)
    if isinstance(max_processes, bool) or not isinstance(max_processes, (int, np.integer)) or max_processes < 1:
        raise ValueError(f"max_processes must be an integer >= 1, got {max_processes!r}")
    return list(range(1, int(max_processes) + 1))


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
            raise ValueError(f"{option} must be MAPPING:N, a mapping and a process count such as P:8, "
                             f"got {value!r}")
        value = (name, int(count))
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise ValueError(f"{option} must be 'MAPPING:N' or a (mapping, n_processes) pair, got {value!r}")
    try:
        mapping = get_mapping(value[0])
    except ValueError as error:
        raise ValueError(f"{option}: {error}") from None
    return mapping, require_int(f"{option} process count", value[1], 1)


# --------------------------------------------------------------------------
# building


def build_report(scene="balls", size: int = 512, *, mappings=DEFAULT_MAPPINGS, max_processes: int = 16,
                 n_processes=None, background: int = 4, n_cpus: int = 8, hierarchy="alpha21164",
                 layout="compact", cost="alpha8400", kd: str | None = None, max_depth: int | None = None,
                 cache_dir=None, out=None, progress: bool = True, workload: str = "modern",
                 miss_map=None, dask=None, memory_budget: int = DEFAULT_MEMORY_BUDGET) -> Report:
    """Render (or load) a scene's trace, simulate the mappings and assemble the report.

    Parameters
    ----------
    scene : str or os.PathLike
        Built-in scene name or NFF/OBJ path.
    size : int
        Image width and height.
    mappings : sequence of str or Mapping
        Mappings to compare (default S, P, R, B, DB).
    max_processes : int
        Simulate 1..max_processes processes.
    n_processes : sequence of int, optional
        Explicit process counts instead (1 is always added).
    background : int
        Always-runnable processes of other users, for the real-time speed-up.
    n_cpus : int
        CPUs of the simulated machine.
    hierarchy, layout, cost : preset name or object
    kd : {"sah", "median"}, optional
        kd-tree builder; default the workload's (sah for ``modern``).
    max_depth : int, optional
    cache_dir : path, optional
        Trace cache folder (see :func:`analyses.traces.cached_trace`).
    workload : str
        The tracer imitated (:data:`tracer.rendering.workload.WORKLOADS`: ``modern``,
        the default, or the study's ``study1997``).
    out : path, optional
        Output folder to create and check for writing once the arguments
        are valid, before the long work (:func:`write_report` writes it).
    progress : bool
        Progress bars on stderr.
    miss_map : str or (str or Mapping, int), optional
        The run whose misses per pixel the report maps, as ``"MAPPING:N"``
        or ``(mapping, n_processes)`` (any mapping, not only the compared
        ones). Default: the compared mapping that loses most to coherence at
        the verdict's process count (8 if simulated, else the largest), at
        that count: its misses are the ones the verdict weighs.
    dask : str or distributed.Client, optional
        Simulate the runs on that Dask scheduler (:mod:`analyses.cluster`);
        the trace cache must be readable by every worker under the same path.
        The report is the same as a local one.
    memory_budget : int
        Bytes the whole process may take. What the process and its runs
        need per pixel is set aside and the rest is split by
        :func:`analyses.memory_budget.memory_shares` between a render's
        records, the runs' shared line addresses and the trace's pages
        resident while it is read, so the trace's length does not matter.
        Results do not depend on it.

    Returns
    -------
    Report
    """
    from cachesim import get_hierarchy
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.simulation import Machine

    from analyses.traces import _scene_identity, cached_trace, check_cache_dir
    from tracer.rendering.workload import get_workload

    # everything that can be wrong with the arguments fails here, before rendering
    mapping_objects = [get_mapping(m) for m in mappings]
    names = [m.name for m in mapping_objects]
    if not names:
        raise ValueError("give at least one mapping")
    if len(set(names)) != len(names):
        raise ValueError(f"mappings must be distinct, got {names}")
    counts = _process_counts(max_processes, n_processes)
    size = require_int("size", size, 1)
    n_jobs = runs_at_once(memory_budget, size * size, os.cpu_count() or 1)  # the same with --dask: same outputs
    shares = memory_shares(memory_budget, size * size, n_jobs)
    miss_map = parse_miss_map(miss_map)
    hierarchy = get_hierarchy(hierarchy)
    layout = get_layout(layout)
    cost = get_cost_model(cost)
    machine = Machine(n_cpus=n_cpus, background_load=background)
    kd = kd or get_workload(workload).kd_config.builder
    _scene_identity(scene)  # unknown name or missing file
    check_cache_dir(cache_dir)
    if out is not None:
        prepare_output_folder(out)

    # a first run compiles the simulation's kernels in a second process while this one renders
    with simulation_warm_up(hierarchy, layout, cost, machine, mapping_objects, enabled=dask is None) as warm:
        scene_obj, trace, info = cached_trace(scene, size, cache_dir=cache_dir, kd=kd, max_depth=max_depth,
                                              progress=progress, workload=workload,
                                              memory_budget=shares["render_records"])
        warm.wait(progress=progress)
    with dask_executor(dask) as executor, trace_pages_limited(trace, shares):
        return _assemble(scene_obj, trace, info, mapping_objects, counts, hierarchy, layout, cost, machine,
                         size, kd, progress, miss_map, executor, shares, n_jobs)


def _assemble(scene, trace, info, mapping_objects, counts, hierarchy, layout, cost, machine, size, kd, progress,
              miss_map_choice, executor, shares, n_jobs):
    from coherence.missmap import miss_map
    from coherence.studies import place_layout, study
    from tracer.trace.access import COUNTER_NAMES

    from analyses.verdict import verdict as compute_verdict

    names = [m.name for m in mapping_objects]
    placed = place_layout(layout, trace, scene)
    result = study(trace, mapping_objects, counts, hierarchy=hierarchy, layout=layout, cost=cost,
                   machine=machine, scene=scene, progress=progress, executor=executor, n_jobs=n_jobs,
                   trace_folder=Path(info["path"]) / "trace", shared_lines_budget=shares["shared_lines"])
    runs = result.runs
    processes = result.processes

    verdict_n = 8 if 8 in counts else max(counts)
    top_n = max(counts)
    verdict = compute_verdict(runs, verdict_n, order=names)

    if miss_map_choice is None:
        worst = verdict.worst["coherence_loss"][0]
        miss_map_choice = (next(m for m in mapping_objects if m.name == worst), verdict_n)
        chosen_by = f"default: the mapping that loses most to coherence at {verdict_n} processes"
    else:
        chosen_by = "given"
    misses = miss_map(trace, *miss_map_choice, hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
                      scene=scene)
    miss_totals = misses.totals()

    curves = miss_ratio_curves(trace, placed, mapping_objects, hierarchy, progress)
    texture = None
    if trace.metadata.get("textures"):
        from analyses.report_texture import texture_section

        texture = texture_section(trace, scene, layout, hierarchy, mapping_objects, verdict_n, cost)
    compute = cost.compute_cycles(trace.counters, COUNTER_NAMES)
    cost_map = compute.reshape(trace.height, trace.width)
    region = placed.region_bytes()
    scene_bytes = pd.DataFrame({"kind": [k for k, v in region.items() if v > 0] + ["total"],
                                "bytes": [v for v in region.values() if v > 0] + [placed.scene_bytes]})
    caches = pd.DataFrame({"level": [lv.name for lv in hierarchy.levels], "size": [lv.size for lv in hierarchy.levels],
                           "line_size": [lv.line_size for lv in hierarchy.levels],
                           "ways": [lv.ways for lv in hierarchy.levels],
                           "latency": [lv.latency for lv in hierarchy.levels]})

    summary_scene = scene.summary()
    tree = {k: v for k, v in info["tree"].items() if not k.endswith("_seconds")}
    totals = dict(info["totals"])
    results = _results_table(summary_scene, tree, totals, trace, scene_bytes, caches, hierarchy, runs, processes,
                             curves, cost_map, verdict, verdict_n, top_n, misses, miss_totals)
    if texture is not None:
        results = pd.concat([results, _texture_rows(texture, verdict_n)], ignore_index=True)
    parameters = {
        "scene": scene.name, "size": int(size), "kd": kd, "workload": info.get("workload", "modern"),
        "max_depth": int(scene.max_depth),
        "mappings": names, "n_processes": counts, "verdict_n_processes": verdict_n,
        "background_load": int(machine.background_load), "n_cpus": int(machine.n_cpus),
        "machine": result.parameters["machine"], "hierarchy": hierarchy.to_dict(), "layout": layout.name,
        "cost": cost.to_dict(), "trace_key": info["key"], "memory_shares": shares, "runs_at_once": n_jobs,
        "miss_map": {"mapping": misses.mapping, "n_processes": misses.n_processes, "chosen_by": chosen_by},
    }
    if texture is not None:
        parameters["texture"] = {"texel_order": layout.texels.label, "n_processes": verdict_n,
                                 "filter": trace.metadata.get("texture_filter"),
                                 "textures": trace.metadata["textures"]}
    summary = _summary(parameters, summary_scene, tree, runs, verdict, verdict_n, top_n, names, scene_bytes,
                       _miss_map_summary(misses, _miss_map_dtype(misses)))
    miss_png = miss_map_png(misses)
    page = report_html(scene, info, parameters, summary_scene, tree, totals, runs, processes, curves, cost_map,
                       scene_bytes, caches, verdict, verdict_n, top_n, names, hierarchy, mapping_objects, trace, progress,
                       miss_png, miss_totals, texture=texture)
    return Report(results=results, summary=summary, html=page, runs=runs, processes=processes, curves=curves,
                  scene_bytes=scene_bytes, cost_map=cost_map, verdict=verdict, render_info=info, miss_map=misses,
                  miss_map_png=miss_png)


def _texture_rows(texture: dict, n_processes: int) -> pd.DataFrame:
    """The texture sections of ``results.csv`` (see :data:`SECTIONS`)."""
    rows = []
    for _, row in texture["share"].iterrows():
        for metric in ("texel_reads", "texel_misses", "misses_per_texel_read", "texture_miss_share"):
            rows.append(("texture", row["mapping"], n_processes, row["level"], metric, _round(row[metric])))
    for _, row in texture["layouts"].iterrows():
        rows.append(("texture_layouts", row["mapping"], n_processes, f"{row['layout']} {row['level']}",
                     "texel_hit_rate", _round(row["texel_hit_rate"])))
    for _, point in texture["curves"].iterrows():
        rows.append(("texture_miss_ratio", point["layout"], 1, str(int(point["size"])),
                     f"miss_ratio_{int(point['line_size'])}B", _round(point["miss_ratio"])))
    return _rows_table(rows)


def _miss_map_dtype(misses) -> np.dtype:
    """uint32 (half of int64's bytes) unless a count does not fit."""
    return np.dtype(np.uint32) if int(misses.misses.max(initial=0)) <= np.iinfo(np.uint32).max \
        else np.dtype(np.int64)


def _miss_map_summary(misses, dtype) -> dict:
    """What summary.json says about miss_map.npy."""
    return {"file": MISS_MAP_FILES[0], "figure": MISS_MAP_FILES[1], "mapping": misses.mapping,
            "n_processes": misses.n_processes, "shape": list(misses.misses.shape), "axes": ["y", "x", "level"],
            "levels": list(misses.levels), "dtype": dtype.str,
            "what": "misses of each pixel at each cache level (reads and writes), on the caches of the CPU "
                    "its process rendered it on; row 0 is the image's top"}


# --------------------------------------------------------------------------
# result table and summary


def _round(value):
    """Ints stay ints; floats get six significant digits (integral ones become ints); NaN/inf become None."""
    return round_number(value, _SIGNIFICANT, integral_as_int=True)


def _results_table(scene_summary, tree, totals, trace, scene_bytes, caches, hierarchy, runs, processes, curves,
                   cost_map, verdict, verdict_n, top_n, misses, miss_totals) -> pd.DataFrame:
    rows = []

    def add(section, metric, value, mapping=None, n=None, item=None):
        rows.append((section, mapping, n, item, metric, _round(value)))

    add("scene", "elements", scene_summary["elements"])
    for kind, count in scene_summary["counts"].items():
        add("scene", kind, count, item="elements")
    for key in ("materials", "lights", "max_depth"):
        add("scene", key, scene_summary[key])
    add("scene", "width", trace.width)
    add("scene", "height", trace.height)
    for key, value in tree.items():
        if isinstance(value, (int, float, np.number)):
            add("scene", key, value, item="tree")
    for key, value in totals.items():
        add("scene", key, value, item="totals")
    for kind, size in zip(scene_bytes["kind"], scene_bytes["bytes"]):
        add("scene_bytes", "bytes", size, item=kind)
        for level, cache_size in zip(caches["level"], caches["size"]):
            add("scene_bytes", f"fraction_of_{level}", size / cache_size, item=kind)
    for _, cache in caches.iterrows():
        for column in ("size", "line_size", "ways", "latency"):
            add("cache", column, cache[column], item=cache["level"])
    add("cache", "latency", hierarchy.memory_latency, item="memory")
    skip = {"mapping", "n_processes"}
    for _, run in runs.iterrows():
        for column in runs.columns:
            if column not in skip and isinstance(run[column], (int, float, np.number)):
                add("runs", column, run[column], mapping=run["mapping"], n=int(run["n_processes"]))
    for n in sorted({verdict_n, top_n}):
        for _, process in processes[processes["n_processes"] == n].iterrows():
            for column in _PROCESS_COLUMNS:
                add("processes", column, process[column], mapping=process["mapping"], n=n,
                    item=str(int(process["process"])))
    for _, point in curves.iterrows():
        add("miss_ratio", f"miss_ratio_{int(point['line_size'])}B", point["miss_ratio"], mapping=point["order"],
            n=1, item=str(int(point["size"])))
    add("cost_map", "min_cycles_per_pixel", cost_map.min())
    add("cost_map", "mean_cycles_per_pixel", cost_map.mean())
    add("cost_map", "max_cycles_per_pixel", cost_map.max())
    add("cost_map", "total_cycles", cost_map.sum())
    for _, level in miss_totals.iterrows():
        for metric in ("total", "mean_per_pixel", "max_per_pixel", "top_1pct_share"):
            add("miss_map", metric, level[metric], mapping=misses.mapping, n=misses.n_processes, item=level["level"])
    for _, number in verdict.numbers.iterrows():
        add("verdict", number["metric"], number["value"], mapping=number["mapping"], n=int(number["n_processes"]))
    return _rows_table(rows)


def _rows_table(rows) -> pd.DataFrame:
    """``results.csv``'s table of ``(section, mapping, n_processes, item, metric, value)`` tuples."""
    columns = list(zip(*rows)) if rows else [()] * len(RESULT_COLUMNS)
    table = pd.DataFrame({name: pd.Series(list(values), dtype=object) for name, values in zip(RESULT_COLUMNS, columns)})
    table["n_processes"] = table["n_processes"].astype("Int64")
    return table


def _clean(value):
    return plain(value, _SIGNIFICANT, integral_as_int=True)


def _summary(parameters, scene_summary, tree, runs, verdict, verdict_n, top_n, names, scene_bytes,
             miss_map) -> dict:
    from rtcommon.versions import package_versions

    headline = {}
    for n in sorted({verdict_n, top_n}):
        at_n = runs[runs["n_processes"] == n].set_index("mapping")
        headline[str(n)] = {name: {column: at_n.loc[name, column] for column in DECOMPOSITION_COLUMNS}
                            for name in names}
    return _clean({
        "report": "coherence report",
        "parameters": parameters,
        "versions": package_versions(),
        "scene": scene_summary,
        "tree": tree,
        "scene_bytes": dict(zip(scene_bytes["kind"], scene_bytes["bytes"])),
        "headline": headline,
        "verdict": {"n_processes": verdict_n, "decided_by": verdict.decided_by, "headline": verdict.headline,
                    "sentences": verdict.sentences, "text": verdict.text,
                    "numbers": verdict.numbers.to_dict(orient="records")},
        "miss_map": miss_map,
        "results_csv": {"columns": list(RESULT_COLUMNS), "sections": SECTIONS},
    })


# --------------------------------------------------------------------------
# writing


def write_report(report: Report, out) -> Path:
    """Write ``index.html``, ``results.csv``, ``summary.json`` and, with a miss map, ``miss_map.npy`` and
    ``miss_map.png`` into ``out`` as one unit (see :func:`rtcommon.files.write_files_atomic`)."""
    path = prepare_output_folder(out)
    files = {path / "results.csv": report.results.to_csv(index=False, lineterminator="\n"),
             path / "summary.json": json.dumps(report.summary, indent=2, allow_nan=False) + "\n",
             path / "index.html": report.html}
    if report.miss_map is not None:
        buffer = io.BytesIO()
        np.save(buffer, report.miss_map.misses.astype(_miss_map_dtype(report.miss_map)), allow_pickle=False)
        files[path / MISS_MAP_FILES[0]] = buffer.getvalue()
        files[path / MISS_MAP_FILES[1]] = report.miss_map_png
    # one unit: all are complete before any is renamed into place
    write_files_atomic(files)
    return path


def make_report(scene="balls", out=None, **options) -> Report:
    """Build the report and write it to ``out`` (default ``report-<scene>``); see :func:`build_report`."""
    if out is None:
        out = f"report-{Path(os.fspath(scene)).stem.lower()}"
    report = build_report(scene, out=out, **options)
    write_report(report, out)
    return report
