"""``coherence simulate`` on a saved trace."""
import json
import signal
import subprocess
import sys

import pandas as pd
import pytest

from analyses.cli import main
from coherence.simulation import Machine
from coherence.studies import study
from trace_factory import random_trace


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    trace = random_trace(width=16, height=8, seed=9)
    folder = tmp_path_factory.mktemp("traces") / "t"
    trace.save(folder)
    return trace, folder


def test_table_json_and_csv_agree_with_study(saved, tmp_path, capsys):
    trace, folder = saved
    csv = tmp_path / "runs.csv"
    assert main(["simulate", str(folder), "--mapping", "R", "--mapping", "DB", "--processes", "2", "4",
                 "--cpus", "2", "--csv", str(csv), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    expected = study(trace, ["R", "DB"], [2, 4], machine=Machine(n_cpus=2), progress=False).runs
    table = pd.read_csv(csv)
    assert [run["speedup_user"] for run in report["runs"]] == pytest.approx(expected["speedup_user"].tolist())
    assert table["L1_hit_rate"].tolist() == pytest.approx(expected["L1_hit_rate"].tolist())
    assert report["parameters"]["machine"]["n_cpus"] == 2
    assert (tmp_path / "runs.csv.meta.json").is_file()
    assert main(["simulate", str(folder), "--mapping", "S", "--processes", "2"]) == 0
    out = capsys.readouterr().out
    assert "speedup_user" in out and "16x8 pixels" in out


def test_errors_are_clear(saved, tmp_path, capsys):
    _, folder = saved
    assert main(["simulate", str(tmp_path / "missing")]) == 2
    assert "no such trace directory" in capsys.readouterr().err
    assert main(["simulate", str(folder), "--mapping", "Q"]) == 2
    assert "unknown mapping 'Q'" in capsys.readouterr().err
    assert main(["simulate", str(folder), "--cpus", "0"]) == 2
    assert "--cpus must be >= 1, got 0" in capsys.readouterr().err
    assert main(["simulate", str(folder), "--csv", str(tmp_path / "no" / "r.csv")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_scheduler_footprint_and_tlb_options_reach_the_machine(saved, capsys):
    trace, folder = saved
    assert main(["simulate", str(folder), "--mapping", "R", "--processes", "3", "--cpus", "2", "--background", "1",
                 "--scheduler", "static", "--placement", "neighbours", "--background-footprint", "4096",
                 "--hierarchy", "alpha21164-dtb", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    machine = Machine(n_cpus=2, scheduler="static", placement="neighbours", background_load=1,
                      background_footprint=4096)
    expected = study(trace, ["R"], [3], hierarchy="alpha21164-dtb", machine=machine, progress=False).runs
    assert report["parameters"]["machine"]["scheduler"] == "static"
    assert report["parameters"]["machine"]["background_footprint"] == 4096
    assert [run["user_cycles_max"] for run in report["runs"]] == expected["user_cycles_max"].tolist()
    assert [run["tlb_misses"] for run in report["runs"]] == expected["tlb_misses"].tolist()
    assert main(["simulate", str(folder), "--placement", "neighbours"]) == 2
    assert "--placement neighbours needs --scheduler static" in capsys.readouterr().err


def run_cli(*arguments, cwd):
    """``coherence ...`` in a subprocess: a segfault fails the test instead of killing pytest."""
    done = subprocess.run([sys.executable, "-m", "analyses", *arguments], capture_output=True, text=True,
                          cwd=cwd, timeout=900)
    assert done.returncode not in (-signal.SIGSEGV, 128 + signal.SIGSEGV), "segfault: " + done.stderr[-2000:]
    return done


def test_more_processes_than_rows_is_a_legal_run(tmp_path):
    trace = random_trace(width=32, height=32, seed=10)
    trace.save(tmp_path / "t")
    done = run_cli("simulate", str(tmp_path / "t"), "--mapping", "S", "--processes", "33", "--json",
                   cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "1 of 33 processes get no pixels" in done.stderr
    run = json.loads(done.stdout)["runs"][-1]
    assert run["n_processes"] == 33 and run["pixels"] == 32 * 32


def test_report_below_its_default_process_count(tmp_path):
    """The report's 16 processes on a 15x15 image: S and R leave a process without rows."""
    done = run_cli("report", "tetra", "--size", "15", "--cache", str(tmp_path / "cache"), "--out",
                   str(tmp_path / "report"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "report" / "summary.json").is_file()
