"""What-if studies: grids, configuration of points, local pool vs Dask, CLI."""
import json

import numpy as np

import pandas as pd
import pytest

from analyses.whatif import WhatIf, configure, load_study_file, parse_grid_flag, parse_value, run_whatif
from analyses.cli import main


@pytest.fixture
def small(tmp_path):
    study = WhatIf.of("t", {"memory_latency": [40, 640], "L1.size": [4096, 8192]}, scene="tetra", size=24,
                      mappings=("S", "R"), n_processes=4)
    return study, tmp_path / "cache"


def test_values_and_flags():
    assert parse_value("4MB") == 4 * 1024**2 and parse_value("96KB") == 98304 and parse_value("full") == "full"
    assert parse_value("0.5") == 0.5 and parse_value("80") == 80
    assert parse_grid_flag("L3.size=1MB,4MB") == ("L3.size", [1048576, 4194304])
    with pytest.raises(ValueError, match="unknown what-if parameter 'L3.colour'"):
        parse_grid_flag("L3.colour=1")
    with pytest.raises(ValueError, match="expected NAME=VALUE"):
        parse_grid_flag("memory_latency")


def test_configure_changes_only_what_the_point_says(small):
    study, _ = small
    hierarchy, layout, cost, machine, n = configure(study, {"memory_latency": 640, "L1.size": 4096,
                                                            "compute_scale": 0.5})
    assert hierarchy.memory_latency == 640 and hierarchy.levels[0].size == 4096
    assert hierarchy.levels[1].size == 96 * 1024 and n == 4 and layout.name == "compact"
    assert cost.test_sphere == pytest.approx(150.0)
    with pytest.raises(ValueError, match="L1"):
        WhatIf(grid={"L1.size": [1000]})  # not a multiple of line size x ways
    with pytest.raises(ValueError, match="levels"):
        WhatIf(grid={"L9.size": [4096]})


def test_local_pool_serial_and_dask_agree(small):
    study, cache = small
    serial = run_whatif(study, cache_dir=cache, n_jobs=1, progress=False)
    pooled = run_whatif(study, cache_dir=cache, n_jobs=2, progress=False)
    pd.testing.assert_frame_equal(serial, pooled)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        on_dask = run_whatif(study, cache_dir=cache, dask=client, progress=False)
    pd.testing.assert_frame_equal(serial, on_dask)
    assert len(serial) == 4 * 2 and set(serial["verdict"]) <= {"balance", "coherence"}
    # More memory latency, more coherence loss, for the same mapping and L1.
    by_point = serial.set_index(["memory_latency", "L1.size", "mapping"])["coherence_loss"]
    assert by_point[(640, 4096, "S")] >= by_point[(40, 4096, "S")]


def test_study_file_and_cli(tmp_path, capsys):
    """A study file run from the command line writes exactly the files ``whatif_files``
    names, each CSV with its sidecar. Fails if ``WHATIF_FILES["lru"]`` loses its ``-lru``."""
    from analyses.whatif_output import whatif_files
    from coherence.provenance import meta_path

    path = tmp_path / "study.toml"
    path.write_text('scene = "tetra"\nsize = 16\nmappings = ["R"]\nn_processes = 2\n'
                    '[grid]\n"L3.size" = ["256KB", "4MB"]\n')
    study = load_study_file(path)
    assert study.grid == {"L3.size": [262144, 4194304]}
    out = tmp_path / "out"
    assert main(["whatif", "--file", str(path), "--out", str(out), "--cache", str(tmp_path / "c"),
                 "--jobs", "1"]) == 0
    files = whatif_files("custom")
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [*files.values(), meta_path(files["table"]).name, meta_path(files["lru"]).name])
    long = pd.read_csv(out / "whatif-custom.csv")
    assert set(long.columns) == {"L3.size", "mapping", "n_processes", "metric", "value"}
    assert {"coherence_loss", "imbalance_loss", "L1_hit_rate"} <= set(long["metric"])
    assert json.loads((out / "whatif-custom.csv.meta.json").read_text())["parameters"]["scene"] == "tetra"
    assert (out / "whatif-custom.png").stat().st_size > 1000
    lru = pd.read_csv(out / "whatif-custom-lru.csv")
    assert sorted(lru["size"].unique()) == [262144, 4194304] and (lru["misses"] <= lru["accesses"]).all()
    first = (out / "whatif-custom.csv").read_bytes()
    assert main(["whatif", "--file", str(path), "--out", str(out), "--cache", str(tmp_path / "c"),
                 "--jobs", "2"]) == 0
    assert (out / "whatif-custom.csv").read_bytes() == first  # same inputs, same bytes
    bad = tmp_path / "bad.toml"
    bad.write_text('colour = "red"\n[grid]\nmemory_latency = [1]\n')
    assert main(["whatif", "--file", str(bad)]) == 2
    assert "unknown keys ['colour']" in capsys.readouterr().err
    assert main(["whatif", "nonsense"]) == 2
    assert "unknown study 'nonsense'" in capsys.readouterr().err
    assert main(["whatif", "latency", "--mappings", "XX", "--out", str(out)]) == 2
    assert "unknown mapping 'XX'" in capsys.readouterr().err
    assert main(["whatif", "--list"]) == 0
    assert "scene-size" in capsys.readouterr().out


def test_exact_lru_curves_equal_a_fully_associative_simulation(small):
    from cachesim import CacheLevel, Hierarchy, simulate
    from analyses.whatif import exact_lru_curves
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.studies import place_layout
    from analyses.traces import cached_trace

    study, cache = small
    curves = exact_lru_curves(study, cache_dir=cache)
    assert set(curves["size"]) == {4096, 8192} and set(curves["level"]) == {"L1"}
    scene, trace, _ = cached_trace("tetra", 24, cache_dir=cache, progress=False)
    placed = place_layout(get_layout("compact"), trace, scene)
    distribution = get_mapping("R").build(24, 24, 4)
    for size in (4096, 8192):
        misses = 0
        for process in range(4):
            pixels = distribution.process_pixels(process)
            records = np.concatenate([trace.records[trace.pixel_offsets[p]:trace.pixel_offsets[p + 1]]
                                      for p in pixels])
            full = Hierarchy((CacheLevel("L1", size, 32, "full", "lru"),))
            misses += int(simulate(placed.addresses(records, 32), full).misses[0])
        row = curves.query("mapping == 'R' and size == @size")
        assert row["misses"].item() == misses


def test_exact_lru_curves_none_when_the_memory_image_varies(small):
    """One curve cannot stand for several memory images: a grid over ``memory_image`` or ``layout`` (with a
    level size) gets no curves. Fails if whatif_lru stops checking those keys."""
    from dataclasses import replace

    from analyses.whatif import exact_lru_curves

    study, cache = small
    for key, values in (("memory_image", ("compact", "malloc1997")), ("layout", ("compact", "alpha1997"))):
        varied = replace(study, grid={**study.grid, key: values})
        assert exact_lru_curves(varied, cache_dir=cache) is None
