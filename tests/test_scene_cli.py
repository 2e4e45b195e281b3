"""``coherence scene`` through :func:`analyses.cli.main`."""
from __future__ import annotations

import json

import pytest

from analyses import cli
from tracer.scenes.nff import read_nff
from tracer.scenes.catalog import load


def test_table_shows_counts_lights_depth_and_box(capsys):
    assert cli.main(["scene", "room"]) == 0
    out = capsys.readouterr().out
    assert "scene room: 7786 elements, 3 lights, max depth 4" in out
    assert "total" in out and "7786" in out
    assert "bounding box  min (0, 0, 0)  max (8, 6, 3)" in out
    summary = load("room").summary()
    for kind, count in summary["counts"].items():
        assert any(line.split() == [kind, str(count)] for line in out.splitlines())


def test_json_has_the_same_numbers(capsys):
    assert cli.main(["scene", "balls", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == load("balls").summary()
    assert printed["counts"]["sphere"] == 7381 and printed["max_depth"] == 2


def test_max_depth_and_nff_out(tmp_path, capsys):
    out_path = tmp_path / "shell.nff"
    assert cli.main(["scene", "shell", "--max-depth", "5", "--nff-out", str(out_path),
                     "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["max_depth"] == 5 and printed["nff_out"] == str(out_path)
    written = read_nff(out_path)
    assert written.n_elements == 5761 and written.max_depth == 5
    assert cli.main(["scene", str(out_path)]) == 0
    assert "5761 elements, 1 lights, max depth 5" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["scene", "teapot"], "unknown scene 'teapot': expected one of balls, tetra, shell"),
    (["scene", "missing.nff"], "scene file not found: 'missing.nff'"),
    (["scene", "tetra", "--max-depth", "-2"], "--max-depth must be in [1, 64], got -2"),
])
def test_user_errors_print_one_line_without_traceback(argv, message, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("coherence scene: error: ") and message in err
    assert "Traceback" not in err


def test_malformed_nff_reports_line_and_column(tmp_path, capsys):
    bad = tmp_path / "bad.nff"
    bad.write_text("s 0 0 0 1\np 2 0 0 0 1 0 0\n")
    assert cli.main(["scene", str(bad)]) == 2
    assert f"{bad}:2:3: expected a polygon with at least 3 vertices" in capsys.readouterr().err


def test_help_teaches_with_examples(capsys):
    with pytest.raises(SystemExit) as done:
        cli.main(["scene", "--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "coherence scene room" in out and "--nff-out" in out
    for name in ("balls", "tetra", "shell", "room", "fluid"):
        assert name in out
