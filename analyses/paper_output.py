"""The files of ``coherence paper``: speed-up figures, paper.json, the HTML page, and writing them.

Everything here only formats a :class:`analyses.paper_study.PaperResult`; the
numbers come from :func:`analyses.paper.reproduce`. Outputs are deterministic
(no timestamps, PNGs without metadata) and written atomically.
"""
from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.html import table_html
from analyses.output import check_output_folder
from analyses.paper_study import N_CPUS, STUDY_TABLE, PaperResult
from cachesim.config import write_bytes_atomic

__all__ = ["speedup_figure", "paper_summary", "paper_html", "write_paper"]


# --------------------------------------------------------------------------
# figures


def speedup_figure(runs: pd.DataFrame, column: str = "speedup_real", *, n_cpus: int = N_CPUS, order=None,
                   title: str | None = None):
    """A grid of speed-up panels, one per scene, one line per mapping (the study's figure style).

    Draws only what ``runs`` holds: the ideal line, the ``n_cpus`` mark where
    processes start sharing CPUs, and ``column`` against ``n_processes``.
    Returns a :class:`matplotlib.figure.Figure`.
    """
    import matplotlib
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    scenes = list(dict.fromkeys(runs["scene"]))
    names = list(dict.fromkeys(runs["mapping"]))
    if order is not None:
        names = [m for m in order if m in names] + [m for m in names if m not in order]
    colours = list(matplotlib.colormaps["tab10"].colors)
    markers = ["o", "s", "^", "D", "v", "P", "X", "*"]
    ncols = min(3, len(scenes))
    nrows = -(-len(scenes) // ncols)
    fig = Figure(figsize=(4.0 * ncols, 3.5 * nrows + 0.4))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    top = int(runs["n_processes"].max())
    for ax, scene in zip(axes, scenes):
        rows = runs[runs["scene"] == scene]
        ax.plot([1, top], [1, top], color="0.6", linewidth=1, linestyle="--", label="ideal")
        for index, name in enumerate(names):
            line = rows[rows["mapping"] == name].sort_values("n_processes")
            ax.plot(line["n_processes"], line[column], marker=markers[index % len(markers)], markersize=3.5,
                    linewidth=1.2, color=colours[index % len(colours)], label=name)
        if n_cpus < top:
            ax.axvline(n_cpus, color="0.35", linestyle=":", linewidth=1, label=f"{n_cpus} CPUs")
        ax.set_title(scene.capitalize(), fontsize=10)
        ax.set_xlabel("processes")
        ax.set_ylabel("speed-up")
        ax.set_xlim(0.5, top + 0.5)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylim(0, top + 0.5)
        ax.grid(True, color="0.92", linewidth=0.6)
    for ax in axes[len(scenes):]:
        ax.set_axis_off()
    handles, labels = axes[0].get_legend_handles_labels()
    spare = axes[len(scenes)] if len(scenes) < len(axes) else None
    if spare is not None:
        spare.legend(handles, labels, loc="center", frameon=False, fontsize=10)
    else:
        axes[0].legend(fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def _png_bytes(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90, metadata={"Software": None})
    return buffer.getvalue()


# --------------------------------------------------------------------------
# writing


def _clean(value):
    """Plain JSON types; NaN and infinities become None; floats to 10 significant digits."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, pd.DataFrame):
        return [_clean(row) for row in value.to_dict(orient="records")]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            return None
        return float(f"{value:.10g}")
    return value


def paper_summary(result: PaperResult) -> dict:
    """What ``paper.json`` holds: parameters, versions, calibration, residuals, table, verdicts."""
    from coherence.provenance import provenance

    calibration = result.calibration
    meta = provenance(**result.parameters)
    return _clean({
        "parameters": meta["parameters"],
        "versions": meta["versions"],
        "traces": result.info and {k: {"trace_key": v["trace_key"]} for k, v in result.info.items()},
        "study": STUDY_TABLE,
        "calibration": {
            "method": "non-negative least squares of the sequential S times (DESIGN.md section 2) minus simulated "
                      "memory cycles; targets scaled by (size/512)^2",
            "weighting": calibration["weighting"],
            "fitted": calibration["fitted"],
            "fixed": calibration["fixed"],
            "model": calibration["model"],
            "default": calibration["default"],
            "scale": calibration["scale"],
            "rms_relative_error": calibration["rms_relative_error"],
            "residuals": calibration["residuals"],
        },
        "scenes": result.table,
        "verdicts": result.verdicts,
        "verdict_numbers": result.verdict_numbers,
    })


_CSS = """body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}
h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;font-size:.85em;margin:.6em 0}th,td{border:1px solid #ddd;padding:.2em .5em;
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
img{max-width:100%;height:auto}.verdict{background:#f5f8ff;border-left:4px solid #36c;padding:.4em 1em;margin:.5em 0}
.note{color:#555;font-size:.9em}"""


def paper_html(result: PaperResult, pngs: dict) -> str:
    """The self-contained page: tables, calibration, verdicts and the embedded figures."""
    e = html.escape
    p = result.parameters
    cal = result.calibration
    model = pd.DataFrame({"operation": list(cal["fitted"]),
                          "fitted cycles": [cal["model"][op] for op in cal["fitted"]],
                          "alpha8400 default": [cal["default"][op] for op in cal["fitted"]]})
    fixed = pd.DataFrame({"operation": list(cal["fixed"]), "cycles (held)": list(cal["fixed"].values())})
    residuals = cal["residuals"][["scene", "study_seconds", "target_seconds", "fitted_seconds", "residual_seconds",
                                  "relative_error", "memory_seconds"]]
    table = result.table.drop(columns=["study_geometry"])
    decomposition = result.runs[result.runs["n_processes"] == p["verdict_n_processes"]][
        ["scene", "mapping", "speedup_user", "speedup_real", "efficiency", "load_balance", "coherence_factor",
         "dispatch_factor", "imbalance_loss", "coherence_loss", "dispatch_loss"]]
    verdicts = "".join(f'<div class="verdict"><p>{e(text)}</p></div>' for text in result.verdicts["text"])
    images = {k: base64.b64encode(v).decode("ascii") for k, v in pngs.items()}
    counts = ", ".join(str(n) for n in p["n_processes"])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>The study reproduced: {p['size']}x{p['size']}</title>
<style>{_CSS}</style></head><body>
<h1>Havran &amp; &#381;&aacute;ra's study reproduced, {p['size']}&times;{p['size']} pixels</h1>
<p class="note">Scenes {e(', '.join(p['scenes']))}; mappings {e(' '.join(p['mappings']))}; {counts} processes on
{p['n_cpus']} simulated CPUs ({e(p['hierarchy'].get('name', 'alpha21164'))} caches, {e(p['layout'])} layout,
{p['clock_hz'] / 1e6:g} MHz). Real time carries a background load of {p['background_load']} always-runnable
processes of other users: the study's machine was shared, and every process, not every user, gets a CPU share.</p>

<h2>Verdict per scene at {p['verdict_n_processes']} processes</h2>
{verdicts}
<p class="note">Loss = 1 &minus; factor of efficiency = load balance &times; coherence &times; dispatch; a coherence
gain (negative loss) comes from processes sharing a CPU's caches or from smaller per-process working sets.</p>

<h2>The scenes beside the study's table</h2>
{table_html(STUDY_TABLE, 1)}
<p class="note">Study: 512&times;512, BSP tree. Ours: intersection tests at {p['size']}&times;{p['size']} with an SAH
kd-tree, which tests far fewer primitives per ray than the study's BSP; fitted seconds are the calibrated cost
model's sequential S time, against the study's time scaled to our pixel count (target).</p>
{table_html(table, 3)}

<h2>Cost-model calibration</h2>
<p class="note">Non-negative least squares ({e(cal['weighting'])} errors) of the study's sequential times (minus our
simulated memory cycles) on our operation counters, {len(cal['fitted'])} fitted operations, the rest held at the alpha8400 defaults.
RMS relative error {cal['rms_relative_error'] * 100:.1f}%. The cycles per test absorb our tree's smaller test
counts: they are what the study's tracer would have paid to do our work.</p>
{table_html(model, 1)}{table_html(residuals, 3)}{table_html(fixed, 1)}

<h2>Speed-up from real time</h2>
<img alt="speed-up from real time" src="data:image/png;base64,{images['speedup_real']}">
<h2>Speed-up from user time (worst process)</h2>
<img alt="speed-up from user time" src="data:image/png;base64,{images['speedup_user']}">

<h2>Efficiency decomposition at {p['verdict_n_processes']} processes</h2>
{table_html(decomposition, 3)}
<p class="note">Every run is in paper.csv; parameters, versions, calibration and verdicts in paper.json.</p>
</body></html>
"""


def _csv(frame: pd.DataFrame) -> str:
    return frame.to_csv(index=False, lineterminator="\n", float_format="%.10g")


def write_paper(result: PaperResult, out="paper") -> Path:
    """Write paper.csv, scenes.csv, paper.json, speedup_real.png, speedup_user.png and index.html into ``out``."""
    path = check_output_folder(out)
    path.mkdir(parents=True, exist_ok=True)
    order = result.parameters["mappings"]
    n_cpus = result.parameters["n_cpus"]
    background = result.parameters["background_load"]
    pngs = {
        "speedup_real": _png_bytes(speedup_figure(result.runs, "speedup_real", n_cpus=n_cpus, order=order,
                                                  title=f"Speed-up from real time (background load {background})")),
        "speedup_user": _png_bytes(speedup_figure(result.runs, "speedup_user", n_cpus=n_cpus, order=order,
                                                  title="Speed-up from user time (worst process)")),
    }
    summary = paper_summary(result)
    write_bytes_atomic(path / "paper.csv", _csv(result.runs).encode())
    write_bytes_atomic(path / "scenes.csv", _csv(result.table).encode())
    write_bytes_atomic(path / "paper.json", (json.dumps(summary, indent=2, allow_nan=False) + "\n").encode())
    for name, data in pngs.items():
        write_bytes_atomic(path / f"{name}.png", data)
    write_bytes_atomic(path / "index.html", paper_html(result, pngs).encode("utf-8"))
    return path
