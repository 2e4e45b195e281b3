"""The verdict under uncertainty: a global sensitivity study of "load balance or coherence?".

>>> from analyses.robustness import ROBUSTNESS_EXPERIMENT, robustness     # doctest: +SKIP
>>> result = robustness(ROBUSTNESS_EXPERIMENT, scenes=["tetra"], trajectories=10, seed=1)
>>> result.summary["scenes"]["tetra"]["p_load_balance"]                     # doctest: +SKIP

For each scene the trace is rendered once per tree variant (through the
trace cache of :mod:`analyses.traces`) and every sample only replays the
trace of its variant. The samples are
Morris trajectories (:func:`analyses.robustness_factors.morris_design`)
over every unknown the toolkit has a mechanism for
(:data:`analyses.robustness_factors.FACTORS`); one sample is one
:func:`coherence.study` of every mapping at one process and at
:data:`analyses.verdict.VERDICT_PROCESSES`, on the sample's machine,
caches, memory image and cost model, so the mappings of a sample share all
its values and seeds. A run whose miss counts an earlier sample of the same
trace already holds (the samples differ only in costs, and the run's
schedule does not depend on cycles) is re-costed from them instead of
simulated (:mod:`coherence.recost`, :data:`RE_COSTED`); the summary counts
the runs of each path per scene (``runs``, :data:`RUN_PATHS`). The samples
of a design go through one :func:`coherence.studies.study_stream`: while a
sample's last runs are simulated, the next samples' runs take the free
threads, with the same results as one sample after another.

From each sample (:data:`SAMPLE_COLUMNS`): the one-process time of B and DB
relative to S's (``(T_B - T_S) / T_S``), every mapping's coherence and
imbalance loss at 8 processes, the verdict and its margin: the largest
imbalance loss of any mapping minus the largest coherence or dispatch loss,
positive when the verdict is "load balance". Morris's ``mu_star`` of the
margin ranks the unknowns; the flip region is a threshold on each of the
top three (:func:`flip_thresholds`). With ``sobol=N``, Saltelli's design of
``N (k + 2)`` samples over the :data:`SOBOL_FACTORS` highest-ranked unknowns
(the others at the middle of their unit range, :data:`HELD_AT`) gives their
first-order and total Sobol indices of the margin. The base's size is at
least :data:`analyses.robustness_size.VERDICT_MIN_SIZE` for the 8-process
losses and the verdict; the size check (:mod:`analyses.robustness_size`)
says whether the one-process quantities would hold on a smaller image.
"""
from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from analyses.experiment import Experiment
from analyses.paper_study import PAPER_EXPERIMENT
from analyses.robustness_factors import (FACTORS, LEFT_OUT, MORRIS_LEVELS, factor_values, morris_design,
                                         morris_indices, sample_setup, sobol_design, sobol_indices)
from analyses.robustness_size import (SIZE_CHECK_MAPPINGS, SIZE_CHECK_QUANTITIES, SIZE_CHECK_TOLERANCE,
                                      VERDICT_MIN_SIZE, check_sizes, compare_sizes, size_check_rows)
from analyses.verdict import VERDICT_PROCESSES
from rtcommon.validate import InputError, require_int, require_power_of_two

__all__ = ["ROBUSTNESS_EXPERIMENT", "RobustnessResult", "robustness", "sample_outputs", "scene_summary",
           "flip_thresholds", "trajectory_seeds", "one_process_differences", "SAMPLE_COLUMNS", "PERCENTILES", "TOP"]

#: The base of every sample: the paper's study-era reproduction (workload,
#: machine) at 256 x 256, the smallest size the verdict is computed at
#: (:data:`analyses.robustness_size.VERDICT_MIN_SIZE`), one process and the
#: verdict's process count.
ROBUSTNESS_EXPERIMENT = replace(PAPER_EXPERIMENT, size=VERDICT_MIN_SIZE, n_processes=(1, VERDICT_PROCESSES),
                                progress=False)

#: Percentiles of every distribution the summary gives.
PERCENTILES = (5, 50, 95)

#: How many of the highest-ranked unknowns the summary and the flip region name.
TOP = 3

#: How many of the highest-ranked unknowns (by Morris mu*) Sobol's indices are computed for.
SOBOL_FACTORS = 4

#: Unit coordinate of every unknown Sobol's design does not vary: the middle
#: of its range (the geometric mean of a log-uniform one, the middle choice).
HELD_AT = 0.5

#: The paths a sample's run can take (:class:`coherence.recost.RunStore`), counted per scene and design.
RUN_PATHS = ("simulated", "re_costed", "reused")

#: Bytes a scene's runs may share in line addresses worked out once per placement
#: (:class:`coherence.studies.Execution` ``shared_lines_budget``), as held at the peak of making them
#: (:func:`coherence.pixel_lines.held_bytes`: 9 a line access kept, 8 a page run): the study replays each
#: placement in every run of many samples. It does not hold every trace at the verdict's size: the largest
#: (the malloc1997 memory image on the larger tree variants of balls, shell and room) are converted per run,
#: with the same counts; ``benchmarks/bench_pixel_lines.py`` prints each trace's bytes against it.
LINES_BUDGET = 3 << 30

#: What the summary's parameters say of re-costing.
RE_COSTED = ("a run whose schedule does not depend on cycles (coherence.recost.fixed_schedule: a static mapping or "
             "one process, with ours and the other users' processes each on a CPU of its own) is re-costed from the "
             "miss counts of an earlier sample of the same trace that differed from it only in costs (latencies, "
             "DTB miss cost, operation costs, time slice) or in the other users' count and footprint, which such a "
             "run does not see; a run identical to an earlier one (the other users' footprint aside when there are "
             "none) is reused; every other run is simulated")

#: Columns of the samples table before the per-mapping losses and the factors' values.
SAMPLE_COLUMNS = ("scene", "sample", "trajectory", "seed", "b_minus_s", "db_minus_s", "decided_by",
                  "load_balance", "margin")


@dataclass
class RobustnessResult:
    """Everything ``coherence robustness`` writes.

    Attributes
    ----------
    samples : DataFrame
        One row per (scene, sample): :data:`SAMPLE_COLUMNS`, then
        ``coherence_loss_<M>`` and ``imbalance_loss_<M>`` per mapping M at
        the verdict's process count, each factor's value, and ``design``
        (``morris`` or ``sobol``).
    indices : DataFrame
        One row per (scene, factor): ``mu_star``, ``mu``, ``sigma`` of the
        margin and ``rank`` (1 = largest ``mu_star``); with Sobol, ``S1``
        and ``ST`` (NaN for a factor Sobol's design held).
    summary : dict
        ``parameters`` (the base's, the scenes, trajectories, seed, factors
        and left-out unknowns) and ``scenes``: per scene what
        :func:`scene_summary` gives, and ``runs``: how many runs of the
        Morris samples were simulated, re-costed and reused
        (:data:`RUN_PATHS`; Sobol's under ``sobol``).
    """

    samples: pd.DataFrame
    indices: pd.DataFrame
    summary: dict = field(default_factory=dict)


def robustness(base: Experiment = ROBUSTNESS_EXPERIMENT, *, scenes=("tetra",), trajectories: int = 10,
               seed: int = 0, sobol: int = 0, size_check: bool = True, executor=None,
               timings: dict | None = None) -> RobustnessResult:
    """Morris screening of the verdict over every unknown with a mechanism, per scene.

    Parameters
    ----------
    base : analyses.experiment.Experiment
        Size, workload, mappings, process counts (the verdict's count is
        needed; 1 is always added), trace cache and everything not sampled.
        With ``progress``, a bar on stderr per scene and phase (Morris
        samples, size check, Sobol samples) counts its samples.
    scenes : sequence of str
        The study's scenes.
    trajectories : int
        Morris trajectories, >= 2; each is ``len(FACTORS) + 1`` samples.
    seed : int
        Seed of the design, the page placements and the other users' streams.
    sobol : int
        Base samples ``N`` of Sobol's design (a power of two), or 0 for
        Morris screening only.
    size_check : bool
        Check, per scene, the one-process quantities at half and twice the
        base's size on :data:`~analyses.robustness_size.SIZE_CHECK_POINTS`
        samples (:mod:`analyses.robustness_size`; ``size_check`` in each
        scene's summary).
    executor : concurrent.futures.Executor, optional
        Simulate the runs there (a Dask client's executor).
    timings : dict, optional
        Filled with scene -> phase (``morris``, ``size_check``, ``sobol``)
        -> ``seconds`` (wall) and ``cpu_seconds`` (this process's, every
        thread's), for benchmarks; the results do not depend on it.

    Returns
    -------
    RobustnessResult
    """
    from analyses.paper_study import check_scenes

    if not isinstance(base, Experiment):
        raise InputError(f"robustness needs an analyses.experiment.Experiment, got {type(base).__name__}")
    require_int("trajectories", trajectories, 2)
    require_int("seed", seed, 0)
    if require_int("sobol", sobol, 0):
        require_power_of_two("sobol", sobol)
    if VERDICT_PROCESSES not in base.n_processes:
        raise InputError(f"Experiment.n_processes must include {VERDICT_PROCESSES}, the verdict's process count; "
                         f"got {list(base.n_processes)}")
    scenes = check_scenes(scenes)
    names = [entry.name for entry in FACTORS]
    design = morris_design(names, trajectories, seed)
    seeds = trajectory_seeds(seed, trajectories)
    frames, index_rows, summaries = [], [], {}
    timings = {} if timings is None else timings
    for scene in scenes:
        clock = _Clock(timings.setdefault(scene, {}))
        replays = _Replays(replace(base, scene=scene), executor)
        rows, paths = _scene_samples(replace(base, scene=scene), design, seeds, replays, "Morris samples")
        frame = pd.DataFrame(rows)
        indices = morris_indices(names, design, frame["margin"].to_numpy(), seed)
        ranked = sorted(names, key=lambda name: -indices["mu_star"][name])
        for name in names:
            index_rows.append({"scene": scene, "factor": name, **{k: indices[k][name] for k in indices},
                               "rank": ranked.index(name) + 1})
        summaries[scene] = {**scene_summary(frame, ranked, indices["mu_star"], base.mapping_names()), "runs": paths}
        frames.append(frame.assign(design="morris"))
        clock.lap("morris")
        if size_check:
            summaries[scene]["size_check"] = _size_check(replace(base, scene=scene), design, seeds, replays)
            clock.lap("size_check")
        if sobol:
            top = ranked[:SOBOL_FACTORS]
            sobol_frame, sobol_result = _sobol(replace(base, scene=scene), top, sobol, seed, replays)
            for row in index_rows[-len(names):]:
                row.update({key: sobol_result[key].get(row["factor"], np.nan) for key in ("S1", "ST")})
            summaries[scene]["sobol"] = {"factors": top, "base_samples": int(sobol),
                                         "n_evaluations": int(len(sobol_frame)),
                                         **{key: sobol_result[key] for key in ("S1", "ST", "runs")}}
            frames.append(sobol_frame.assign(design="sobol"))
            clock.lap("sobol")
    parameters = {**base.as_parameters(), "scenes": scenes, "trajectories": int(trajectories), "seed": int(seed),
                  "verdict_n_processes": VERDICT_PROCESSES, "morris_levels": MORRIS_LEVELS, "sobol": int(sobol),
                  "sobol_held_at": HELD_AT, "size_check": bool(size_check),
                  "factors": [{"name": e.name, "distribution": e.distribution, "low": e.low, "high": e.high,
                               "choices": list(e.choices), "unit": e.unit} for e in FACTORS],
                  "left_out": dict(LEFT_OUT), "re_costed": RE_COSTED}
    for key in ("hierarchy", "cost", "layout", "background_load", "background_footprint", "page_placement",
                "page_seed", "tree_variant", "scene"):
        parameters.pop(key)  # sampled per run, recorded per sample
    return RobustnessResult(pd.concat(frames, ignore_index=True), pd.DataFrame(index_rows),
                            {"parameters": parameters, "scenes": summaries})


class _Clock:
    """Wall and CPU time of consecutive phases, written into ``phases`` (phase -> seconds, cpu_seconds)."""

    def __init__(self, phases: dict):
        self.phases = phases
        self.start = (time.perf_counter(), time.process_time())

    def lap(self, phase: str) -> None:
        now = (time.perf_counter(), time.process_time())
        self.phases[phase] = {"seconds": now[0] - self.start[0], "cpu_seconds": now[1] - self.start[1]}
        self.start = now


def trajectory_seeds(seed: int, trajectories: int) -> list[int]:
    """One seed per trajectory: the samples of a trajectory differ only in the factor it steps."""
    return [int(np.random.default_rng([int(seed), t]).integers(0, 2**31 - 1)) for t in range(int(trajectories))]


def _sobol(base: Experiment, top, base_samples: int, seed: int, replays: _Replays):
    """Sobol's samples of one scene over the unknowns ``top`` (the rest held at :data:`HELD_AT`), and the indices."""
    names = [entry.name for entry in FACTORS]
    partial = sobol_design(top, base_samples, seed)
    design = np.full((partial.shape[0], len(names)), HELD_AT)
    design[:, [names.index(name) for name in top]] = partial
    # every Sobol sample shares one seed: the indices see no noise of the placement's draw
    rows, paths = _scene_samples(base, design, trajectory_seeds(seed, 1), replays, "Sobol samples")
    frame = pd.DataFrame(rows)
    return frame, {**sobol_indices(top, frame["margin"].to_numpy(), seed), "runs": paths}


class _Replays:
    """One scene's traces, rendered or loaded once each (one kept in memory: the designs step one factor at a
    time), each with a :class:`coherence.recost.RunStore`, and how many runs took each path so far."""

    def __init__(self, base: Experiment, executor):
        self.base = base
        self.executor = executor
        self.key = None
        self.replay = None
        self.store = None
        self.done = dict.fromkeys(RUN_PATHS, 0)  # runs of the stores already let go

    def __call__(self, variant, size=None):
        """(scene, trace, execution) of tree ``variant`` at ``size`` (default: the base's)."""
        from analyses.traces import cached_trace
        from coherence.recost import RunStore
        from coherence.studies import Execution

        base = self.base
        key = (variant, size or base.size)
        if key != self.key:
            self.done = self.paths()
            scene, trace, info = cached_trace(base.scene, key[1], cache_dir=base.cache_dir, kd=base.kd_builder(),
                                              max_depth=base.max_depth, progress=base.progress,
                                              workload=base.workload, tree_variant=variant)
            self.store = RunStore()
            self.key = key
            self.replay = (scene, trace, Execution(executor=self.executor, trace_folder=f"{info['path']}/trace",
                                                   shared_lines_budget=LINES_BUDGET, store=self.store))
        return self.replay

    def paths(self) -> dict:
        """Runs simulated, re-costed and reused so far (:data:`RUN_PATHS`)."""
        store = self.store
        return {path: self.done[path] + (getattr(store, path) if store is not None else 0) for path in RUN_PATHS}


def _scene_samples(base: Experiment, design: np.ndarray, seeds, replays: _Replays,
                   phase: str = "samples") -> tuple[list[dict], dict]:
    """The rows of ``design``'s samples, and how many runs took each path (:data:`RUN_PATHS`) for them.

    The samples' studies go through one :func:`coherence.studies.study_stream`: while a sample's last runs
    are simulated, the next samples' start on the free threads. With ``base.progress``, a bar named by the
    scene and ``phase`` counts the samples as their results come.
    """
    before = replays.paths()
    per_trajectory = design.shape[0] // len(seeds)
    samples = []  # (values, seed, trajectory, scene) per sample, in order, as the stream reads the calls

    def calls():
        for index, unit_row in enumerate(design):
            trajectory = index // per_trajectory
            values = factor_values(unit_row)
            replay = replays(values["tree_variant"])
            samples.append((values, seeds[trajectory], trajectory, replay[0].name))
            yield _sample_call(base, replay, values, seeds[trajectory])

    rows = []
    with warnings.catch_warnings(record=True) as caught, \
            _samples_bar(design.shape[0], base, phase) as bar:  # every sample warns alike: say each thing once
        warnings.simplefilter("always")
        for index, result in enumerate(_stream(calls())):
            values, seed, trajectory, scene = samples[index]
            rows.append({"scene": scene, "sample": index, "trajectory": trajectory, "seed": seed,
                         **sample_outputs(result.runs), **values})
            bar.update(1)
    for message in dict.fromkeys(str(warning.message) for warning in caught):
        warnings.warn(message, stacklevel=3)
    after = replays.paths()
    return rows, {path: after[path] - before[path] for path in RUN_PATHS}


def _samples_bar(total: int, base: Experiment, phase: str):
    """A tqdm bar on stderr of ``total`` samples of ``phase`` of ``base.scene``, off unless ``base.progress``.

    It stays on the terminal when done, so a long study shows what each phase took.
    """
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=f"{base.scene}: {phase}", unit="sample", disable=not base.progress,
                file=sys.stderr)


def _stream(calls):
    """:func:`coherence.studies.study_stream` of ``calls`` (a separate name, for benchmarks to time)."""
    from coherence.studies import study_stream

    return study_stream(calls)


def _sample_call(base: Experiment, replay, values: dict, seed: int):
    """The :class:`coherence.studies.StudyCall` of the sample of ``values`` on ``replay`` = (scene, trace,
    execution)."""
    from coherence.studies import StudyCall

    scene, trace, execution = replay
    setup = sample_setup(base, values, seed)
    experiment = setup.experiment
    return StudyCall(trace, tuple(experiment.mapping_objects()), tuple(experiment.n_processes),
                     hierarchy=experiment.hierarchy_object(), layout=experiment.layout_object(),
                     cost=experiment.cost_model(), machine=setup.machine, scene=scene, execution=execution)


def _sample_runs(base: Experiment, replay, values: dict, seed: int) -> pd.DataFrame:
    """The run table (:attr:`coherence.StudyResult.runs`) of the sample of ``values`` on ``replay``."""
    result, = _stream([_sample_call(base, replay, values, seed)])
    return result.runs


def _size_check(base: Experiment, design: np.ndarray, seeds, replays: _Replays) -> dict:
    """The size check of one scene (:mod:`analyses.robustness_size`) on the Morris ``design``."""
    small_size, reference_size = check_sizes(base.size)
    rows = size_check_rows(design.shape[0])
    per_trajectory = design.shape[0] // len(seeds)
    # one-process runs of S, B and DB only, on the base's tree (one trace per size)
    checked = replace(base, mappings=SIZE_CHECK_MAPPINGS, n_processes=(1,))
    sizes = (small_size, reference_size)

    def calls():
        for size in sizes:
            for index in rows:
                point = {**factor_values(design[index]), "tree_variant": base.tree_variant}
                yield _sample_call(replace(checked, size=size), replays(base.tree_variant, size), point,
                                   seeds[index // per_trajectory])

    values = {size: {name: [] for name in SIZE_CHECK_QUANTITIES} for size in sizes}
    phase = f"size check at {small_size} and {reference_size}"
    with warnings.catch_warnings(), _samples_bar(len(sizes) * len(rows), base, phase) as bar:
        warnings.simplefilter("ignore")  # small images warn of idle processes; the Morris samples said so
        for number, result in enumerate(_stream(calls())):
            differences = one_process_differences(result.runs)
            for name in SIZE_CHECK_QUANTITIES:
                values[sizes[number // len(rows)]][name].append(differences[name])
            bar.update(1)
    return {"small_size": small_size, "reference_size": reference_size, "verdict_size": int(base.size),
            "tolerance": SIZE_CHECK_TOLERANCE, "samples": rows.tolist(), "tree_variant": base.tree_variant,
            "quantities": compare_sizes(values[small_size], values[reference_size], base.size)}


def sample_outputs(runs: pd.DataFrame, n_processes: int = VERDICT_PROCESSES) -> dict:
    """One sample's outputs from its run table (:attr:`coherence.StudyResult.runs`).

    ``b_minus_s`` and ``db_minus_s`` (one-process user time of B and DB
    relative to S's, NaN when one of them did not run), ``decided_by`` and
    ``load_balance`` (the verdict at ``n_processes``), ``margin``, and
    ``coherence_loss_<M>`` and ``imbalance_loss_<M>`` per mapping M.
    """
    from analyses.verdict import verdict

    judged = verdict(runs, n_processes)
    worst = {column: value for column, (_, value) in judged.worst.items()}
    out = one_process_differences(runs)
    out["decided_by"] = judged.decided_by
    out["load_balance"] = judged.decided_by == "load balance"
    out["margin"] = float(worst["imbalance_loss"] - max(worst["coherence_loss"], worst["dispatch_loss"]))
    for row in runs[runs["n_processes"] == n_processes].itertuples(index=False):
        out[f"coherence_loss_{row.mapping}"] = float(row.coherence_loss)
        out[f"imbalance_loss_{row.mapping}"] = float(row.imbalance_loss)
    return out


def one_process_differences(runs: pd.DataFrame) -> dict:
    """``b_minus_s`` and ``db_minus_s``: one-process user time of B and DB relative to S's (NaN when one did not run)."""
    one = runs[runs["n_processes"] == 1].set_index("mapping")["user_cycles_max"]
    out = {}
    for mapping, key in (("B", "b_minus_s"), ("DB", "db_minus_s")):
        out[key] = float(one[mapping] / one["S"] - 1.0) if mapping in one and "S" in one else float("nan")
    return out


def _percentiles(values) -> dict:
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return {f"p{p}": None for p in PERCENTILES}
    return {f"p{p}": float(np.percentile(values, p)) for p in PERCENTILES}


def scene_summary(frame: pd.DataFrame, ranked, mu_star: dict, mappings) -> dict:
    """The summary of one scene's samples.

    ``n_evaluations``; percentiles (:data:`PERCENTILES`) of ``b_minus_s``,
    ``db_minus_s`` and ``margin``; per mapping its coherence and imbalance
    losses (median and the 5-95% interval); ``p_load_balance``, the
    fraction of samples whose verdict is "load balance"; ``mu_star`` of
    every factor, ``top`` (the :data:`TOP` largest) and ``flip``
    (:func:`flip_thresholds` on the top ones).
    """
    losses = {}
    for mapping in mappings:
        losses[mapping] = {kind: _percentiles(frame[f"{kind}_loss_{mapping}"]) for kind in ("coherence", "imbalance")
                           if f"{kind}_loss_{mapping}" in frame}
    top = list(ranked[:TOP])
    return {"n_evaluations": int(len(frame)),
            "b_minus_s": _percentiles(frame["b_minus_s"]), "db_minus_s": _percentiles(frame["db_minus_s"]),
            "losses": losses, "p_load_balance": float(frame["load_balance"].mean()),
            "margin": _percentiles(frame["margin"]),
            "mu_star": {name: float(mu_star[name]) for name in ranked}, "top": top,
            "flip": flip_thresholds(frame, top)}


def flip_thresholds(frame: pd.DataFrame, factors) -> dict:
    """Where the verdict flips, per factor: a threshold, a set of choices, or ``"none in range"``.

    For a numeric factor: the value ``t`` (midway between two sampled
    values) and side such that "load balance exactly when the factor is
    above (below) ``t``" agrees with the most samples; for a categorical
    one: the choices where most samples say "load balance". ``agreement``
    is the fraction of samples the rule classifies right. A rule that
    agrees with no more samples than "always the commoner verdict" (which
    is every case where all samples agree) is ``"none in range"``.
    """
    verdicts = frame["load_balance"].to_numpy(dtype=bool)
    baseline = max(verdicts.mean(), 1.0 - verdicts.mean())
    by_name = {entry.name: entry for entry in FACTORS}
    out = {}
    for name in factors:
        entry = by_name[name]
        values = frame[name].to_numpy()
        rule = _choice_rule(entry, values, verdicts) if entry.distribution == "categorical" else \
            _threshold_rule(values.astype(np.float64), verdicts)
        out[name] = rule if rule is not None and rule["agreement"] > baseline + 1e-12 else "none in range"
    return out


def _threshold_rule(values: np.ndarray, verdicts: np.ndarray) -> dict | None:
    levels = np.unique(values)
    best = None
    for low, high in zip(levels[:-1], levels[1:]):
        threshold = 0.5 * (low + high)
        above = values > threshold
        for side, says in (("above", above), ("below", ~above)):
            agreement = float(np.mean(says == verdicts))
            if best is None or agreement > best["agreement"]:
                best = {"threshold": float(threshold), "load_balance_when": side, "agreement": agreement}
    return best


def _choice_rule(entry, values: np.ndarray, verdicts: np.ndarray) -> dict:
    chosen = [choice for choice in entry.choices if (values == choice).any()
              and verdicts[values == choice].mean() > 0.5]
    says = np.isin(values, chosen)
    return {"load_balance_choices": chosen, "agreement": float(np.mean(says == verdicts))}
