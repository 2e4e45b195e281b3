"""coherence paper --platform: a "today" column beside the study's machine, with the platform's own costs."""
import json

import pandas as pd
import pytest

from analyses import paper
from analyses.cli import main
from coherence.platforms import get_platform

COUNTS = [1, 2, 4]
SIZE = 8
# DB has one 32x32 block at 8x8: its warning about idle processes is expected here
pytestmark = pytest.mark.filterwarnings("ignore:mapping DB")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("trace-cache")


@pytest.fixture(scope="module")
def results(cache):
    """tetra at 8x8: the paper without a platform and with apple-m1's today column."""
    common = dict(size=SIZE, n_processes=COUNTS, scenes=["tetra"], cache_dir=cache, progress=False)
    return paper.reproduce(**common), paper.reproduce(platform="apple-m1", **common)


def test_the_study_s_machine_is_unchanged_by_a_today_column(results):
    """Mutation: drop ``experiment, today = today_of(experiment)`` from reproduce (the study's runs and
    calibration then use the platform's machine)."""
    plain, today = results
    pd.testing.assert_frame_equal(plain.runs, today.runs)
    assert plain.calibration["model"] == today.calibration["model"]
    assert plain.today is None and "platform" not in today.parameters
    assert list(today.table.columns[:len(plain.table.columns)]) == list(plain.table.columns)


def test_today_runs_are_the_platform_s_with_its_own_costs(results, cache):
    """The today runs equal coherence.study on the same trace with the platform's shared levels (default
    interleaving), cost model and 4 CPUs (the study's background load kept). Mutation: ``cost=experiment.cost_model()`` ->
    ``cost=get_cost_model("alpha8400")`` in run_today."""
    from analyses.traces import cached_trace
    from coherence import study
    from coherence.layout import get_layout
    from coherence.shared_run import SharedLevels
    from coherence.simulation import Machine

    _, today = results
    m1 = get_platform("apple-m1")
    scene, trace, _ = cached_trace("tetra", SIZE, cache_dir=cache, progress=False, workload="study1997")
    expected = study(trace, list(paper.DEFAULT_MAPPINGS), COUNTS, hierarchy=SharedLevels(m1.hierarchy),
                     layout=get_layout("alpha1997"), cost=m1.cost, scene=scene, progress=False,
                     machine=Machine(n_cpus=4, background_load=paper.DEFAULT_BACKGROUND)).runs
    runs = today.today["runs"]
    assert (runs["scene"] == "tetra").all()
    pd.testing.assert_frame_equal(runs.drop(columns="scene").reset_index(drop=True), expected)
    row = today.table.iloc[0]
    s1 = expected[(expected["mapping"] == "S") & (expected["n_processes"] == 1)]
    assert row["today_seconds"] == float(s1["real_seconds"].iloc[0])
    verdict = today.today["verdicts"].iloc[0]
    assert row["today_best_mapping"] == verdict["best_mapping"] and row["today_decided_by"] == verdict["decided_by"]
    assert today.today["platform"]["name"] == "apple-m1" and today.today["platform"]["n_cpus"] == 4


def test_today_files_only_with_a_platform(results, tmp_path):
    """Mutation: drop the today.csv line from write_paper."""
    plain, today = results
    without = paper.write_paper(plain, tmp_path / "plain")
    with_today = paper.write_paper(today, tmp_path / "today")
    assert not (without / "today.csv").exists() and "today" not in json.loads((without / "paper.json").read_text())
    assert pd.read_csv(with_today / "today.csv").shape[0] == len(today.today["runs"])
    summary = json.loads((with_today / "paper.json").read_text())
    assert summary["today"]["platform"]["name"] == "apple-m1"
    assert summary["today"]["verdicts"][0]["scene"] == "tetra"
    assert "today_best_mapping" in (with_today / "scenes.csv").read_text()


def test_paper_cli_takes_a_platform(cache, tmp_path, capsys):
    """Mutation: drop the today verdict lines from the paper command's output."""
    argv = ["paper", "--out", str(tmp_path / "out"), "--size", str(SIZE), "--scenes", "tetra",
            "--processes", "1", "2", "--cache", str(cache), "--platform", "apple-m1"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "today, on apple-m1: Tetra at 2 processes:" in captured.out
    assert "today.csv" in captured.err
