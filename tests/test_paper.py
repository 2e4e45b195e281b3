"""coherence paper: the study's table verbatim, calibration, verdicts from the run table, files, errors."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analyses import paper
from analyses.verdict import format_percent
from coherence.cli import main

SCENES = ["tetra", "balls"]
COUNTS = [1, 2, 4]
SIZE = 24
FILES = ("paper.csv", "scenes.csv", "paper.json", "speedup_real.png", "speedup_user.png", "index.html")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("trace-cache")


@pytest.fixture(scope="module")
def result(cache):
    return paper.reproduce(size=SIZE, n_processes=COUNTS, scenes=SCENES, cache_dir=cache, progress=False)


@pytest.fixture(scope="module")
def written(tmp_path_factory, cache):
    outs = []
    for index in range(2):
        out = tmp_path_factory.mktemp(f"paper{index}") / "out"
        status = main(["paper", "--out", str(out), "--size", str(SIZE), "--scenes", *SCENES,
                       "--processes", *map(str, COUNTS), "--cache", str(cache)])
        assert status == 0
        outs.append(out)
    return outs


def test_study_table_is_design_md_verbatim():
    design = Path(__file__).resolve().parents[1].parent / "shared" / "DESIGN.md"
    expected = pd.DataFrame({
        "scene": ["balls", "tetra", "shell", "room", "fluid"],
        "elements": [7382, 4096, 5761, 7786, 2899],
        "lights": [3, 1, 1, 3, 2],
        "tests_1e6": [193.0, 7.6, 212.2, 114.4, 29.3],
        "max_depth": [2, 2, 2, 4, 5],
        "sequential_seconds": [345.8, 28.8, 403.0, 365.7, 97.5],
    })
    pd.testing.assert_frame_equal(paper.STUDY_TABLE[list(expected.columns)], expected)
    if design.is_file():  # parse the table in the design notes themselves
        text = design.read_text()
        for row in paper.STUDY_TABLE.itertuples():
            line = next(l for l in text.splitlines() if l.startswith(f"| {row.scene.capitalize()} |"))
            cells = [c.strip() for c in line.strip("|").split("|")]
            assert cells[1] == row.geometry
            assert int(cells[2]) == row.elements and int(cells[3]) == row.lights
            assert float(cells[4]) == row.tests_1e6 and int(cells[5]) == row.max_depth
            assert re.search(rf"{row.scene.capitalize()} {row.sequential_seconds}", text.replace("\n", " "))


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
    assert math.isfinite(cal["rms_relative_error"])
    # held operations keep the alpha8400 defaults, fitted ones are non-negative
    for op, cycles in cal["fixed"].items():
        assert cal["model"][op] == cycles == cal["default"][op]
    assert set(cal["fitted"]) <= set(paper.FIT)
    assert all(cal["model"][op] >= 0 for op in paper.FIT)


def test_runs_cover_every_scene_mapping_count(result):
    runs = result.runs
    assert set(runs["scene"]) == set(SCENES)
    assert len(runs) == len(SCENES) * len(paper.DEFAULT_MAPPINGS) * len(COUNTS)
    one = runs[runs["n_processes"] == 1]
    assert np.allclose(one["speedup_user"], 1.0)
    # background 2 on 8 CPUs: a lone process runs at full speed, so real = user time
    assert np.allclose(one["speedup_real"], 1.0)


def test_verdict_numbers_come_from_the_run_table(result):
    n = result.parameters["verdict_n_processes"]
    assert n == max(COUNTS)
    runs = result.runs[result.runs["n_processes"] == n]
    assert list(result.verdicts["scene"]) == SCENES
    for row in result.verdict_numbers.itertuples():
        run = runs[(runs["scene"] == row.scene) & (runs["mapping"] == row.mapping)].iloc[0]
        if row.metric.startswith("speedup"):
            assert row.value == float(f"{run[row.metric]:.2f}")
        else:
            column = "imbalance_loss" if row.metric.startswith("imbalance") else "coherence_loss"
            value = float(run[column])
            assert (value < 0) == row.metric.endswith("gain_pct")
            assert row.value == float(format_percent(abs(value)))
            assert row.value == pytest.approx(100 * abs(value), abs=0.051)
    for verdict in result.verdicts.itertuples():
        rows = runs[runs["scene"] == verdict.scene].set_index("mapping")
        assert verdict.best_mapping == rows["speedup_user"].idxmax()
        assert verdict.max_imbalance_loss == rows["imbalance_loss"].max()
        assert verdict.max_coherence_loss == rows["coherence_loss"].max()
        expected = "load balance" if verdict.max_imbalance_loss >= verdict.max_coherence_loss else "coherence"
        assert verdict.decided_by == expected
        assert f"{expected} decided" in verdict.text
        quoted = result.verdict_numbers[result.verdict_numbers["scene"] == verdict.scene]
        # every number in the text is one of the quoted numbers
        for number in re.findall(r"\d+\.\d+|\d+(?=%)", verdict.text.split(": ", 1)[1]):
            assert any(math.isclose(float(number), v) for v in quoted["value"]), number


def test_files_written_and_deterministic(written):
    first, second = written
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
    assert len(summary["verdicts"]) == len(SCENES)
    page = (first / "index.html").read_text()
    assert page.count("data:image/png;base64,") == 2
    assert "http://" not in page and "https://" not in page
    assert (first / "speedup_real.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(first.glob(".*.tmp"))


@pytest.mark.parametrize("argv, message", [
    (["--scenes", "nosuch"], "unknown scene"),
    (["--processes", "0", "2"], "process counts"),
    (["--size", "0"], "--size"),
    (["--background", "-1"], "--background"),
    (["--mappings", "zigzag"], "zigzag"),
])
def test_errors_before_work(tmp_path, capsys, argv, message):
    status = main(["paper", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), *argv])
    assert status == 2
    assert message in capsys.readouterr().err
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
    with pytest.raises(ValueError, match="process counts"):
        paper.reproduce(size=SIZE, n_processes=[2, -1], cache_dir=tmp_path)
    assert not list(tmp_path.iterdir())


def test_relative_weighting_beats_absolute_on_relative_error(result, cache):
    absolute = paper.reproduce(size=SIZE, n_processes=[1], scenes=["tetra", "balls", "room"], cache_dir=cache,
                               progress=False, weighting="absolute")
    relative = paper.reproduce(size=SIZE, n_processes=[1], scenes=["tetra", "balls", "room"], cache_dir=cache,
                               progress=False)
    assert relative.calibration["weighting"] == "relative"
    assert relative.calibration["rms_relative_error"] <= absolute.calibration["rms_relative_error"] + 1e-9
    with pytest.raises(ValueError, match="weighting"):
        paper.reproduce(size=SIZE, scenes=["tetra"], cache_dir=cache, weighting="median")
