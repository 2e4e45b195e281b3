"""``coherence render`` end to end (small images)."""
import json

import pytest

from analyses.cli import main
from tracer.trace.access import AccessTrace


def test_render_named_scene_json_png_and_trace(tmp_path, capsys):
    png = tmp_path / "tetra.png"
    trace = tmp_path / "trace"
    status = main(["render", "tetra", "--size", "16", "--png", str(png), "--trace", str(trace), "--json"])
    assert status == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rays"]["primary"] == 256
    assert out["records"] > 0 and out["bytes_per_record"] == 4
    assert png.stat().st_size > 0
    loaded = AccessTrace.load(trace)
    assert loaded.n_records == out["records"]
    assert loaded.totals()["node_visits"] == out["node_visits"]


def test_render_nff_file_table(tmp_path, capsys):
    from scene_factory import random_scene
    from tracer.scenes.nff import write_nff
    path = tmp_path / "mini.nff"
    write_nff(random_scene(n=20, seed=3), path)
    assert main(["render", str(path), "--size", "8", "--kd", "median", "--no-log"]) == 0
    captured = capsys.readouterr()
    assert "primary" in captured.out and "node visits" in captured.out
    assert "rendering" in captured.err


def test_render_errors(capsys, tmp_path):
    assert main(["render", "nosuchscene", "--size", "8"]) == 2
    assert "error" in capsys.readouterr().err
    assert main(["render", "tetra", "--no-log", "--trace", str(tmp_path / "t")]) == 2
    assert "--no-log" in capsys.readouterr().err


def test_render_help_has_examples(capsys):
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    assert "examples:" in capsys.readouterr().out


@pytest.mark.jit_only  # two kd-tree builds of balls (7,381 elements)
def test_render_epsilon_option(capsys):
    from tracer.rendering.render import SPD_EPSILON
    assert main(["render", "balls", "--size", "8", "--no-log", "--epsilon", "spd", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["epsilon"] == SPD_EPSILON
    assert main(["render", "balls", "--size", "8", "--no-log", "--epsilon", "0.002", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["epsilon"] == 0.002
    for bad in ("-1", "0", "inf", "tiny"):
        with pytest.raises(SystemExit):
            main(["render", "balls", "--size", "8", "--epsilon", bad])
        assert "--epsilon" in capsys.readouterr().err
