"""The files of ``coherence paper``: speed-up figures, paper.json, the HTML page, and writing them.

Everything here only formats a :class:`analyses.paper_study.PaperResult`; the
numbers come from :func:`analyses.paper.reproduce`. Outputs are deterministic
(no timestamps, PNGs without metadata) and written atomically.
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from analyses.html import figure_png, render_page
from analyses.output import check_output_folder, csv_text
from analyses.paper_study import N_CPUS, STUDY_TABLE, PaperResult
from analyses.paper_today import TODAY_FILES
from analyses.plots import plot_speedup_panels
from coherence.cost import OPERATIONS
from coherence.metrics import DECOMPOSITION_COLUMNS
from rtcommon.files import write_files_atomic
from rtcommon.jsonio import plain

__all__ = ["speedup_figure", "crossover_figure", "paper_summary", "paper_html", "write_paper", "PAPER_FILES",
           "CROSSOVER_FILES"]

#: The files :func:`write_paper` always writes, by what they hold: the names readers, tests and
#: ``--help`` use. The two speed-up figures are keyed by the column they plot.
PAPER_FILES = {"runs": "paper.csv", "scenes": "scenes.csv", "predictions": "predictions.csv",
               "summary": "paper.json", "speedup_real": "speedup_real.png", "speedup_user": "speedup_user.png",
               "page": "index.html"}
#: The files it adds when the result holds a crossover study.
CROSSOVER_FILES = {"crossover_table": "crossover.csv", "crossover": "crossover.png"}


# --------------------------------------------------------------------------
# figures


def speedup_figure(runs: pd.DataFrame, column: str = "speedup_real", *, n_cpus: int = N_CPUS, order=None,
                   title: str | None = None):
    """A grid of speed-up panels, one per scene, one line per mapping (the study's figure style).

    Draws only what ``runs`` holds (see :func:`analyses.plots.plot_speedup_panels`);
    ``n_cpus`` defaults to the study's 8. Returns a
    :class:`matplotlib.figure.Figure`.
    """
    return plot_speedup_panels(runs, column=column, order=order, n_cpus=n_cpus, title=title)


# --------------------------------------------------------------------------
# writing


def _clean(value):
    """Plain JSON types; NaN and infinities become None; floats to 10 significant digits."""
    return plain(value, 10)


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
            "method": "bounded least squares of relative errors of the study's sequential S times "
                      "minus simulated memory cycles; targets scaled by (size/512)^2; each scene also predicted "
                      "from a fit to the others (left_out_*); unexplained_seconds is the target minus the fitted "
                      "time, every cost inside its bounds",
            "structure": calibration["structure"],
            "fitted": calibration["fitted"],
            "at_bound": calibration["at_bound"],
            "model": calibration["model"],
            "scale": calibration["scale"],
            "rms_relative_error": calibration["rms_relative_error"],
            "left_out_rms_relative_error": calibration["left_out_rms_relative_error"],
            "residuals": calibration["residuals"],
        },
        "scenes": result.table,
        "predictions": result.predictions,
        "crossover_boundary": _boundary(result),
        "verdicts": result.verdicts,
        "verdict_numbers": result.verdict_numbers,
        **({} if result.today is None else {"today": {
            "method": "the same traces, mappings and process counts on the platform, with its own cost model "
                      "(not fitted to the study)",
            "platform": result.today["platform"], "verdicts": result.today["verdicts"]}}),
    })


def _boundary(result: PaperResult):
    from analyses.crossover import crossover_boundary

    return None if result.crossover is None else crossover_boundary(result.crossover)


def crossover_figure(boundary: pd.DataFrame):
    """The crossover boundary of every scene (:func:`analyses.crossover.plot_crossover`) in a Figure."""
    from matplotlib.figure import Figure

    from analyses.crossover import plot_crossover

    figure = Figure(figsize=(7, 5))
    plot_crossover(boundary, ax=figure.subplots())
    figure.suptitle("Where P or R would lose more to coherence than S to imbalance")
    return figure


def paper_html(result: PaperResult, pngs: dict) -> str:
    """The self-contained page: tables, calibration, verdicts and the embedded figures.

    ``pngs`` holds the PNG bytes of ``speedup_real`` and ``speedup_user``;
    ``templates/paper.html.j2`` lays the page out.
    """
    p = result.parameters
    cal = result.calibration
    fitted = pd.DataFrame(cal["fitted"]).rename(columns={"name": "fitted cost", "reference": "cycles of",
                                                         "low": "lowest", "high": "highest"})
    model = pd.DataFrame({"operation": list(OPERATIONS), "cycles": [cal["model"][op] for op in OPERATIONS]})
    residuals = cal["residuals"][["scene", "study_seconds", "target_seconds", "fitted_seconds", "unexplained_seconds",
                                  "relative_error", "left_out_seconds", "left_out_error", "memory_share"]]
    decomposition = result.runs[result.runs["n_processes"] == p["verdict_n_processes"]][
        ["scene", "mapping", *DECOMPOSITION_COLUMNS]]
    return render_page("paper.html.j2", p=p, calibration=cal, verdicts=list(result.verdicts["text"]),
                       study_table=STUDY_TABLE, scenes_table=result.table.drop(columns=["study_geometry"]),
                       fitted_table=fitted, model_table=model, residuals_table=residuals,
                       predictions_table=result.predictions, crossover_table=_boundary(result),
                       decomposition=decomposition, pngs=pngs)


def write_paper(result: PaperResult, out="paper") -> Path:
    """Write paper.csv, scenes.csv, predictions.csv, paper.json, the speed-up PNGs and index.html into ``out``
    (and today.csv with a platform's today column)."""
    path = check_output_folder(out)
    path.mkdir(parents=True, exist_ok=True)
    order = result.parameters["mappings"]
    n_cpus = result.parameters["n_cpus"]
    background = result.parameters["background_load"]
    pngs = {
        "speedup_real": figure_png(speedup_figure(result.runs, "speedup_real", n_cpus=n_cpus, order=order,
                                                  title=f"Speed-up from real time (background load {background})")),
        "speedup_user": figure_png(speedup_figure(result.runs, "speedup_user", n_cpus=n_cpus, order=order,
                                                  title="Speed-up from user time (worst process)")),
    }
    boundary = _boundary(result)
    if boundary is not None:
        pngs["crossover"] = figure_png(crossover_figure(boundary))
    summary = paper_summary(result)
    # one unit: every file is made before any is renamed into place (an interrupt leaves the old set)
    names = {**PAPER_FILES, **CROSSOVER_FILES}
    files = {path / names["runs"]: csv_text(result.runs).encode(),
             path / names["scenes"]: csv_text(result.table).encode(),
             path / names["predictions"]: csv_text(result.predictions).encode()}
    if boundary is not None:
        files[path / names["crossover_table"]] = csv_text(result.crossover).encode()
    if result.today is not None:
        files[path / TODAY_FILES["today_runs"]] = csv_text(result.today["runs"]).encode()
    files[path / names["summary"]] = (json.dumps(summary, indent=2, allow_nan=False) + "\n").encode()
    files.update({path / names[name]: data for name, data in pngs.items()})
    files[path / names["page"]] = paper_html(result, pngs).encode("utf-8")
    write_files_atomic(files)
    return path
