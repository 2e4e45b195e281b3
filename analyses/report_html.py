"""The HTML page of ``coherence report``: one self-contained file with embedded figures.

:func:`report_html` draws the figures and shapes the tables of what
:mod:`analyses.report` computed (scene, caches, speed-ups, losses, miss-ratio
curves, cost map, verdict); ``templates/report.html.j2`` lays them out.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.html import figure_png, render_page

__all__ = ["report_html", "miss_map_png"]


def miss_map_png(misses) -> bytes:
    """The miss map as PNG bytes: one panel per cache level, first level on the left.

    Parameters
    ----------
    misses : coherence.missmap.MissMap
    """
    from matplotlib.figure import Figure

    from analyses import plots

    n_levels = len(misses.levels)
    fig = Figure(figsize=(5.2 * n_levels, 4.6))
    for ax, level in zip(fig.subplots(1, n_levels, squeeze=False)[0], misses.levels):
        plots.plot_miss_map(misses, level, ax)
    return figure_png(fig)


def report_html(inputs, miss_png: bytes) -> str:
    """The report page as HTML text, figures embedded as PNG.

    Draws on bare :class:`matplotlib.figure.Figure` objects, so it needs no
    pyplot and picks no backend.

    Parameters
    ----------
    inputs : analyses.report_tables.ReportInputs
        The pieces :func:`analyses.report.build_report` computed (a
        textured scene's tables in ``inputs.texture``).
    miss_png : bytes
        The miss map's figure (:func:`miss_map_png`).
    """
    from matplotlib.figure import Figure
    from tqdm.auto import tqdm

    from analyses import plots

    scene, info, parameters, scene_summary = inputs.scene, inputs.info, inputs.parameters, inputs.scene_summary
    tree, totals, runs, processes, curves = inputs.tree, inputs.totals, inputs.runs, inputs.processes, inputs.curves
    cost_map, scene_bytes, caches, verdict = inputs.cost_map, inputs.scene_bytes, inputs.caches, inputs.verdict
    verdict_n, top_n, names, hierarchy = inputs.verdict_n, inputs.top_n, inputs.names, inputs.hierarchy
    mapping_objects, trace, miss_totals, texture = inputs.mappings, inputs.trace, inputs.miss_totals, inputs.texture
    bar = tqdm(total=8, desc="figures", unit="figure", disable=not inputs.experiment.progress, leave=False,
               file=sys.stderr)
    figures = {}

    def draw(key, figsize, painter, ncols=1, per_column=False):
        # per_column painters take the row of axes even when it holds one (a report of one mapping)
        fig = Figure(figsize=figsize)
        axes = fig.subplots(1, ncols, squeeze=False)[0]
        painter(axes if ncols > 1 or per_column else axes[0])
        figures[key] = figure_png(fig)
        bar.update(1)

    image = Path(info["png"]).read_bytes()
    draw("bytes", (6.5, 3.0), lambda ax: plots.plot_scene_bytes(scene_bytes, ax, caches=caches))

    levels = []
    for n in sorted({1, verdict_n}):
        for _, run in runs[runs["n_processes"] == n].iterrows():
            for level in hierarchy.level_names:
                levels.append({"mapping": run["mapping"], "n_processes": n, "level": level,
                               "hit_rate": run[f"{level}_hit_rate"], "miss_rate": 1.0 - run[f"{level}_hit_rate"],
                               "misses_per_ray": run[f"{level}_misses_per_ray"]})
    levels = pd.DataFrame(levels)

    def two_level_plots(axes):
        plots.plot_level_metric(levels, axes[0], metric="miss_rate", order=names)
        plots.plot_level_metric(levels, axes[1], metric="misses_per_ray", order=names)
        axes[0].set_title("miss rate per access at each level", fontsize=10)
        axes[1].set_title("misses per ray at each level", fontsize=10)

    draw("levels", (12, 3.8), two_level_plots, ncols=2)
    draw("curves", (8, 4.5), lambda ax: plots.plot_miss_ratio_curves(curves, ax, caches=caches))
    draw("cost", (5.2, 4.5), lambda ax: plots.plot_cost_map(cost_map, ax))

    def pictures(axes):
        for mapping, ax in zip(mapping_objects, axes):
            mapping.picture(verdict_n, trace.width, trace.height, ax=ax)
            ax.title.set_fontsize(8)

    draw("pictures", (2.6 * len(mapping_objects), 2.9), pictures, ncols=len(mapping_objects), per_column=True)
    at_verdict = processes[processes["n_processes"] == verdict_n]
    draw("processes", (10, 3.8), lambda ax: plots.plot_process_times(at_verdict, ax, order=names))

    background = parameters["background_load"]

    def speedups(axes):
        plots.plot_speedup(runs, axes[0], column="speedup_user", order=names, n_cpus=parameters["n_cpus"],
                           title="from user time (worst process)")
        plots.plot_speedup(runs, axes[1], column="speedup_real", order=names, n_cpus=parameters["n_cpus"],
                           title=f"from real time, background load {background}")

    draw("speedup", (11, 4.2), speedups, ncols=2)
    bar.update(1)
    bar.close()

    chosen = runs[runs["n_processes"].isin(sorted({verdict_n, top_n}))].sort_values(["n_processes"], kind="stable")
    decomposition = pd.DataFrame({
        "mapping": chosen["mapping"], "n": chosen["n_processes"],
        "speed-up (user)": chosen["speedup_user"], f"speed-up (real, B={parameters['background_load']})":
            chosen["speedup_real"], "efficiency": chosen["efficiency"], "load balance": chosen["load_balance"],
        "coherence": chosen["coherence_factor"], "dispatch": chosen["dispatch_factor"],
        "imbalance loss %": 100 * chosen["imbalance_loss"], "coherence loss %": 100 * chosen["coherence_loss"],
        "dispatch loss %": 100 * chosen["dispatch_loss"]})
    level_table = []
    for n in sorted({1, verdict_n}):
        for _, run in runs[runs["n_processes"] == n].iterrows():
            row = {"mapping": run["mapping"], "n": n}
            for level in hierarchy.level_names:
                row[f"{level} hit rate"] = run[f"{level}_hit_rate"]
            for level in hierarchy.level_names:
                row[f"{level} misses/ray"] = run[f"{level}_misses_per_ray"]
            level_table.append(row)
    level_table = pd.DataFrame(level_table)
    counts_table = pd.DataFrame({"kind": list(scene_summary["counts"]), "elements": list(scene_summary["counts"].values())})
    counts_table = counts_table[counts_table["elements"] > 0]
    tree_table = pd.DataFrame({"statistic": list(tree), "value": pd.Series(list(tree.values()), dtype=object)})
    totals_keys = ["rays", "primary_rays", "shadow_rays", "reflection_rays", "refraction_rays",
                   "intersection_tests", "node_visits", "records"]
    totals_table = pd.DataFrame({"counter": [k for k in totals_keys if k in totals],
                                 "total": [totals[k] for k in totals_keys if k in totals]})
    bytes_table = scene_bytes.copy()
    for level, size in zip(caches["level"], caches["size"]):
        bytes_table[f"/ {level} ({plots._bytes_text(size)})"] = bytes_table["bytes"] / size
    curve_points = curves[curves["size"].isin(list(caches["size"]))].pivot_table(
        index=["order", "line_size"], columns="size", values="miss_ratio", sort=False).reset_index()
    curve_points.columns = [c if not isinstance(c, (int, np.integer)) else f"miss ratio @ {plots._bytes_text(c)}"
                            for c in curve_points.columns]

    miss_table = miss_totals.rename(columns={"total": "misses", "mean_per_pixel": "mean per pixel",
                                             "max_per_pixel": "max per pixel",
                                             "top_1pct_share": "share of the 1% worst pixels"})
    figures["miss_map"] = miss_png
    texture_share = None
    if texture is not None:
        from analyses.report_texture import plot_texel_curves, plot_texel_hit_rates

        def hit_rates(axes):
            for ax, level in zip(axes, hierarchy.level_names[:2]):
                plot_texel_hit_rates(texture["layouts"], level, ax)
                ax.set_title(f"texel hit rate at {level}, {verdict_n} processes", fontsize=10)

        draw("texture_layouts", (12, 3.8), hit_rates, ncols=2)
        draw("texture_curves", (7, 4), lambda ax: plot_texel_curves(texture["curves"], ax))
        texture_share = texture["share"].rename(columns={
            "texel_reads": "texel reads", "texel_misses": "texel misses",
            "misses_per_texel_read": "misses per texel read", "texture_miss_share": "texel share of misses"})

    ray_orders = None
    if inputs.ray_orders is not None:
        from analyses.report_orders import order_table_html

        ray_orders = order_table_html(inputs.ray_orders)
    from analyses.report_tables import platform_views

    return render_page("report.html.j2", ray_orders=ray_orders, texture_share=texture_share, miss_table=miss_table, scene_name=scene.name, p=parameters, names=names,
                       hierarchy_name=parameters["hierarchy"].get("name", hierarchy.name),
                       views=platform_views(inputs), verdict=verdict, verdict_n=verdict_n, top_n=top_n,
                       scene_summary=scene_summary, image=image, figures=figures, counts_table=counts_table,
                       totals_table=totals_table, tree_table=tree_table, bytes_table=bytes_table,
                       level_table=level_table, curve_points=curve_points, decomposition=decomposition)
