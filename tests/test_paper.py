"""coherence paper: the study's table verbatim, calibration, verdicts from the run table, files, errors."""
from __future__ import annotations

import gc
import json
import math
import os
import re
import threading
import weakref

import numpy as np
import pandas as pd
import pytest

from analyses import paper
from analyses import verdict as verdict_module
from analyses.verdict import format_percent
from analyses.cli import main
from analyses.paper_output import PAPER_FILES
from coherence.calibration import (FITS, OPERATION_FLOPS, PRIOR_UNKNOWNS, STUDY1997_COSTS, STUDY1997_PRIOR_COSTS,
                                   STUDY_BOUNDS)
from coherence.unknowns import unknown
from coherence.cost import OPERATIONS

SCENES = ["tetra", "balls"]
COUNTS = [1, 2, 4]
# As plain Python (the no-JIT coverage run) the study-era traces replay slowly: a smaller image
# keeps every line covered (DB then has one block, which the tests allow).
SIZE = 8 if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0") else 24
FILES = tuple(PAPER_FILES.values())


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("trace-cache")


@pytest.fixture(scope="module")
def result(cache):
    return paper.reproduce(size=SIZE, n_processes=COUNTS, scenes=SCENES, cache_dir=cache, progress=False)


@pytest.fixture(scope="module")
def written(tmp_path_factory, cache):
    """The paper written twice: locally, then with its runs on a Dask cluster (the same bytes, checked below)."""
    distributed = pytest.importorskip("distributed")
    outs = []
    for index in range(2):
        out = tmp_path_factory.mktemp(f"paper{index}") / "out"
        argv = ["paper", "--out", str(out), "--size", str(SIZE), "--scenes", *SCENES,
                "--processes", *map(str, COUNTS), "--cache", str(cache)]
        if index == 0:
            assert main(argv) == 0
        else:
            with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                          dashboard_address=None) as cluster:
                assert main([*argv, "--dask", cluster.scheduler_address]) == 0
                assert "simulate_stored" in cluster.scheduler.task_prefixes  # the runs went to the cluster
        outs.append(out)
    return outs


def test_study_table_holds_the_published_figures():
    """The study's scene table as published (Havran & Zara), typed here from the paper, against
    its one home in the code. Fails when one figure changes, e.g. Shell's 403.0 s -> 430.0 s."""
    expected = pd.DataFrame({
        "scene": ["balls", "tetra", "shell", "room", "fluid"],
        "geometry": ["spheres (SPD sphereflake)", "triangles (SPD tetra)", "spheres (SPD shells)",
                     "polygon meshes (CAAD interior)", "spheres (fluid-dynamics visualisation)"],
        "elements": [7382, 4096, 5761, 7786, 2899],
        "lights": [3, 1, 1, 3, 2],
        "tests_1e6": [193.0, 7.6, 212.2, 114.4, 29.3],
        "max_depth": [2, 2, 2, 4, 5],
        "sequential_seconds": [345.8, 28.8, 403.0, 365.7, 97.5],
    })
    pd.testing.assert_frame_equal(paper.STUDY_TABLE[list(expected.columns)], expected)


def test_side_by_side_table(result):
    table = result.table.set_index("scene")
    assert list(table.index) == SCENES
    study = paper.STUDY_TABLE.set_index("scene")
    for scene in SCENES:
        assert table.loc[scene, "study_elements"] == study.loc[scene, "elements"]
        assert table.loc[scene, "study_seconds"] == study.loc[scene, "sequential_seconds"]
        assert table.loc[scene, "study_tests_1e6"] == study.loc[scene, "tests_1e6"]
        assert table.loc[scene, "our_elements"] == study.loc[scene, "elements"]
        assert table.loc[scene, "our_lights"] == study.loc[scene, "lights"]
        assert table.loc[scene, "our_max_depth"] == study.loc[scene, "max_depth"]
        assert table.loc[scene, "our_rays"] >= SIZE * SIZE
        assert table.loc[scene, "our_tests_per_ray"] > 0
        # the calibrated sequential S time is what the study's run simulates
        assert table.loc[scene, "simulated_seconds"] == pytest.approx(table.loc[scene, "fitted_seconds"], rel=1e-9)


def test_calibration_residuals_reported(result):
    cal = result.calibration
    residuals = cal["residuals"].set_index("scene")
    assert list(residuals.index) == SCENES
    scale = (SIZE / 512) ** 2
    for scene in SCENES:
        study = paper.STUDY_TABLE.set_index("scene").loc[scene, "sequential_seconds"]
        assert residuals.loc[scene, "target_seconds"] == pytest.approx(study * scale)
        assert residuals.loc[scene, "residual_seconds"] == pytest.approx(
            residuals.loc[scene, "fitted_seconds"] - residuals.loc[scene, "target_seconds"])
    assert math.isfinite(cal["rms_relative_error"]) and math.isfinite(cal["left_out_rms_relative_error"])
    assert np.isfinite(residuals["left_out_seconds"]).all()
    assert ((residuals["memory_share"] > 0) & (residuals["memory_share"] < 1)).all()
    # three costs, each inside its prior (the default fit), and so is every tied cost that has a prior
    assert len(cal["fitted"]) == 3
    assert cal["structure"]["name"] == STUDY1997_PRIOR_COSTS.name
    for cost in cal["fitted"]:
        assert cost["low"] - 1e-9 <= cost["cycles"] <= cost["high"] + 1e-9
    assert all(cal["model"][op] > 0 for op in OPERATIONS)
    for operation, name in PRIOR_UNKNOWNS.items():
        assert unknown(name).low - 1e-9 <= cal["model"][operation] <= unknown(name).high + 1e-9, operation
    # operations without a prior keep their flop ratios to the sphere test
    assert cal["model"]["test_polygon"] / cal["model"]["test_sphere"] == pytest.approx(
        OPERATION_FLOPS["test_polygon"] / OPERATION_FLOPS["test_sphere"])


def test_unexplained_time_and_bound_flags_in_every_table(result):
    """Per scene the time the model does not explain is the target minus the fitted time, in the residuals
    and the scene table, and every fitted cost's at-bound flag is on every scene's row, equal to the fitted
    list's. Fails when side_by_side copies residual_seconds (fitted minus target) as unexplained_seconds."""
    cal = result.calibration
    residuals = cal["residuals"].set_index("scene")
    table = result.table.set_index("scene")
    scale = (SIZE / 512) ** 2
    for scene in SCENES:
        unexplained = residuals.loc[scene, "target_seconds"] - residuals.loc[scene, "fitted_seconds"]
        assert residuals.loc[scene, "unexplained_seconds"] == pytest.approx(unexplained, rel=1e-9, abs=1e-12)
        assert table.loc[scene, "unexplained_seconds"] == pytest.approx(unexplained, rel=1e-9, abs=1e-12)
        assert table.loc[scene, "unexplained_share"] == pytest.approx(
            unexplained / residuals.loc[scene, "target_seconds"], rel=1e-9, abs=1e-12)
        assert residuals.loc[scene, "unexplained_seconds_at_512"] == pytest.approx(unexplained / scale, rel=1e-9)
    for cost in cal["fitted"]:
        at = min(abs(cost["cycles"] - cost["low"]), abs(cost["cycles"] - cost["high"])) <= 1e-6 * cost["cycles"]
        assert cost["at_bound"] == at
        assert (table[f"{cost['name']}_at_bound"] == at).all()
        assert (residuals[f"{cost['name']}_at_bound"] == at).all()
        assert (cost["name"] in cal["at_bound"]) == at


def test_study_bounds_fit_is_kept_for_comparison(result):
    """The same measurements fitted with --fit study-bounds: the old structure, its 5-5000 bounds and flop-ratio
    ties, and the command's choices are the names of coherence.calibration.FITS. Fails when FITS maps
    'study-bounds' to the prior structure."""
    from analyses.commands.paper import FIT_CHOICES

    assert FIT_CHOICES == tuple(FITS)
    measurements = result.calibration["measurements"].drop(columns="seconds").to_dict("records")
    _, old = paper._calibrate(measurements, FITS["study-bounds"], result.parameters["clock_hz"], SIZE)
    assert old["structure"]["name"] == STUDY1997_COSTS.name
    assert all((cost["low"], cost["high"]) == STUDY_BOUNDS for cost in old["fitted"])
    assert old["model"]["test_triangle"] / old["model"]["test_sphere"] == pytest.approx(
        OPERATION_FLOPS["test_triangle"] / OPERATION_FLOPS["test_sphere"])


def test_sequential_predictions_of_every_mapping(result):
    predictions = result.predictions.set_index("scene")
    fitted = result.calibration["residuals"].set_index("scene")["fitted_seconds_at_512"]
    for scene in SCENES:
        # S's one-process time is the fitted one; the others are predicted beside it
        assert predictions.loc[scene, "S_seconds"] == pytest.approx(fitted[scene], rel=1e-9)
        for mapping in ("P", "R", "B", "DB"):
            gap = predictions.loc[scene, f"{mapping}_minus_S_percent"]
            assert gap == pytest.approx(100 * (predictions.loc[scene, f"{mapping}_seconds"]
                                               / predictions.loc[scene, "S_seconds"] - 1))


def test_runs_cover_every_scene_mapping_count(result):
    runs = result.runs
    assert set(runs["scene"]) == set(SCENES)
    assert len(runs) == len(SCENES) * len(paper.DEFAULT_MAPPINGS) * len(COUNTS)
    one = runs[runs["n_processes"] == 1]
    assert np.allclose(one["speedup_user"], 1.0)
    # background 2 on 8 CPUs: a lone process runs at full speed, so real = user time
    assert np.allclose(one["speedup_real"], 1.0)


#: Quoted metric -> run-table column it rounds (percentages of the absolute value).
SOURCES = {"speedup_user": "speedup_user", "speedup_real": "speedup_real",
           "imbalance_loss_pct": "imbalance_loss", "imbalance_gain_pct": "imbalance_loss",
           "coherence_loss_pct": "coherence_loss", "coherence_gain_pct": "coherence_loss",
           "dispatch_loss_pct": "dispatch_loss", "dispatch_gain_pct": "dispatch_loss",
           "dispatch_share_pct": "dispatch_share"}


def check_verdicts(verdicts, numbers, runs, n):
    """The paper's verdicts are the report's verdict per scene, and every printed number is quoted and sourced."""
    at = runs[runs["n_processes"] == n]
    assert list(verdicts["scene"]) == list(dict.fromkeys(runs["scene"]))
    assert not numbers.duplicated(["scene", "mapping", "metric"]).any()
    for row in numbers.itertuples():
        run = at[(at["scene"] == row.scene) & (at["mapping"] == row.mapping)].iloc[0]
        assert row.n_processes == n
        value = float(run[SOURCES[row.metric]])
        if row.metric.startswith("speedup"):
            assert row.value == float(verdict_module.format_speedup(value))
        else:
            assert (value < 0) == row.metric.endswith("gain_pct"), row
            assert row.value == float(format_percent(abs(value)))
            assert row.value == pytest.approx(100 * abs(value), abs=0.051)
    for row in verdicts.itertuples():
        rows = runs[runs["scene"] == row.scene]
        report = verdict_module.verdict(rows, n, order=paper.DEFAULT_MAPPINGS)  # what `coherence report` says
        assert row.decided_by == report.decided_by
        assert row.headline == report.headline
        assert row.text.endswith(report.text)
        scene = at[at["scene"] == row.scene].set_index("mapping")
        assert row.best_mapping == scene["speedup_user"].idxmax()
        assert row.best_mapping_real == scene["speedup_real"].idxmax()
        for column, _, short in verdict_module.LOSSES:
            assert getattr(row, f"max_{short}_loss") == scene[column].max()
            assert getattr(row, f"max_{short}_mapping") == scene[column].idxmax()
        quoted = set(numbers.loc[numbers["scene"] == row.scene, "value"]) | {float(n)}
        printed = re.findall(r"\d+(?:\.\d+)?", row.text)
        assert len(printed) >= 6
        for number in printed:  # every number of the text, prefix included, is quoted
            assert float(number) in quoted, (row.scene, number)


def test_verdict_numbers_come_from_the_run_table(result):
    n = result.parameters["verdict_n_processes"]
    assert n == max(COUNTS)
    assert list(result.verdicts["scene"]) == SCENES
    check_verdicts(result.verdicts, result.verdict_numbers, result.runs, n)


def _runs(losses):
    """Hand-built run table at 8 processes: scene -> mapping -> (imbalance, coherence, dispatch, share)."""
    rows = []
    for scene, mappings in losses.items():
        for index, (mapping, (imbalance, coherence, dispatch, share)) in enumerate(mappings.items()):
            user = 8 * (1 - imbalance) * (1 - coherence) * (1 - dispatch)
            rows.append({"scene": scene, "mapping": mapping, "n_processes": 8, "speedup_user": user,
                         "speedup_real": user * 0.8 - 0.01 * index, "imbalance_loss": imbalance,
                         "coherence_loss": coherence, "dispatch_loss": dispatch, "dispatch_share": share})
    return pd.DataFrame(rows)


def test_dispatch_decides_in_report_and_paper():
    runs = _runs({
        "balls": {"S": (0.05, 0.002, 0.0, 0.0), "DB": (0.01, -0.003, 0.30, 0.25)},
        "tetra": {"S": (0.40, 0.01, 0.0, 0.0), "DB": (0.02, 0.004, 0.12, 0.1)},
        "room": {"S": (0.02, 0.15, 0.0, 0.0), "DB": (0.01, 0.003, 0.07, 0.05)},
    })
    report = verdict_module.verdict(runs[runs["scene"] == "balls"], 8)
    assert report.decided_by == "dispatch overhead"
    assert report.headline.startswith("Dispatch overhead, not load balance, decided the speed-up at 8 processes: "
                                      "dispatch cost up to 30.0% (DB), imbalance at most 5.0% (S)")
    assert report.worst["dispatch_loss"] == ("DB", 0.30)
    verdicts, numbers = paper.scene_verdicts(runs, 8)
    decided = dict(zip(verdicts["scene"], verdicts["decided_by"]))
    assert decided == {"balls": "dispatch overhead", "tetra": "load balance", "room": "coherence"}
    balls = verdicts.set_index("scene").loc["balls"]
    assert "Dispatch overhead, not load balance, decided" in balls["text"]
    assert "DB reaches a user speed-up of 5.56 and loses 1.0% to imbalance, gains 0.3% from coherence and " \
           "loses 30.0% to dispatch; hand-outs take 25.0% of its work" in balls["text"]
    assert balls["max_dispatch_loss"] == 0.30 and balls["max_dispatch_mapping"] == "DB"
    assert verdicts.set_index("scene").loc["tetra", "text"].count("Load balance, not dispatch overhead") == 1
    check_verdicts(verdicts, numbers, runs, 8)
    with pytest.raises(ValueError, match="room: no runs with n_processes == 16"):
        paper.scene_verdicts(runs[runs["scene"] == "room"], 16)


def test_at_most_two_traces_mapped_at_once(cache, monkeypatch):
    """A trace's pages stay resident while it is mapped: reproduce may run one scene's sequential run while
    it loads the next, but must drop every other trace before mapping another."""
    import coherence
    from analyses import traces

    seen = []
    lock = threading.Lock()

    def live(current=None):
        gc.collect()
        return [name for name, ref in seen if ref() is not None and ref() is not current]

    def cached_trace(name, *args, **kwargs):
        with lock:
            assert len(live()) <= 1, f"{name} loaded while {live()} still mapped"
        return real_cached_trace(name, *args, **kwargs)

    def study(trace, *args, **kwargs):
        with lock:
            assert len(live(trace.records)) <= 1, f"{live(trace.records)} still mapped"
            seen.append((kwargs["scene"].name, weakref.ref(trace.records)))
        return real_study(trace, *args, **kwargs)

    real_cached_trace, real_study = traces.cached_trace, coherence.study
    monkeypatch.setattr(traces, "cached_trace", cached_trace)
    monkeypatch.setattr(coherence, "study", study)
    result = paper.reproduce(size=SIZE, n_processes=[2], scenes=SCENES, cache_dir=cache, progress=False)
    assert len(seen) == 2 * len(SCENES)  # a sequential run and a full study per scene
    assert not live()
    assert list(result.table["scene"]) == SCENES


def test_files_written_and_deterministic(written):
    """Exactly the files ``PAPER_FILES`` names, the same bytes twice. Fails if
    ``write_paper`` writes ``paper.json`` under a name of its own."""
    first, second = written
    assert sorted(path.name for path in first.iterdir()) == sorted(FILES)
    for name in FILES:
        assert (first / name).is_file(), name
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    runs = pd.read_csv(first / "paper.csv")
    assert {"scene", "mapping", "n_processes", "speedup_user", "speedup_real", "imbalance_loss",
            "coherence_loss"} <= set(runs.columns)
    summary = json.loads((first / "paper.json").read_text())
    assert summary["parameters"]["scenes"] == SCENES
    assert summary["parameters"]["background_load"] == paper.DEFAULT_BACKGROUND
    assert "versions" in summary and "residuals" in summary["calibration"]
    # the unexplained time and the bound flags reach the files and the page
    scenes = pd.read_csv(first / "scenes.csv")
    assert {"unexplained_seconds", "test_at_bound", "ray_at_bound", "node_visit_at_bound"} <= set(scenes.columns)
    assert [c["name"] for c in summary["calibration"]["fitted"] if c["at_bound"]] == summary["calibration"]["at_bound"]
    assert all("unexplained_seconds" in row for row in summary["calibration"]["residuals"])
    assert len(summary["verdicts"]) == len(SCENES)
    page = (first / "index.html").read_text()
    assert ("At a bound: " in page) == bool(summary["calibration"]["at_bound"])
    assert ("No fitted cost is at a bound." in page) != bool(summary["calibration"]["at_bound"])
    assert page.count("data:image/png;base64,") == 2
    assert "http://" not in page and "https://" not in page
    assert (first / "speedup_real.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(first.glob(".*.tmp"))


@pytest.mark.parametrize("argv, message", [
    (["--scenes", "nosuch"], "unknown scene"),
    (["--processes", "0", "2"], "--processes must be >= 1"),
    (["--size", "0"], "--size"),
    (["--background", "-1"], "--background"),
    (["--mappings", "zigzag"], "zigzag"),
    (["--memory-budget", "1"], "--memory-budget must be at least"),
])
def test_errors_before_work(tmp_path, capsys, argv, message):
    status = main(["paper", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), *argv])
    assert status == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()


def test_fit_must_be_one_of_the_fits(tmp_path, capsys):
    """--fit takes only the names of coherence.calibration.FITS. Fails when FIT_CHOICES is dropped from the
    option (any name accepted, and FITS[name] fails after the traces are rendered)."""
    with pytest.raises(SystemExit) as stopped:
        main(["paper", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), "--fit", "loose"])
    assert stopped.value.code == 2
    assert "invalid choice: 'loose'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()


def test_output_path_is_a_file(tmp_path, capsys):
    target = tmp_path / "taken"
    target.write_text("x")
    status = main(["paper", "--out", str(target), "--cache", str(tmp_path / "cache"), "--scenes", "tetra"])
    assert status == 2
    assert "not a folder" in capsys.readouterr().err
    assert not (tmp_path / "cache").exists()


def test_api_validates_before_rendering(tmp_path):
    with pytest.raises(ValueError, match="unknown scene"):
        paper.reproduce(size=SIZE, scenes=["balls", "teapot"], cache_dir=tmp_path)
    with pytest.raises(ValueError, match="n_processes"):
        paper.reproduce(size=SIZE, n_processes=[2, -1], cache_dir=tmp_path)
    assert not list(tmp_path.iterdir())


def test_costs_must_be_a_structure(cache):
    with pytest.raises(ValueError, match="CostStructure"):
        paper.reproduce(size=SIZE, scenes=["tetra"], cache_dir=cache, costs={"ray": 1.0})


def test_crossover_study_in_the_paper(cache, tmp_path):
    result = paper.reproduce(size=SIZE, n_processes=[1, 4], scenes=["tetra"], cache_dir=cache, progress=False,
                             crossover=True)
    crossing = result.crossover
    assert set(crossing["mapping"]) == {"S", "P", "R"} and set(crossing["scene"]) == {"tetra"}
    assert (crossing["n_processes"] == 4).all() and len(crossing) == 4 * 4 * 3
    # the (1, 1) point is the paper's own run at 4 processes
    own = result.runs[(result.runs["n_processes"] == 4)].set_index("mapping")
    first = crossing[(crossing["record_scale"] == 1) & (crossing["latency_scale"] == 1)].set_index("mapping")
    for mapping in ("S", "P", "R"):
        assert first.loc[mapping, "coherence_loss"] == pytest.approx(own.loc[mapping, "coherence_loss"], rel=1e-12)
    out = paper.write_paper(result, tmp_path / "out")
    assert (out / "crossover.csv").is_file() and (out / "crossover.png").is_file()
    summary = json.loads((out / "paper.json").read_text())
    assert {row["mapping"] for row in summary["crossover_boundary"]} == {"P", "R"}
    assert "When would coherence have won?" in (out / "index.html").read_text()
