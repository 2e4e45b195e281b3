"""The study reproduced: all five scenes beside Havran & Žára's table and figures.

>>> from analyses.paper import reproduce, write_paper        # doctest: +SKIP
>>> result = reproduce(size=512)                              # doctest: +SKIP
>>> write_paper(result, "paper")                              # doctest: +SKIP

:func:`reproduce` does, for the chosen scenes (default the study's five):

1. renders (or loads from the trace cache of :mod:`analyses.traces`) each
   scene's access trace with the study-era workload (``study1997``,
   :mod:`tracer.rendering.workload`: a spatial-median BSP, one rule for every scene,
   whose test counts are near the study's, and the tracer's own per-ray
   data), laid out as a 1990s C tracer's structs (``alpha1997``);
2. runs each scene once with one process and the strip mapping S, which gives
   the trace's operation counters and its simulated memory cycles (memory
   cycles depend on the caches and the layout, not on the cycles per
   operation);
3. fits three costs (per intersection test, per ray, per kd-node visit),
   each within its prior range (by default; ``costs`` chooses), to the
   study's sequential S times (:data:`STUDY_TABLE`) with
   :mod:`coherence.calibration`; every other operation is tied to the test
   cost by a ratio fixed in advance. What the fitted model does not explain
   is reported per scene (``unexplained_seconds``), and a cost at a bound is
   flagged (``<cost>_at_bound``). Each scene is also predicted from a fit to
   the other four (leave one out), and every other mapping's one-process
   time is predicted, not fitted;
4. runs every mapping at every process count per scene with the calibrated
   model on an 8-CPU machine whose real time carries a background load
   (:data:`DEFAULT_BACKGROUND` always-runnable processes of other users);
5. judges each scene from the numbers with the report's rule
   (:func:`scene_verdicts`, :func:`analyses.verdict.verdict`).

The study's times are for 512x512 images. At another ``size`` the targets
are scaled by ``(size / 512) ** 2`` (the pixel count), so a small test image
calibrates to comparable cycles per operation.

:func:`write_paper` writes ``paper.csv`` (run table), ``scenes.csv`` (the side
by side table), ``paper.json`` (parameters, versions, calibration, residuals,
verdicts), ``speedup_real.png``, ``speedup_user.png`` and a self-contained
``index.html``. All outputs are deterministic (no timestamps, PNGs without
metadata) and written atomically.

The study's numbers, the defaults and the checks of the inputs live in
:mod:`analyses.paper_study`, the figures and files in
:mod:`analyses.paper_output`; their public names are importable from here.
"""
from __future__ import annotations

import os
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.cluster import dask_executor
from analyses.output import check_output_folder
from analyses.experiment import Experiment
from analyses.memory_budget import memory_shares, runs_at_once, trace_pages_limited
from analyses.paper_output import paper_html, paper_summary, speedup_figure, write_paper
from analyses.paper_today import run_today, today_columns, today_of
from analyses.paper_study import (DEFAULT_BACKGROUND, DEFAULT_MAPPINGS, DEFAULT_PROCESSES, PAPER_EXPERIMENT,
                                  STUDY_SIZE, STUDY_TABLE, PaperResult, check_process_counts, check_scenes)
from analyses.verdict import LOSSES, VERDICT_PROCESSES, format_speedup, verdict, verdict_process_count
from coherence.cost import OPERATIONS
from rtcommon.validate import InputError

__all__ = ["STUDY_TABLE", "STUDY_SIZE", "DEFAULT_BACKGROUND", "DEFAULT_PROCESSES", "DEFAULT_MAPPINGS",
           "PAPER_EXPERIMENT", "PaperResult", "reproduce", "sequential_predictions", "scene_verdicts", "side_by_side", "speedup_figure", "write_paper",
           "paper_summary", "paper_html", "check_scenes", "check_process_counts", "check_output_folder"]

_COUNTERS = tuple(counter for counters in OPERATIONS.values() for counter in counters)
_RAYS = ("primary_rays", "shadow_rays", "reflection_rays", "refraction_rays")
_TESTS = ("tests_sphere", "tests_triangle", "tests_polygon", "tests_patch", "tests_cone")


# --------------------------------------------------------------------------
# the reproduction


def reproduce(experiment: Experiment = PAPER_EXPERIMENT, *, scenes=None, costs=None, crossover: bool = False,
              **choices) -> PaperResult:
    """Calibrate the cost model to the study's times and simulate its runs for every scene.

    Parameters
    ----------
    experiment : analyses.experiment.Experiment
        Image size (the study's is 512), workload, mappings, process counts
        (1 is always added), CPUs, background load, caches, memory layout,
        base cost model (its clock and the sequential runs' cycles), trace
        cache, Dask scheduler, memory budget and progress bars. Default
        :data:`analyses.paper_study.PAPER_EXPERIMENT`: the study's machine
        and tracer (the 21164 as its manuals describe it, a 1990s C tracer's
        structs, the study-era workload whose tests per ray are what the
        calibration's costs multiply, 8 CPUs, background
        :data:`DEFAULT_BACKGROUND`). Its ``scene`` is replaced by each of
        ``scenes`` in turn. The results are the same on a Dask scheduler as
        locally, and do not depend on the memory budget.
    scenes : sequence of str, optional
        Study scenes (default all five, :data:`tracer.scenes.catalog.PAPER_SCENES`).
    costs : coherence.calibration.CostStructure, optional
        Which cycles per operation are fitted and how the rest follow
        (default :data:`coherence.calibration.STUDY1997_PRIOR_COSTS`: per
        test, per ray and per node visit, each within its prior range;
        :data:`coherence.calibration.STUDY1997_COSTS` is the older fit
        within 5-5,000 cycles, :data:`coherence.calibration.FITS` names both).
        With a ``platform``, the study's machine is still the one
        calibrated and judged; the platform is an opt-in "today" column
        beside it (:mod:`analyses.paper_today`): the same mappings and
        process counts on the platform, with its own cost model, no fit.
    crossover : bool
        Also run :func:`analyses.crossover.crossover_study` per scene at the
        verdict's process count with the calibrated model: where would
        coherence have mattered more than balance? (16 more runs of S, P
        and R per scene.)
    **choices
        Fields of ``experiment`` to replace (``size=128``,
        ``cache_dir=...``), a shorthand for :func:`dataclasses.replace`.

    Returns
    -------
    PaperResult
    """
    from tqdm.auto import tqdm

    from analyses.traces import cached_trace
    from coherence import study
    from coherence.calibration import STUDY1997_PRIOR_COSTS, CostStructure
    from coherence.studies import Execution
    from tracer.scenes.catalog import PAPER_SCENES
    from tracer.trace.access import AccessTrace

    # every argument is checked before rendering anything
    if not isinstance(experiment, Experiment):
        raise InputError(f"reproduce needs an analyses.experiment.Experiment, got {type(experiment).__name__}")
    experiment = replace(experiment, **choices) if choices else experiment
    experiment, today = today_of(experiment)
    scenes = check_scenes(PAPER_SCENES if scenes is None else scenes)
    counts = sorted({1, *experiment.n_processes})
    size, background, progress = experiment.size, experiment.background, experiment.progress
    # step 4 runs one run per CPU, step 1 two scenes at once; the same with dask: same outputs
    n_jobs = runs_at_once(experiment.memory_budget, size * size, os.cpu_count() or 1)
    shares = memory_shares(experiment.memory_budget, size * size, max(2, n_jobs))
    mapping_objects = experiment.mapping_objects()
    names = [m.name for m in mapping_objects]
    costs = STUDY1997_PRIOR_COSTS if costs is None else costs
    if not isinstance(costs, CostStructure):
        raise InputError(f"costs must be a coherence.calibration.CostStructure, got {type(costs).__name__}")
    hierarchy = experiment.hierarchy_object()
    layout = experiment.layout_object()
    machine = experiment.machine()
    base = experiment.cost_model()

    # 1-2: traces, and counters and memory cycles of the sequential S run. A trace is memory-mapped and
    # every page a run touched stays resident while it is mapped (all five are about 4 GB at 512x512), so
    # at most two are mapped at once: one scene's run goes on while the next scene's trace is rendered or
    # loaded and run beside it. Only the scene and its render info are kept; step 4 maps the same cache
    # entry again.
    def sequential_run(name, scene, trace):
        with trace_pages_limited(trace, shares):
            sequential = study(trace, ["S"], [1], hierarchy=hierarchy, layout=layout, cost=base, machine=machine,
                               scene=scene, progress=False, execution=Execution(n_jobs=1))
        run = sequential.runs.iloc[0]
        counters = sequential.processes[list(_COUNTERS)].sum()
        return {"scene": name, "memory_cycles": float(run["memory_cycles"]),
                **{c: int(counters[c]) for c in _COUNTERS}}

    loaded = {}
    info_out = {}
    runs_of_scenes = []
    bar = tqdm(scenes, desc="traces and sequential runs", unit="scene", disable=not progress, leave=False,
               file=sys.stderr)
    with ThreadPoolExecutor(max_workers=2) as pool:
        for name in bar:
            bar.set_postfix_str(name)
            one = replace(experiment, scene=name)
            scene, trace, info = cached_trace(one.scene, one.size, cache_dir=one.cache_dir, kd=one.kd,
                                              max_depth=one.max_depth, progress=progress, workload=one.workload,
                                              tree_variant=one.tree_variant,
                                              memory_budget=shares["render_records"])
            loaded[name] = (scene, None, info)
            info_out[name] = {"trace_key": info["key"], "cached": bool(info.get("cached"))}
            runs_of_scenes.append(pool.submit(sequential_run, name, scene, trace))
            del trace
            if len(runs_of_scenes) >= 2:
                runs_of_scenes[-2].result()  # its trace unmapped before the next one is mapped
        measurements = [future.result() for future in runs_of_scenes]
    bar.close()

    # 3: calibration to the study's sequential times
    model, calibration = _calibrate(measurements, costs, base.clock_hz, size)
    residuals = calibration["residuals"]

    # 4: every mapping at every count, per scene, with the calibrated model
    frames = []
    today_frames = []
    crossings = []
    verdict_n = verdict_process_count(counts)
    with dask_executor(experiment.dask) as executor:
        for name in scenes:
            scene, _, info = loaded[name]
            if progress:
                print(f"simulating {name}", file=sys.stderr)
            folder = Path(info["path"]) / "trace"
            trace = AccessTrace.load(folder, mmap=True)  # the entry of step 1
            with trace_pages_limited(trace, shares):
                execution = Execution(n_jobs=n_jobs, executor=executor, trace_folder=folder,
                                      shared_lines_budget=shares["shared_lines"])
                result = study(trace, mapping_objects, counts, hierarchy=hierarchy, layout=layout, cost=model,
                               machine=machine, scene=scene, progress=progress, execution=execution)
                frames.append(result.runs.assign(scene=name))
                if today is not None:
                    today_frames.append(run_today(today, trace, scene, counts, execution).assign(scene=name))
                if crossover and verdict_n > 1:
                    from analyses.crossover import crossover_study

                    crossings.append(crossover_study(trace, cost=model, hierarchy=hierarchy, layout=layout,
                                                     scene=scene, machine=machine, n_processes=verdict_n,
                                                     execution=Execution(executor=executor, trace_folder=folder))
                                     .assign(scene=name))
            del trace
    runs = pd.concat(frames, ignore_index=True)
    runs = runs[["scene"] + [c for c in runs.columns if c != "scene"]]

    table = side_by_side(loaded, runs, residuals, size)
    predictions = sequential_predictions(runs, size, order=names)
    crossings = pd.concat(crossings, ignore_index=True) if crossings else None
    verdicts, numbers = scene_verdicts(runs, verdict_n, order=names)
    today_result = None
    if today is not None:
        today_runs = pd.concat(today_frames, ignore_index=True)
        today_runs = today_runs[["scene"] + [c for c in today_runs.columns if c != "scene"]]
        columns, today_verdicts = today_columns(today_runs, verdict_n, names)
        table = table.merge(columns, on="scene", how="left")
        today_result = {"platform": today.parameters, "runs": today_runs, "verdicts": today_verdicts}
    # the experiment's record (one per scene: "scenes" for "scene"), with what this run resolved
    recorded = {key: value for key, value in experiment.as_parameters().items() if key != "scene"}
    parameters = {
        **recorded, "size": size, "scenes": scenes, "mappings": names, "n_processes": counts,
        "n_cpus": int(machine.n_cpus), "background_load": background, "verdict_n_processes": int(verdict_n),
        "hierarchy": hierarchy.to_dict(), "layout": layout.name, "machine": {k: (v.item() if isinstance(v, np.generic) else v)
                                           for k, v in machine.__dict__.items()},
        "clock_hz": base.clock_hz, "costs": costs.to_dict(), "study_size": STUDY_SIZE,
        "workload": experiment.workload, "crossover": bool(crossover), "memory_shares": shares,
        "runs_at_once": n_jobs,
    }
    return PaperResult(table=table, runs=runs, calibration=calibration, predictions=predictions,
                       verdicts=verdicts, verdict_numbers=numbers, parameters=parameters, info=info_out,
                       crossover=crossings, today=today_result)


def _calibrate(measurements: list, costs, clock_hz: float, size: int):
    """Fit the cost model to the study's sequential S times (step 3 of :func:`reproduce`).

    ``measurements`` holds one dict per scene: ``scene``, ``memory_cycles``
    and the operation counters of its sequential S run. The fit is
    :func:`coherence.calibration.fit_costs` (bounded least squares of
    relative errors); every scene is also predicted from a fit to the other
    four (:func:`coherence.calibration.leave_one_out`). Returns the
    calibrated model and :attr:`PaperResult.calibration`.
    """
    from coherence.calibration import at_bounds, fit_costs, fitted_values, leave_one_out, rms

    measurements = pd.DataFrame(measurements).set_index("scene")
    study_rows = STUDY_TABLE.set_index("scene")
    scale = (size / STUDY_SIZE) ** 2
    measurements.insert(0, "seconds", study_rows.loc[measurements.index, "sequential_seconds"].to_numpy() * scale)
    model, fit = fit_costs(measurements, costs, clock_hz=clock_hz, name="calibrated to the study")
    values = fitted_values(model, costs)
    residuals = pd.DataFrame({
        "study_seconds": study_rows.loc[measurements.index, "sequential_seconds"].to_numpy(),
        "target_seconds": fit["measured_seconds"],
        "fitted_seconds": fit["fitted_seconds"],
        "residual_seconds": fit["fitted_seconds"] - fit["measured_seconds"],
        "unexplained_seconds": fit["unexplained_seconds"],
        "unexplained_share": fit["unexplained_seconds"] / fit["measured_seconds"],
        "relative_error": fit["relative_error"],
        "memory_share": fit["memory_share"],
        "memory_seconds": measurements["memory_cycles"].to_numpy() / clock_hz,
    }, index=measurements.index)
    residuals["fitted_seconds_at_512"] = residuals["fitted_seconds"] / scale
    residuals["unexplained_seconds_at_512"] = residuals["unexplained_seconds"] / scale
    bound = at_bounds(values, costs)
    for name, flag in bound.items():  # one flag per cost, on every scene's row: every output carries it
        residuals[f"{name}_at_bound"] = flag
    if len(measurements) >= 2:
        held_out = leave_one_out(measurements, costs, clock_hz=clock_hz)
        residuals["left_out_seconds"] = held_out["predicted_seconds"]
        residuals["left_out_error"] = held_out["relative_error"]
    else:
        residuals["left_out_seconds"] = residuals["left_out_error"] = np.nan
    residuals.index.name = "scene"
    residuals = residuals.reset_index()
    fitted = [{"name": cost.name, "reference": next(iter(cost.multiples)), "cycles": values[cost.name],
               "low": cost.bounds[0], "high": cost.bounds[1], "at_bound": bound[cost.name]}
              for cost in costs.fitted]
    calibration = {
        "model": model.to_dict(),
        "structure": costs.to_dict(),
        "fitted": fitted,
        "at_bound": [cost["name"] for cost in fitted if cost["at_bound"]],
        "scale": scale,
        "residuals": residuals,
        "rms_relative_error": rms(residuals["relative_error"]),
        "left_out_rms_relative_error": (rms(residuals["left_out_error"]) if len(measurements) >= 2
                                        else float("nan")),
        "measurements": measurements.reset_index(),
    }
    return model, calibration


def sequential_predictions(runs: pd.DataFrame, size: int, order=None) -> pd.DataFrame:
    """Per scene, every mapping's one-process time predicted by the calibrated model, at 512x512.

    Only S's time was fitted; the others (P, R, B with 64x64 fields, DB with
    32x32 blocks) differ from it only through the order in which pixels meet
    the caches (and DB's dispatches). Nothing is tuned to them.

    Returns
    -------
    DataFrame
        ``scene``, ``<mapping>_seconds`` per mapping (user time of the
        one-process run, scaled to 512x512 by pixel count) and
        ``<mapping>_minus_S_percent`` per mapping other than S.
    """
    one = runs[runs["n_processes"] == 1]
    mappings = list(order) if order is not None else list(dict.fromkeys(one["mapping"]))
    scale = (size / STUDY_SIZE) ** 2
    rows = []
    for scene in dict.fromkeys(one["scene"]):
        seconds = one[one["scene"] == scene].set_index("mapping")["user_seconds_max"].astype(float) / scale
        row = {"scene": scene, **{f"{m}_seconds": float(seconds[m]) for m in mappings if m in seconds}}
        if "S" in seconds:
            for m in mappings:
                if m != "S" and m in seconds:
                    row[f"{m}_minus_S_percent"] = float(100.0 * (seconds[m] - seconds["S"]) / seconds["S"])
        rows.append(row)
    return pd.DataFrame(rows)


def _geometry(counts: dict) -> str:
    parts = [f"{n} {kind}{'' if n == 1 else 'es' if kind == 'patch' else 's'}" for kind, n in counts.items() if n]
    return " + ".join(parts) or "empty"


def side_by_side(loaded: dict, runs: pd.DataFrame, residuals: pd.DataFrame, size: int) -> pd.DataFrame:
    """Per scene, the study's figures beside ours.

    Parameters
    ----------
    loaded : dict
        Scene name -> (scene, trace, render info) from the trace cache (the
        trace is not used and may be ``None``).
    runs : DataFrame
        The run table (for the calibrated sequential S time and rays).
    residuals : DataFrame
        The calibration's per-scene residuals.
    size : int

    Returns
    -------
    DataFrame
        ``scene``, ``study_geometry``, ``our_geometry``, ``study_elements``,
        ``our_elements``, ``study_lights``, ``our_lights``, ``study_max_depth``,
        ``our_max_depth``, ``study_tests_1e6``, ``our_tests_1e6`` (at our
        size), ``study_seconds``, ``target_seconds`` (at our size),
        ``fitted_seconds`` (calibrated model, sequential S),
        ``unexplained_seconds`` (target minus fitted: what the model, every
        cost inside its bounds, does not explain), ``unexplained_share``
        (of the target), ``relative_error``, ``simulated_seconds`` (sequential S run of the
        study), ``our_rays``, ``our_tests_per_ray``, ``study_tests_per_pixel``
        and ``our_tests_per_pixel``, then ``<cost>_at_bound`` per fitted
        cost (the same on every row: whether that cost sits at a bound).
    """
    study_rows = STUDY_TABLE.set_index("scene")
    fits = residuals.set_index("scene")
    rows = []
    for name, (scene, _, info) in loaded.items():
        summary = scene.summary()
        totals = info["totals"]
        rays = int(sum(int(totals.get(c, 0)) for c in _RAYS))
        tests = int(sum(int(totals.get(c, 0)) for c in _TESTS))
        s1 = runs[(runs["scene"] == name) & (runs["mapping"] == "S") & (runs["n_processes"] == 1)]
        study_row = study_rows.loc[name]
        rows.append({
            "scene": name,
            "study_geometry": study_row["geometry"],
            "our_geometry": _geometry(summary["counts"]),
            "study_elements": int(study_row["elements"]),
            "our_elements": int(summary["elements"]),
            "study_lights": int(study_row["lights"]),
            "our_lights": int(summary["lights"]),
            "study_max_depth": int(study_row["max_depth"]),
            "our_max_depth": int(summary["max_depth"]),
            "study_tests_1e6": float(study_row["tests_1e6"]),
            "our_tests_1e6": tests / 1e6,
            "study_seconds": float(study_row["sequential_seconds"]),
            "target_seconds": float(fits.loc[name, "target_seconds"]),
            "fitted_seconds": float(fits.loc[name, "fitted_seconds"]),
            "unexplained_seconds": float(fits.loc[name, "unexplained_seconds"]),
            "unexplained_share": float(fits.loc[name, "unexplained_share"]),
            "relative_error": float(fits.loc[name, "relative_error"]),
            "simulated_seconds": float(s1["real_seconds"].iloc[0]) if len(s1) else float("nan"),
            "our_rays": rays,
            "our_tests_per_ray": tests / rays if rays else float("nan"),
            "study_tests_per_pixel": float(study_row["tests_1e6"]) * 1e6 / STUDY_SIZE ** 2,
            "our_tests_per_pixel": tests / (size * size),
            **{column: bool(fits.loc[name, column]) for column in fits.columns if column.endswith("_at_bound")},
        })
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------
# verdicts


def scene_verdicts(runs: pd.DataFrame, n_processes: int = VERDICT_PROCESSES,
                   order=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per scene: :func:`analyses.verdict.verdict` on its runs, and its best mappings.

    The rule is the report's: the headline names the loss (imbalance,
    coherence or dispatch) whose worst case over the mappings is largest,
    and one sentence per mapping gives its user speed-up and losses. Before
    it, one sentence names the best mapping by user and by real-time
    speed-up. Every number of the text is returned, exactly as printed, in
    the second table.

    Parameters
    ----------
    runs : DataFrame
        Columns ``scene``, ``mapping``, ``n_processes``, ``speedup_user``,
        ``speedup_real``, ``imbalance_loss``, ``coherence_loss``,
        ``dispatch_loss`` and optionally ``dispatch_share``.
    n_processes : int
    order : sequence of str, optional
        Mapping order of the texts.

    Returns
    -------
    verdicts : DataFrame
        ``scene``, ``n_processes``, ``best_mapping``, ``best_speedup_user``,
        ``best_mapping_real``, ``best_speedup_real``, then per loss of
        :data:`analyses.verdict.LOSSES` ``max_<loss>`` and
        ``max_<loss>_mapping`` (``max_imbalance_loss``,
        ``max_imbalance_mapping``, ...), ``decided_by``, ``headline`` and
        ``text``.
    numbers : DataFrame
        ``scene``, ``mapping``, ``n_processes``, ``metric``, ``value``.
    """
    verdicts = []
    numbers = []
    for scene in dict.fromkeys(runs["scene"]):
        rows = runs[runs["scene"] == scene]
        at = rows[rows["n_processes"] == n_processes]
        if at.empty:
            raise InputError(f"{scene}: no runs with n_processes == {n_processes}")
        judged = verdict(rows, n_processes, order=order)
        at = at.set_index("mapping")
        best = at["speedup_user"].astype(float).idxmax()
        best_real = at["speedup_real"].astype(float).idxmax()
        best_text = format_speedup(at.loc[best, "speedup_user"])  # the verdict quotes every mapping's
        real_text = format_speedup(at.loc[best_real, "speedup_real"])
        quoted = judged.numbers.assign(scene=scene)
        real_row = {"scene": scene, "mapping": best_real, "n_processes": int(n_processes), "metric": "speedup_real",
                    "value": float(real_text)}
        numbers.append(pd.concat([quoted, pd.DataFrame([real_row])], ignore_index=True))
        text = (f"{scene.capitalize()} at {n_processes} processes: {best} is best with a user speed-up of "
                f"{best_text} (best real-time speed-up: {best_real} {real_text}). {judged.text}")
        worst = {}
        for column, _, short in LOSSES:
            mapping, value = judged.worst[column]
            worst[f"max_{short}_loss"] = value
            worst[f"max_{short}_mapping"] = mapping
        verdicts.append({
            "scene": scene, "n_processes": int(n_processes),
            "best_mapping": best, "best_speedup_user": float(at.loc[best, "speedup_user"]),
            "best_mapping_real": best_real, "best_speedup_real": float(at.loc[best_real, "speedup_real"]),
            **worst, "decided_by": judged.decided_by, "headline": judged.headline, "text": text,
        })
    columns = ["scene", "mapping", "n_processes", "metric", "value"]
    numbers = pd.concat(numbers, ignore_index=True)[columns] if numbers else pd.DataFrame(columns=columns)
    return pd.DataFrame(verdicts), numbers
