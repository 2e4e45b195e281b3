"""coherence robustness: unit coordinates to values, samples inside the documented ranges, Morris and Sobol on a
synthetic model, the flip rule, and a seeded study that gives the same files twice."""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from analyses.robustness import ROBUSTNESS_EXPERIMENT, flip_thresholds, robustness
from analyses.robustness_factors import (FACTORS, LEFT_OUT, factor_value, factor_values, morris_design,
                                         morris_indices, sample_setup, sobol_design, sobol_indices)
from analyses.robustness_output import ROBUSTNESS_FILES, write_robustness
from coherence.unknowns import UNKNOWNS, unknown

NAMES = [entry.name for entry in FACTORS]


def test_categorical_and_integer_coordinates_by_hand():
    """Four choices split [0, 1] in quarters, u = 1 is the last; an integer range 0..8 has nine equal cells.
    Fails if factor_value's ``min(..., count - 1)`` is dropped (u = 1 indexes past the choices) or if the
    integer cell count loses its ``+ 1`` (8 is then only reached at u = 1)."""
    placement = unknown("page_placement")
    assert placement.choices == ("contiguous", "colouring", "bin-hopping", "random")
    expected = {0.0: "contiguous", 0.24: "contiguous", 0.25: "colouring", 0.5: "bin-hopping", 0.74: "bin-hopping",
                0.75: "random", 0.999: "random", 1.0: "random"}
    for u, choice in expected.items():
        assert factor_value(placement, u) == choice
    image = unknown("memory_image")  # three choices: two of Morris's six levels 0, 0.2, ..., 1 on each
    assert [factor_value(image, u) for u in np.linspace(0, 1, 6)] == ["compact", "compact", "alpha1997",
                                                                      "alpha1997", "malloc1997", "malloc1997"]
    tree = unknown("tree_variant")  # five choices: the six levels reach every one
    assert [factor_value(tree, u) for u in np.linspace(0, 1, 6)] == [*tree.choices, tree.choices[-1]]
    load = unknown("background_load")
    assert [factor_value(load, u) for u in (0.0, 0.11, 0.12, 0.5, 0.88, 0.89, 1.0)] == [0, 0, 1, 4, 7, 8, 8]
    with pytest.raises(ValueError, match="page_placement.*\\[0, 1\\]"):
        factor_value(placement, 1.5)


def test_numeric_coordinates_against_their_distributions():
    """log-uniform: u = 1/2 is the geometric mean of the bounds; uniform: the arithmetic mean. Fails if
    factor_value's log-uniform branch is made linear (``low + u * (high - low)``)."""
    latency = unknown("memory_latency")
    assert factor_value(latency, 0.0) == pytest.approx(latency.low)
    assert factor_value(latency, 1.0) == pytest.approx(latency.high)
    assert factor_value(latency, 0.5) == pytest.approx(math.sqrt(latency.low * latency.high))
    bcache = unknown("bcache_latency")
    assert factor_value(bcache, 0.5) == pytest.approx(0.5 * (bcache.low + bcache.high))


def test_every_sample_lies_in_the_documented_ranges_and_reaches_the_objects():
    """Every value of a seeded Morris design lies in its unknown's range, and the sample's Experiment,
    Machine, hierarchy and cost model carry it. Fails if sample_setup drops one replacement (for example
    the ``tlb=tlb`` of the hierarchy, so the DTB miss cost stays at its default)."""
    base = replace(ROBUSTNESS_EXPERIMENT, size=32)
    design = morris_design(NAMES, 6, seed=11)
    assert design.shape == (6 * (len(NAMES) + 1), len(NAMES))
    seen = {name: set() for name in NAMES}
    for row in design:
        values = factor_values(row)
        for entry in FACTORS:
            assert entry.contains(values[entry.name]), (entry.name, values[entry.name])
            seen[entry.name].add(values[entry.name])
        setup = sample_setup(base, values, seed=5)
        experiment, machine = setup.experiment, setup.machine
        hierarchy, cost = experiment.hierarchy_object(), experiment.cost_model()
        assert hierarchy.memory_latency == values["memory_latency"]
        assert hierarchy.levels[2].latency == values["bcache_latency"]
        assert (hierarchy.tlb is not None) == (values["data_tlb"] == "on")
        if hierarchy.tlb is not None:
            assert hierarchy.tlb.miss_cycles == values["dtb_miss_cycles"]
        assert experiment.layout_object().name == values["memory_image"]
        assert machine.page_placement.policy == values["page_placement"]
        assert machine.page_placement.seed == 5 and machine.background_seed == 5
        assert machine.background_load == values["background_load"]
        assert machine.background_footprint == round(values["background_footprint"])
        assert machine.quantum_cycles == values["quantum_cycles"]
        for field, name in (("node_visit", "cost_node_visit"), ("test_sphere", "cost_test_sphere"),
                            ("test_triangle", "cost_test_triangle"), ("light_read", "cost_light_read"),
                            ("ray", "cost_ray"), ("test_root", "square_root_cycles")):
            assert getattr(cost, field) == pytest.approx(values[name]), field
        assert experiment.tree_variant == values["tree_variant"]
        assert (experiment.scene, experiment.size, experiment.workload) == (base.scene, 32, base.workload)
    for row in morris_design(NAMES, 40, seed=11):  # a longer design reaches both ends of every range
        for name, value in factor_values(row).items():
            seen[name].add(value)
    for entry in FACTORS:
        if entry.distribution == "categorical":
            assert seen[entry.name] == set(entry.choices), entry.name
        else:
            assert min(seen[entry.name]) == pytest.approx(entry.low) and max(seen[entry.name]) == pytest.approx(entry.high)
    assert {entry.name for entry in UNKNOWNS} == set(NAMES) | set(LEFT_OUT)


def _one_factor_model(unit: np.ndarray) -> np.ndarray:
    """Only the fourth coordinate matters (a steep nonlinear function of it)."""
    return np.exp(3.0 * unit[:, 3]) + 0.0 * unit.sum(axis=1)


def test_morris_ranks_the_only_factor_that_matters_first():
    """On a synthetic model of the unit design where only one factor matters, its mu* is first and every other
    is zero. Fails if morris_indices reverses the design's columns (``design[:, ::-1]``) before SALib."""
    names = NAMES[:6]
    design = morris_design(names, 10, seed=2)
    indices = morris_indices(names, design, _one_factor_model(design), seed=2)
    ranked = sorted(names, key=lambda name: -indices["mu_star"][name])
    assert ranked[0] == names[3]
    assert all(indices["mu_star"][name] == 0.0 for name in names if name != names[3])


def test_sobol_total_index_of_the_only_factor_that_matters():
    """Sobol over four factors of a model where only one matters: its total index > 0.9, the others' < 0.05.
    Fails if sobol_indices zips the names with reversed results."""
    names = NAMES[:4]
    design = sobol_design(names, 256, seed=4)
    indices = sobol_indices(names, _one_factor_model(design), seed=4)
    assert indices["ST"][names[3]] > 0.9
    assert all(abs(indices["ST"][name]) < 0.05 for name in names[:3])


def test_flip_threshold_on_a_synthetic_verdict():
    """The verdict is "load balance" exactly when memory latency is below 100 cycles: the rule says below, the
    threshold lies between the nearest sampled latencies on each side, and it agrees with every sample; a
    categorical factor names the choices; with one verdict everywhere, none in range. Fails if
    _threshold_rule swaps its ``above`` and ``below`` sides."""
    rng = np.random.default_rng(0)
    latency = rng.uniform(51, 150, 200)
    image = rng.choice(["compact", "alpha1997", "malloc1997"], 200)
    frame = pd.DataFrame({"memory_latency": latency, "memory_image": image, "load_balance": latency < 100})
    flip = flip_thresholds(frame, ["memory_latency", "memory_image"])
    rule = flip["memory_latency"]
    assert rule["load_balance_when"] == "below" and rule["agreement"] == 1.0
    assert latency[latency < 100].max() < rule["threshold"] < latency[latency >= 100].min()
    frame["load_balance"] = frame["memory_image"] == "malloc1997"
    assert flip_thresholds(frame, ["memory_image"])["memory_image"]["load_balance_choices"] == ["malloc1997"]
    frame["load_balance"] = True
    assert flip_thresholds(frame, ["memory_latency", "memory_image"]) == {"memory_latency": "none in range",
                                                                           "memory_image": "none in range"}


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    base = replace(ROBUSTNESS_EXPERIMENT, size=32, cache_dir=str(tmp_path_factory.mktemp("cache")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # DB has fewer blocks than processes at 32x32
        first = robustness(base, scenes=["tetra"], trajectories=2, seed=3, sobol=4)
        second = robustness(base, scenes=["tetra"], trajectories=2, seed=3, sobol=4)
    return first, second, tmp_path_factory.mktemp("out"), base


def test_study_is_reproducible_with_a_seed(small_study):
    """Two studies with one seed give equal tables and byte-identical files. Fails if trajectory_seeds draws
    from an unseeded generator (``np.random.default_rng()``)."""
    first, second, out, _ = small_study
    pd.testing.assert_frame_equal(first.samples, second.samples)
    a = write_robustness(first, out / "a")
    b = write_robustness(second, out / "b")
    for name in ROBUSTNESS_FILES.values():
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_study_outputs_agree_with_the_samples(small_study):
    """n_evaluations counts the samples; the verdict's probability is the fraction of "load balance" rows; a
    positive margin is that verdict; each trajectory shares one seed. Fails if sample_outputs takes the
    smaller of the coherence and dispatch losses (``min``) for the margin."""
    result = small_study[0]
    samples = result.samples[result.samples["design"] == "morris"]
    summary = result.summary["scenes"]["tetra"]
    assert summary["n_evaluations"] == len(samples) == 2 * (len(NAMES) + 1)
    assert summary["p_load_balance"] == pytest.approx(samples["load_balance"].mean())
    assert ((samples["margin"] > 0) == samples["load_balance"]).all()
    losses = samples[[f"coherence_loss_{m}" for m in ("S", "P", "R", "B", "DB")]].max(axis=1)
    imbalance = samples[[f"imbalance_loss_{m}" for m in ("S", "P", "R", "B", "DB")]].max(axis=1)
    assert np.all(samples["margin"] <= imbalance - losses + 1e-12)
    assert samples.groupby("trajectory")["seed"].nunique().eq(1).all()
    assert len(summary["top"]) == 3 and set(summary["flip"]) == set(summary["top"])
    assert summary["b_minus_s"]["p5"] <= summary["b_minus_s"]["p50"] <= summary["b_minus_s"]["p95"]


def test_sobol_samples_vary_the_top_factors_only(small_study):
    """Sobol's samples of a scene vary the top four unknowns by Morris mu* over their ranges and hold every
    other at the middle of its range; the indices table has S1 and ST for those four only. Fails if _sobol
    leaves out ``design[:, columns] = partial`` (every factor held)."""
    result = small_study[0]
    summary = result.summary["scenes"]["tetra"]
    top = summary["sobol"]["factors"]
    assert top == sorted(summary["mu_star"], key=lambda name: -summary["mu_star"][name])[:4]
    sobol = result.samples[result.samples["design"] == "sobol"]
    assert len(sobol) == summary["sobol"]["n_evaluations"] == 4 * (len(top) + 2)
    for entry in FACTORS:
        values = sobol[entry.name]
        if entry.name in top:
            assert values.nunique() > 1, entry.name
        else:
            assert (values == factor_value(entry, 0.5)).all(), entry.name
    indices = result.indices.set_index("factor")
    assert indices["ST"].notna().sum() == 4 and set(indices.index[indices["ST"].notna()]) == set(top)


def test_samples_differing_only_in_costs_share_one_simulation(tmp_path):
    """Three samples: a start with no other users, then the memory latency changed, then the other users'
    count: the second's runs are re-costed from the first's miss counts except DB at 8 processes (its
    hand-outs depend on cycles), and its outputs equal those of a study without the first; the third (a
    change of the machine's load) is simulated but for its one-process runs, which the other users, each on
    a CPU of its own, do not touch (re-costed). Fails if _Replays gives every sample a fresh RunStore
    (nothing is then re-costed)."""
    from analyses.robustness import _Replays, _scene_samples

    base = replace(ROBUSTNESS_EXPERIMENT, size=16, scene="tetra", cache_dir=str(tmp_path))
    start = np.full(len(NAMES), 0.5)
    start[NAMES.index("background_load")] = 0.0
    design = np.array([start, start, start])
    design[1:, NAMES.index("memory_latency")] = 0.9
    design[2, NAMES.index("background_load")] = 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # DB has fewer blocks than processes at 16x16
        rows, paths = _scene_samples(base, design, [5], _Replays(base, None))
        alone, _ = _scene_samples(base, design[1:2], [5], _Replays(base, None))
    # 7 distinct runs a sample: at 16 x 16 (one 64 x 64 field) S, P, R and B at one process replay one stream
    assert paths == {"simulated": 7 + 1 + 5, "re_costed": 6 + 2, "reused": 0}
    for key, value in alone[0].items():
        if isinstance(value, float):
            assert rows[1][key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
        elif key != "sample":
            assert rows[1][key] == value, key


def test_size_comparison_by_hand():
    """Within 10% of the reference value at every one of five points passes; 11% at one point, a zero
    reference (no relative difference) or only four points fails; the check's points spread over the design.
    Fails if compare_sizes divides by the smaller size's value (0.9 against 1.0 is then 11%)."""
    from analyses.robustness_size import compare_sizes, size_check_rows

    reference = {"a": [1.0, -2.0, 0.5, 1.0, 3.0], "b": [1.0] * 5, "c": [0.0, 1, 1, 1, 1], "d": [1.0] * 4}
    small = {"a": [0.9, -2.1, 0.54, 1.05, 3.0], "b": [1.0, 1.0, 1.11, 1.0, 1.0], "c": [0.0, 1, 1, 1, 1],
             "d": [1.0] * 4}
    result = compare_sizes(small, reference, size_used=256)
    assert {name: entry["passed"] for name, entry in result.items()} == {"a": True, "b": False, "c": False,
                                                                         "d": False}
    assert result["a"]["relative_difference"] == pytest.approx([0.1, 0.05, 0.08, 0.05, 0.0])
    assert math.isnan(result["c"]["relative_difference"][0]) and result["a"]["size_used"] == 256
    assert size_check_rows(34).tolist() == [0, 8, 16, 25, 33]
    assert size_check_rows(3).tolist() == [0, 1, 2]


def test_size_check_simulates_its_points_at_both_sizes(small_study):
    """The scene's size check holds five points of the Morris design; its values at half and twice the study's
    size are the one-process B - S and DB - S of a study of that sample (its trajectory's seed, the base's
    tree) at that size. Fails if _size_check runs the reference points at the smaller size."""
    from analyses.robustness import _Replays, _sample_runs, one_process_differences, trajectory_seeds

    result, base = small_study[0], replace(small_study[3], scene="tetra")
    check = result.summary["scenes"]["tetra"]["size_check"]
    assert (check["small_size"], check["reference_size"], check["verdict_size"]) == (16, 64, 32)
    assert len(check["samples"]) == 5 and set(check["quantities"]) == {"b_minus_s", "db_minus_s"}
    design = morris_design(NAMES, 2, seed=3)
    last = check["samples"][-1]
    values = {**factor_values(design[last]), "tree_variant": base.tree_variant}
    seed = trajectory_seeds(3, 2)[last // (len(NAMES) + 1)]
    for size, key in ((16, "small"), (64, "reference")):
        sized = replace(base, size=size, mappings=("S", "B", "DB"), n_processes=(1,))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs = _sample_runs(sized, _Replays(base, None)(base.tree_variant, size), values, seed)
        for name, value in one_process_differences(runs).items():
            assert check["quantities"][name][key][-1] == pytest.approx(value, rel=1e-9), (name, size)


class _CountingBar:
    """Stands for tqdm: records each bar's description, total, whether it is shown and how far it counted."""

    made: list = []

    def __init__(self, iterable=None, *, total=None, desc="", disable=False, **_):
        self.iterable, self.total, self.desc, self.disable, self.n = iterable, total, desc, disable, 0
        _CountingBar.made.append(self)

    def __iter__(self):
        for item in self.iterable:
            self.n += 1
            yield item

    def update(self, n=1):
        self.n += n

    def set_postfix_str(self, *_, **__):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *_):
        return False


def test_progress_bars_count_every_sample_of_each_scene_and_phase(tmp_path, monkeypatch):
    """With progress on, one bar per scene and phase (Morris samples, size check, Sobol samples) counts each of
    its samples once, up to its total. Fails if _size_check's ``bar.update(1)`` is left out (its bar stays at
    0 of 10)."""
    import tqdm.auto

    monkeypatch.setattr(tqdm.auto, "tqdm", _CountingBar)
    _CountingBar.made = []
    base = replace(ROBUSTNESS_EXPERIMENT, size=16, cache_dir=str(tmp_path), progress=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # DB has fewer blocks than processes at 16x16
        robustness(base, scenes=["tetra", "balls"], trajectories=2, seed=1, sobol=2)
    bars = {bar.desc: bar for bar in _CountingBar.made if bar.desc.startswith(("tetra:", "balls:"))}
    morris, sobol = 2 * (len(NAMES) + 1), 2 * (4 + 2)
    expected = {f"{scene}: {phase}": total for scene in ("tetra", "balls")
                for phase, total in (("Morris samples", morris), ("size check at 8 and 32", 10),
                                     ("Sobol samples", sobol))}
    assert {desc: (bar.n, bar.total) for desc, bar in bars.items()} == {d: (t, t) for d, t in expected.items()}
    assert not any(bar.disable for bar in bars.values())


def test_progress_off_prints_nothing_and_bars_change_no_file(tmp_path, capsys):
    """A study with progress off writes nothing to stderr or stdout; with it on the bars go to stderr only,
    and the files are byte-identical. Fails if _samples_bar passes ``disable=False``."""
    base = replace(ROBUSTNESS_EXPERIMENT, size=16, scene="tetra", cache_dir=str(tmp_path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        quiet = robustness(base, scenes=["tetra"], trajectories=2, seed=1, size_check=False)
        printed_quiet = capsys.readouterr()
        shown = robustness(replace(base, progress=True), scenes=["tetra"], trajectories=2, seed=1, size_check=False)
        printed_shown = capsys.readouterr()
    assert printed_quiet.err == "" and printed_quiet.out == ""
    samples = 2 * (len(NAMES) + 1)
    assert "tetra: Morris samples" in printed_shown.err and f"{samples}/{samples}" in printed_shown.err
    assert printed_shown.out == ""
    a, b = write_robustness(quiet, tmp_path / "a"), write_robustness(shown, tmp_path / "b")
    for name in ROBUSTNESS_FILES.values():
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_cli_shows_bars_on_a_terminal_unless_told_not_to(monkeypatch, tmp_path):
    """``coherence robustness`` turns progress on when stderr is a terminal, off with --no-progress or
    when stderr is not a terminal. Fails if run() leaves ROBUSTNESS_EXPERIMENT's progress (False) as is."""
    import sys

    import analyses.robustness
    from analyses.cli import build_parser

    class Stop(Exception):
        pass

    seen = []

    def record(base, **_):
        seen.append(base.progress)
        raise Stop

    class Terminal:
        def __init__(self, tty):
            self.tty = tty

        def isatty(self):
            return self.tty

        def write(self, text):
            return len(text)

        def flush(self):
            pass

    monkeypatch.setattr(analyses.robustness, "robustness", record)
    for tty, extra, expected in ((True, [], True), (True, ["--no-progress"], False), (False, [], False)):
        args = build_parser().parse_args(["robustness", "--scenes", "tetra", "--size", "16", "--cache",
                                          str(tmp_path / "cache"), "--out", str(tmp_path / "out"), *extra])
        monkeypatch.setattr(sys, "stderr", Terminal(tty))
        with pytest.raises(Stop):
            args.func(args)
        monkeypatch.undo()
        monkeypatch.setattr(analyses.robustness, "robustness", record)
        assert seen[-1] is expected
