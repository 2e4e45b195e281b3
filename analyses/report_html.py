"""The HTML page of ``coherence report``: one self-contained file with embedded figures.

:func:`_html` lays out and draws what :mod:`analyses.report` computed
(scene, caches, speed-ups, losses, miss-ratio curves, cost map, verdict).
"""
from __future__ import annotations

import base64
import html
import io
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.html import table_html


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em}h2{font-size:1.25em;margin-top:2em;border-bottom:1px solid #ccc;padding-bottom:.2em}
table{border-collapse:collapse;font-size:.85em;margin:.6em 0}th,td{border:1px solid #ddd;padding:.2em .5em;
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto}.verdict{background:#f5f8ff;border-left:4px solid #36c;padding:.6em 1em}
.note{color:#555;font-size:.9em}.wide{overflow-x:auto}.row{display:flex;flex-wrap:wrap;gap:1em;align-items:flex-start}
"""


def _figure_png(fig) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90, bbox_inches="tight", metadata={"Software": None})
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _img(data: str, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def _html(scene, info, parameters, scene_summary, tree, totals, runs, processes, curves, cost_map, scene_bytes,
          caches, verdict, verdict_n, top_n, names, hierarchy, mapping_objects, trace, progress) -> str:
    from matplotlib.figure import Figure
    from tqdm.auto import tqdm

    from analyses import plots

    bar = tqdm(total=8, desc="figures", unit="figure", disable=not progress, leave=False, file=sys.stderr)
    figures = {}

    def draw(key, figsize, painter, ncols=1):
        fig = Figure(figsize=figsize)
        axes = fig.subplots(1, ncols, squeeze=False)[0]
        painter(axes if ncols > 1 else axes[0])
        figures[key] = _figure_png(fig)
        bar.update(1)

    image_b64 = base64.b64encode(Path(info["png"]).read_bytes()).decode("ascii")
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

    draw("pictures", (2.6 * len(mapping_objects), 2.9), pictures, ncols=len(mapping_objects))
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

    p = parameters
    e = html.escape
    sentences = "".join(f"<li>{e(s)}</li>" for s in verdict.sentences)
    counts_text = ", ".join(str(n) for n in p["n_processes"])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>Coherence report: {e(scene.name)} {p['size']}x{p['size']}</title>
<style>{_CSS}</style></head><body>
<h1>Coherence report: {e(scene.name)}, {p['size']}&times;{p['size']} pixels</h1>
<p class="note">Mappings {e(' '.join(names))}; {counts_text} processes on {p['n_cpus']} simulated CPUs;
{e(hierarchy.name)} caches, {e(p['layout'])} memory layout, {e(p['cost']['name'])} cost model at
{p['cost']['clock_hz'] / 1e6:g} MHz; kd-tree {e(p['kd'])}, ray depth {p['max_depth']}.
Real time assumes a background load of {background} always-runnable processes of other users
(the study's machine was shared). Trace cache key {e(p['trace_key'])}.</p>

<h2>Verdict</h2>
<div class="verdict"><p><strong>{e(verdict.headline)}</strong></p><ul>{sentences}</ul></div>
<p class="note">Efficiency = load balance &times; coherence &times; dispatch; each loss is 1 &minus; its factor.
A negative coherence loss (a gain) means processes sharing a CPU warmed each other's caches.</p>

<h2>The scene</h2>
<div class="row"><div>{_img(image_b64, 'rendered image')}</div>
<div>{table_html(counts_table)}<p>{scene_summary['lights']} lights, {scene_summary['materials']} materials,
maximum depth {scene_summary['max_depth']}.</p>{table_html(totals_table)}</div>
<div>{table_html(tree_table, 2)}</div></div>
<h3>Bytes of scene data against each cache size</h3>
<div class="row"><div>{_img(figures['bytes'], 'scene bytes per record kind')}</div>
<div>{table_html(bytes_table, 3)}</div></div>

<h2>Hit rates and misses per ray, 1 and {verdict_n} processes</h2>
{_img(figures['levels'], 'miss rates and misses per ray per level')}
{table_html(level_table, 4)}

<h2>Miss-ratio curves</h2>
<p class="note">From exact LRU reuse distances of the one-process stream in each mapping's pixel order
(S, P and R share the scan order), for a fully associative LRU cache of each size; dotted lines mark the
hierarchy's caches. Real caches with lower associativity miss more.</p>
{_img(figures['curves'], 'miss-ratio curves')}
{table_html(curve_points, 5)}

<h2>Cost per pixel</h2>
<p class="note">Compute cycles per pixel from the cost model (memory stalls excluded): where the work is,
which static mappings must split evenly to balance.</p>
{_img(figures['cost'], 'compute cycles per pixel')}

<h2>Mappings at {verdict_n} processes</h2>
{_img(figures['pictures'], 'mapping pictures')}

<h2>User time per process at {verdict_n} processes</h2>
{_img(figures['processes'], 'per-process user time')}

<h2>Speed-up against the number of processes</h2>
<p class="note">User speed-up = T1 / worst process user time; real speed-up under a background load of
{background} (processor sharing: every process, not every user, gets a share of the {p['n_cpus']} CPUs).
The dotted line marks where processes start sharing CPUs. Beyond it, a dynamic mapping's processes alone on a CPU
take more blocks than those sharing one, so its worst user time, and with it the user speed-up, stays near the
number of CPUs until every CPU is shared.</p>
{_img(figures['speedup'], 'speed-up curves')}

<h2>Efficiency decomposition</h2>
<p class="note">Efficiency = load balance &times; coherence &times; dispatch (factors), at {verdict_n}
{'' if top_n == verdict_n else f'and {top_n} '}processes; losses are 1 &minus; factor, in percent.</p>
{table_html(decomposition, 3)}

<p class="note">All numbers are in results.csv (tidy long form) and summary.json beside this page.</p>
</body></html>
"""
