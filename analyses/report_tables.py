"""What a report computed, and its tables: ``results.csv``'s rows and ``summary.json``.

:class:`ReportInputs` bundles every piece :func:`analyses.report.build_report`
computes, so the steps that shape them (:func:`results_table`,
:func:`summary`, :func:`analyses.report_html.report_html`) take one argument
instead of a list of positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from analyses.plots import _bytes_text
from coherence.metrics import DECOMPOSITION_COLUMNS
from rtcommon.jsonio import plain, round_number

__all__ = ["ReportInputs", "RESULT_COLUMNS", "SECTIONS", "MISS_MAP_FILES", "results_table", "texture_rows",
           "miss_map_dtype", "miss_map_summary", "summary"]


@dataclass(frozen=True)
class ReportInputs:
    """Everything a report's page and tables are made from.

    Attributes
    ----------
    experiment : analyses.experiment.Experiment
        The choices the report was asked for.
    scene : tracer.scenes.model.Scene
    trace : tracer.trace.access.AccessTrace
    info : dict
        Render information from :func:`analyses.traces.cached_trace`.
    mappings : list of coherence.mappings.Mapping
        The compared mappings, in order; ``names`` their names.
    names : list of str
    hierarchy : cachesim.Hierarchy
    counts : list of int
        Simulated process counts (1 included).
    verdict_n, top_n : int
        The verdict's process count (8 if simulated, else the largest) and
        the largest.
    runs, processes : DataFrame
        The study's tables (:func:`coherence.studies.study`).
    verdict : analyses.verdict.Verdict
    curves : DataFrame
        Miss-ratio curves (:func:`analyses.report_curves.miss_ratio_curves`).
    cost_map : ndarray, shape (H, W)
        Compute cycles per pixel.
    scene_bytes : DataFrame
        kind, bytes.
    caches : DataFrame
        level, size, line_size, ways, latency.
    misses : coherence.missmap.MissMap
        The miss map's run; ``miss_totals`` its :meth:`~coherence.missmap.MissMap.totals`.
    miss_totals : DataFrame
    scene_summary, tree, totals : dict
        The scene's summary, the kd-tree's statistics (no timings) and the
        render's counter totals.
    parameters : dict
        What ``summary.json`` records as the report's parameters.
    texture : dict or None
        :func:`analyses.report_texture.texture_section`'s tables of a
        textured scene.
    ray_orders : DataFrame or None
        :func:`analyses.report_orders.order_section`'s table of a
        path-traced trace.
    """

    experiment: object
    scene: object
    trace: object
    info: dict
    mappings: list
    names: list
    hierarchy: object
    counts: list
    verdict_n: int
    top_n: int
    runs: pd.DataFrame
    processes: pd.DataFrame
    verdict: object
    curves: pd.DataFrame
    cost_map: np.ndarray
    scene_bytes: pd.DataFrame
    caches: pd.DataFrame
    misses: object
    miss_totals: pd.DataFrame
    scene_summary: dict
    tree: dict
    totals: dict
    parameters: dict
    texture: dict | None = None
    ray_orders: pd.DataFrame | None = None


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
    "ray_orders": "path-traced traces only; the mapping that loses most to coherence at the verdict's process "
                  "count, item = ray order: misses per ray per level, modelled times, speed-up, efficiency and its "
                  "five factors (load balance, coherence, reordering gain and overhead, dispatch), the order's "
                  "ray-state and queue records and sorting cycles (analyses.report_orders)",
    "miss_map": "mapping and n_processes of the miss map's run, item = cache level: misses per pixel summed "
                "('total'), their mean and largest, and the share of the total made by the 1% of pixels "
                "that miss most ('top_1pct_share')",
    "verdict": "every number the verdict prints, exactly as printed (percentages in percent)",
}

#: Files of the miss map beside the page: the per-pixel array and its figure.
MISS_MAP_FILES = ("miss_map.npy", "miss_map.png")

_PROCESS_COLUMNS = ("pixels", "user_cycles", "compute_cycles", "memory_cycles", "dispatch_cycles")
_SIGNIFICANT = 6


def texture_rows(texture: dict, n_processes: int) -> pd.DataFrame:
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


def miss_map_dtype(misses) -> np.dtype:
    """uint32 (half of int64's bytes) unless a count does not fit."""
    return np.dtype(np.uint32) if int(misses.misses.max(initial=0)) <= np.iinfo(np.uint32).max \
        else np.dtype(np.int64)


def _machine_words(platform) -> str:
    """What a run on ``platform``'s shared levels has on, for the views' sentences."""
    return "coherence and the levels' prefetchers on" if platform.hierarchy.hierarchy.prefetches else "coherence on"


def texture_note(inputs) -> str | None:
    """Under a platform, what the texture section was computed on: runs on the platform's shared levels,
    one per texel order and mapping; None without a platform."""
    experiment = inputs.experiment
    if experiment.platform is None:
        return None
    platform = experiment.platform_object()
    machine = _machine_words(platform)
    return (f"texel reads and misses come from one run per texel order and mapping at {inputs.verdict_n} "
            f"processes on {platform.name}'s shared levels, as the study's runs (interleaved "
            f"{int(experiment.interleave_cycles)} cycles at a time, {machine}), each level's counts summed over "
            "its instances; a level's misses are the processes' own there (background reads left out); the "
            "texel miss-ratio curves take no machine")


#: Under a platform, what ``results.csv``'s texture sections hold instead of :data:`SECTIONS`' (their runs).
PLATFORM_SECTIONS = {
    "texture": SECTIONS["texture"].replace(
        "each process on a cold hierarchy of its own (coherence.kind_misses)",
        "from a run of each mapping on the platform's shared levels, each level summed over its instances "
        "(analyses.report_texture.shared_texel_table)"),
    "texture_layouts": SECTIONS["texture_layouts"] + ", from a run of each texel order and mapping on the "
                                                     "platform's shared levels, each level summed over its instances",
}


def platform_views(inputs) -> dict | None:
    """Under a platform, what each section computed beside the study's runs took, as ``{section: {"view",
    "what"}}``: the miss map and the texture section (when the report has one, :func:`texture_note`) runs
    on the platform's shared levels, the miss-ratio curves no machine; None without a platform."""
    experiment = inputs.experiment
    if experiment.platform is None:
        return None
    platform, misses = experiment.platform_object(), inputs.misses
    machine = _machine_words(platform)
    sizes = ", ".join(f"{level} {_bytes_text(size)}" for level, size in zip(inputs.caches["level"],
                                                                            inputs.caches["size"]))
    views = {
        "miss_map": {"view": "shared run",
                     "what": f"the run of {misses.mapping} at {misses.n_processes} processes on {platform.name}'s "
                             f"shared levels, as the study's runs (interleaved {int(experiment.interleave_cycles)} "
                             f"cycles at a time, {machine}): each pixel's misses are "
                             "those of its own accesses on the instances its hardware thread reaches; a task "
                             "counter's accesses belong to no pixel"},
        "miss_curves": {"view": "no machine",
                        "what": "fully associative LRU of one process's stream, the same on any machine; the "
                                f"marked sizes are {platform.name}'s whole levels ({sizes})"},
    }
    if inputs.texture is not None:
        views["texture"] = {"view": "shared run", "what": texture_note(inputs)}
    return views


def miss_map_summary(misses, dtype) -> dict:
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


def results_table(inputs: ReportInputs) -> pd.DataFrame:
    """``results.csv``'s rows (:data:`RESULT_COLUMNS`, sections :data:`SECTIONS`), texture sections included."""
    scene_summary, tree, totals, trace = inputs.scene_summary, inputs.tree, inputs.totals, inputs.trace
    scene_bytes, caches, runs, processes = inputs.scene_bytes, inputs.caches, inputs.runs, inputs.processes
    verdict_n, misses = inputs.verdict_n, inputs.misses
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
    add("cache", "latency", inputs.hierarchy.memory_latency, item="memory")
    skip = {"mapping", "n_processes"}
    for _, run in runs.iterrows():
        for column in runs.columns:
            if column not in skip and isinstance(run[column], (int, float, np.number)):
                add("runs", column, run[column], mapping=run["mapping"], n=int(run["n_processes"]))
    for n in sorted({verdict_n, inputs.top_n}):
        for _, process in processes[processes["n_processes"] == n].iterrows():
            for column in _PROCESS_COLUMNS:
                add("processes", column, process[column], mapping=process["mapping"], n=n,
                    item=str(int(process["process"])))
    for _, point in inputs.curves.iterrows():
        add("miss_ratio", f"miss_ratio_{int(point['line_size'])}B", point["miss_ratio"], mapping=point["order"],
            n=1, item=str(int(point["size"])))
    cost_map = inputs.cost_map
    add("cost_map", "min_cycles_per_pixel", cost_map.min())
    add("cost_map", "mean_cycles_per_pixel", cost_map.mean())
    add("cost_map", "max_cycles_per_pixel", cost_map.max())
    add("cost_map", "total_cycles", cost_map.sum())
    for _, level in inputs.miss_totals.iterrows():
        for metric in ("total", "mean_per_pixel", "max_per_pixel", "top_1pct_share"):
            add("miss_map", metric, level[metric], mapping=misses.mapping, n=misses.n_processes, item=level["level"])
    for _, number in inputs.verdict.numbers.iterrows():
        add("verdict", number["metric"], number["value"], mapping=number["mapping"], n=int(number["n_processes"]))
    tables = [_rows_table(rows)]
    if inputs.texture is not None:
        tables.append(texture_rows(inputs.texture, verdict_n))
    if inputs.ray_orders is not None:
        from analyses.report_orders import order_rows

        tables.append(_rows_table(order_rows(inputs.ray_orders, _round)))
    return tables[0] if len(tables) == 1 else pd.concat(tables, ignore_index=True)


def _rows_table(rows) -> pd.DataFrame:
    """``results.csv``'s table of ``(section, mapping, n_processes, item, metric, value)`` tuples."""
    columns = list(zip(*rows)) if rows else [()] * len(RESULT_COLUMNS)
    table = pd.DataFrame({name: pd.Series(list(values), dtype=object) for name, values in zip(RESULT_COLUMNS, columns)})
    table["n_processes"] = table["n_processes"].astype("Int64")
    return table


def _clean(value):
    return plain(value, _SIGNIFICANT, integral_as_int=True)


def summary(inputs: ReportInputs) -> dict:
    """What ``summary.json`` holds: parameters, versions, scene, headline numbers, verdict, miss map."""
    from rtcommon.versions import package_versions

    runs, verdict, verdict_n, names = inputs.runs, inputs.verdict, inputs.verdict_n, inputs.names
    headline = {}
    for n in sorted({verdict_n, inputs.top_n}):
        at_n = runs[runs["n_processes"] == n].set_index("mapping")
        headline[str(n)] = {name: {column: at_n.loc[name, column] for column in DECOMPOSITION_COLUMNS}
                            for name in names}
    shared = shared_levels_summary(runs, inputs.hierarchy.level_names, sorted({verdict_n, inputs.top_n}), names)
    views = platform_views(inputs)
    return _clean({
        "report": "coherence report",
        "parameters": inputs.parameters,
        "versions": package_versions(),
        "scene": inputs.scene_summary,
        "tree": inputs.tree,
        "scene_bytes": dict(zip(inputs.scene_bytes["kind"], inputs.scene_bytes["bytes"])),
        "headline": headline,
        "verdict": {"n_processes": verdict_n, "decided_by": verdict.decided_by, "headline": verdict.headline,
                    "sentences": verdict.sentences, "text": verdict.text,
                    "numbers": verdict.numbers.to_dict(orient="records")},
        "miss_map": {**miss_map_summary(inputs.misses, miss_map_dtype(inputs.misses)),
                     **({} if views is None else {"caches": views["miss_map"]["what"]})},
        **({} if views is None else {"views": views}),
        **({} if inputs.ray_orders is None else {"ray_orders": inputs.ray_orders.to_dict(orient="records")}),
        "results_csv": {"columns": list(RESULT_COLUMNS),
                        "sections": SECTIONS if views is None else {**SECTIONS, **PLATFORM_SECTIONS}},
        **shared,
    })


def shared_levels_summary(runs, level_names, counts, names) -> dict:
    """Under a platform, ``{"shared_levels": {n: {mapping: {level: counts}}}}``: each level's misses (the
    processes', summed) and the machine's coherence invalidations, coherence misses and false-sharing misses
    at each process count of ``counts``, and with prefetchers the prefetches issued, useful and useless; empty
    for runs on private caches (no such columns)."""
    from coherence.shared_run import PREFETCH_RUN_COLUMNS, SHARED_RUN_COLUMNS

    if f"{level_names[0]}_{SHARED_RUN_COLUMNS[0][0]}" not in runs:
        return {}
    columns = [column for column, _ in SHARED_RUN_COLUMNS + PREFETCH_RUN_COLUMNS
               if f"{level_names[0]}_{column}" in runs]
    table = {}
    for n in counts:
        at_n = runs[runs["n_processes"] == n].set_index("mapping")
        table[str(n)] = {name: {level: {"accesses": at_n.loc[name, f"{level}_accesses"],
                                        "hit_rate": at_n.loc[name, f"{level}_hit_rate"],
                                        **{column: at_n.loc[name, f"{level}_{column}"] for column in columns}}
                                for level in level_names}
                         for name in names}
    return {"shared_levels": table}
