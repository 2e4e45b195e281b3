"""What ``coherence robustness`` writes: samples and indices as CSV, the summary as JSON, one HTML page.

Files (:data:`ROBUSTNESS_FILES`), written together to temporary names and
then renamed (:func:`rtcommon.files.write_files_atomic`):

``samples.csv``
    One row per (scene, sample): its outputs and every sampled value, and
    the design it belongs to, ``morris`` or ``sobol``
    (:attr:`analyses.robustness.RobustnessResult.samples`).
``indices.csv``
    Morris ``mu_star``, ``mu``, ``sigma`` and rank of every (scene, factor),
    with Sobol's ``S1`` and ``ST`` for the factors Sobol's design varied.
``robustness.json``
    Parameters, seed, package versions (SALib's included), the command that
    reproduces the study (:func:`robustness_command`), the commit of the
    code that ran it (:func:`rtcommon.versions.source_commit`), the budgeted
    design beside the one run (:func:`study_budget`) and per scene the
    summary of :func:`analyses.robustness.scene_summary` with
    ``n_evaluations_budgeted``.
``index.html``
    One self-contained page: per scene the verdict's probability, the
    percentiles, the flip region and a tornado chart of ``mu_star``.

The same inputs and seed give byte-identical files.
"""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from analyses.html import figure_png, render_page
from analyses.output import csv_text, prepare_output_folder
from analyses.robustness_size import VERDICT_MIN_SIZE
from rtcommon.files import write_files_atomic
from rtcommon.jsonio import plain

__all__ = ["ROBUSTNESS_FILES", "BUDGET_TRAJECTORIES", "BUDGET_SOBOL", "study_budget", "robustness_command",
           "robustness_summary", "plot_tornado", "write_robustness"]

#: The files :func:`write_robustness` writes, by what they hold.
ROBUSTNESS_FILES = {"samples": "samples.csv", "indices": "indices.csv", "summary": "robustness.json",
                    "page": "index.html"}


#: Morris trajectories the verdict's study is budgeted for, per study scene.
BUDGET_TRAJECTORIES = 10

#: Base samples of the budgeted Sobol design over the top unknowns.
BUDGET_SOBOL = 64


def study_budget(parameters: dict) -> dict:
    """The budgeted study beside the one ``parameters`` (a ``robustness.json``'s) ran.

    Returns
    -------
    dict
        ``scenes`` (every study scene, :data:`tracer.scenes.catalog.PAPER_SCENES`),
        ``scenes_not_run``, ``trajectories`` (:data:`BUDGET_TRAJECTORIES`),
        ``morris_evaluations`` per scene (``trajectories (k + 1)`` over the
        ``k`` unknowns the study varied), ``sobol_base_samples``
        (:data:`BUDGET_SOBOL`) and ``met``: every study scene run with at
        least the budgeted trajectories and Sobol base samples.
    """
    from tracer.scenes.catalog import PAPER_SCENES

    not_run = [scene for scene in PAPER_SCENES if scene not in parameters["scenes"]]
    met = (not not_run and parameters["size"] >= VERDICT_MIN_SIZE and parameters["trajectories"] >= BUDGET_TRAJECTORIES
           and parameters["sobol"] >= BUDGET_SOBOL)
    return {"scenes": list(PAPER_SCENES), "scenes_not_run": not_run, "trajectories": BUDGET_TRAJECTORIES,
            "morris_evaluations": BUDGET_TRAJECTORIES * (len(parameters["factors"]) + 1),
            "sobol_base_samples": BUDGET_SOBOL, "met": bool(met)}


def robustness_command(parameters: dict) -> str:
    """The ``coherence robustness`` command line that runs the study of ``parameters`` (its recorded ones)."""
    command = ["coherence robustness", "--scenes", *parameters["scenes"], "--size", str(parameters["size"]),
               "--trajectories", str(parameters["trajectories"]), "--seed", str(parameters["seed"])]
    if parameters["sobol"]:
        command += ["--sobol", str(parameters["sobol"])]
    if not parameters.get("size_check", True):
        command.append("--no-size-check")
    return " ".join(command)


def robustness_summary(result) -> dict:
    """What ``robustness.json`` holds: parameters, versions, command, commit and the per-scene summaries,
    as plain JSON data."""
    from importlib.metadata import version

    from coherence.provenance import provenance
    from rtcommon.versions import source_commit

    meta = provenance(**result.summary["parameters"])
    versions = {**meta["versions"], "SALib": version("SALib")}
    budget = study_budget(meta["parameters"])
    scenes = {scene: {**summary, "n_evaluations_budgeted": budget["morris_evaluations"]}
              for scene, summary in result.summary["scenes"].items()}
    return plain({"parameters": meta["parameters"], "versions": versions,
                  "command": robustness_command(meta["parameters"]), "commit": source_commit(),
                  "budget": budget, "scenes": scenes}, 10)


def plot_tornado(df, ax=None, *, title=None):
    """Horizontal bars of ``mu_star`` per factor, the largest on top.

    Parameters
    ----------
    df : DataFrame
        Columns ``factor`` and ``mu_star``, one row per factor of one scene.
    """
    from analyses.plots import _axes

    ax = _axes(ax, (6.0, 4.0))
    rows = df.sort_values("mu_star", ascending=True, kind="stable")
    ax.barh(rows["factor"], rows["mu_star"], color="tab:blue")
    ax.set_xlabel("Morris mu* of the verdict's margin")
    if title:
        ax.set_title(title)
    return ax


def _tornado_png(indices: pd.DataFrame, scene: str) -> bytes:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(6.0, 4.0))
    plot_tornado(indices[indices["scene"] == scene], ax=figure.subplots(), title=scene)
    return figure_png(figure)


def _flip_text(rule) -> str:
    if isinstance(rule, str):
        return rule
    if "threshold" in rule:
        return f"load balance when {rule['load_balance_when']} {rule['threshold']:.4g} " \
               f"(agrees with {100 * rule['agreement']:.0f}% of samples)"
    return f"load balance with {', '.join(rule['load_balance_choices']) or 'no choice'} " \
           f"(agrees with {100 * rule['agreement']:.0f}% of samples)"


def _scene_tables(summary: dict) -> dict:
    spread = pd.DataFrame([{"quantity": name, **summary[name]} for name in ("b_minus_s", "db_minus_s", "margin")])
    losses = pd.DataFrame([{"mapping": mapping, "loss": kind, **values}
                           for mapping, kinds in summary["losses"].items() for kind, values in kinds.items()])
    flip = pd.DataFrame([{"factor": name, "flip region": _flip_text(rule)} for name, rule in summary["flip"].items()])
    tables = {"spread": spread, "losses": losses, "flip": flip}
    if "size_check" in summary:
        check = summary["size_check"]
        tables["size_check"] = pd.DataFrame([
            {"quantity": name, "sample": sample, f"at {check['small_size']}": small,
             f"at {check['reference_size']}": reference, "relative difference": relative,
             "passed": "yes" if entry["passed"] else "no", "size used": entry["size_used"]}
            for name, entry in check["quantities"].items()
            for sample, small, reference, relative in zip(check["samples"], entry["small"], entry["reference"],
                                                          entry["relative_difference"])])
    if "sobol" in summary:
        sobol = summary["sobol"]
        tables["sobol"] = pd.DataFrame([{"factor": name, "first order": sobol["S1"][name], "total": sobol["ST"][name]}
                                        for name in sobol["factors"]])
    return tables


def write_robustness(result, out) -> Path:
    """Write :data:`ROBUSTNESS_FILES` into ``out`` as one unit; return the folder."""
    path = prepare_output_folder(out)
    summary = robustness_summary(result)
    scenes = []
    for scene, scene_summary in summary["scenes"].items():
        scenes.append({"name": scene, "summary": scene_summary, "tables": _scene_tables(scene_summary),
                       "tornado": _tornado_png(result.indices, scene)})
    page = render_page("robustness.html.j2", p=summary["parameters"], budget=summary["budget"], scenes=scenes)
    files = {path / ROBUSTNESS_FILES["samples"]: csv_text(result.samples),
             path / ROBUSTNESS_FILES["indices"]: csv_text(result.indices),
             path / ROBUSTNESS_FILES["summary"]: json.dumps(summary, indent=2, allow_nan=False) + "\n",
             path / ROBUSTNESS_FILES["page"]: page}
    write_files_atomic(files)
    return path
