"""The paper's "today" column: the study's runs again on a machine of today (``coherence paper --platform``).

Opt-in: with a platform (:data:`coherence.platforms.PLATFORMS`) in the
paper's experiment, every scene's trace (the study-era tracer's, with its
per-ray data) is also run with the same mappings and process counts on the
platform: each hardware thread a CPU, its shared levels as a run under a
platform simulates them (:meth:`analyses.experiment.Experiment.study_hierarchy`), and
the platform's own cost model, not fitted to the study. The study's machine
and its calibration are untouched; the platform's results go beside them:
``today_*`` columns of ``scenes.csv``, ``today.csv`` (the platform's run
table) and a ``today`` section of ``paper.json``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import pandas as pd

__all__ = ["TODAY_FILES", "Today", "today_of", "run_today", "today_columns"]

#: The file :func:`analyses.paper_output.write_paper` adds with a today column.
TODAY_FILES = {"today_runs": "today.csv"}


@dataclass(frozen=True)
class Today:
    """How the paper's runs are simulated on a platform.

    Attributes
    ----------
    experiment : analyses.experiment.Experiment
        The paper's experiment with its platform: hierarchy, cost model and
        CPUs are the platform's.
    parameters : dict
        The platform as a run records it
        (:func:`analyses.experiment.platform_parameters`), with the
        simulated hierarchy and cost model's fields.
    """

    experiment: object
    parameters: dict


def today_of(experiment):
    """Split a paper experiment: (the study's machine's experiment, :class:`Today` or None).

    Without a platform the experiment is returned as it is, with None.
    """
    from analyses.experiment import platform_parameters

    platform = experiment.platform_object()
    if platform is None:
        return experiment, None
    parameters = {**platform_parameters(platform, experiment.interleave_cycles),
                  "hierarchy": experiment.study_hierarchy().to_dict(),
                  "cost": platform.cost.to_dict(), "n_cpus": experiment.cpus()}
    return replace(experiment, platform=None), Today(experiment, parameters)


def run_today(today: Today, trace, scene, counts, execution) -> pd.DataFrame:
    """One scene's runs on the platform: every mapping at every count of ``counts``.

    Parameters
    ----------
    today : Today
    trace : tracer.trace.access.AccessTrace
    scene : tracer.scenes.model.Scene
    counts : list of int
        The paper's process counts (1 included).
    execution : coherence.studies.Execution
        Where the runs go (the paper's own).

    Returns
    -------
    DataFrame
        :func:`coherence.study`'s run table.
    """
    from coherence.studies import study

    experiment = today.experiment
    return study(trace, experiment.mapping_objects(), counts, hierarchy=experiment.study_hierarchy(),
                 layout=experiment.layout_object(), cost=experiment.cost_model(), machine=experiment.machine(),
                 scene=scene, progress=experiment.progress, execution=execution).runs


def today_columns(runs: pd.DataFrame, n_processes: int, order) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per scene, what the platform's runs say, and the verdicts they come from.

    Parameters
    ----------
    runs : DataFrame
        The platform's runs with a ``scene`` column.
    n_processes : int
        The verdict's process count (the paper's).
    order : sequence of str
        Mapping order of the verdict texts.

    Returns
    -------
    columns : DataFrame
        ``scene``, ``today_seconds`` (real seconds of the sequential S run at
        the paper's size), ``today_best_mapping``, ``today_best_speedup_user``,
        ``today_decided_by`` (the loss the verdict names) and
        ``today_headline``.
    verdicts : DataFrame
        :func:`analyses.paper.scene_verdicts` on the platform's runs.
    """
    from analyses.paper import scene_verdicts

    verdicts, _ = scene_verdicts(runs, n_processes, order=order)
    sequential = runs[(runs["mapping"] == "S") & (runs["n_processes"] == 1)].set_index("scene")["real_seconds"]
    columns = pd.DataFrame({
        "scene": verdicts["scene"],
        "today_seconds": [float(sequential.get(scene, float("nan"))) for scene in verdicts["scene"]],
        "today_best_mapping": verdicts["best_mapping"],
        "today_best_speedup_user": verdicts["best_speedup_user"].astype(float),
        "today_decided_by": verdicts["decided_by"],
        "today_headline": verdicts["headline"],
    })
    return columns, verdicts
