"""`coherence report`: files, self-containment, determinism, verdict provenance, trace cache, user errors."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

import tracer.rendering.render
from analyses import traces
from analyses.experiment import Experiment
from analyses.report import MISS_MAP_FILES, REPORT_FILES, RESULT_COLUMNS, SECTIONS, build_report
from analyses.verdict import format_percent, verdict
from analyses.cli import main

SIZE = "32"
ARGS = ["--size", SIZE, "--processes", "2", "8", "--mappings", "S", "P", "B", "DB"]


def _no_render(*args, **kwargs):
    raise AssertionError("render() was called although the trace should come from the cache")


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """The same report written twice; the second run must not render."""
    root = tmp_path_factory.mktemp("report")
    cache = root / "cache"
    first, second = root / "first", root / "second"
    assert main(["report", "balls", *ARGS, "--out", str(first), "--cache", str(cache)]) == 0
    patch = pytest.MonkeyPatch()
    patch.setattr(tracer.rendering.render, "render", _no_render)
    try:
        assert main(["report", "balls", *ARGS, "--out", str(second), "--cache", str(cache)]) == 0
    finally:
        patch.undo()
    return first, second


def test_writes_its_files(reports):
    """Exactly the files ``REPORT_FILES`` and ``MISS_MAP_FILES`` name, none empty, no temporaries
    left. Fails if ``write_report`` writes ``summary.json`` under a name of its own."""
    first, _ = reports
    assert sorted(path.name for path in first.iterdir()) == sorted([*REPORT_FILES.values(), *MISS_MAP_FILES])
    for name in (*REPORT_FILES.values(), *MISS_MAP_FILES):
        assert (first / name).stat().st_size > 0


def test_html_is_self_contained(reports):
    page = (reports[0] / "index.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    for forbidden in ("http://", "https://", 'src="file', "<link", "<script"):
        assert forbidden not in page
    sources = re.findall(r'src="([^"]*)"', page)
    assert len(sources) >= 9 and all(s.startswith("data:image/png;base64,") for s in sources)
    for heading in ("Verdict", "The scene", "Miss-ratio curves", "Cost per pixel", "Misses per pixel",
                    "Efficiency decomposition"):
        assert heading in page


def test_outputs_are_deterministic(reports):
    first, second = reports
    for name in (*REPORT_FILES.values(), *MISS_MAP_FILES):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name


def _miss_map_matches_its_run(folder, mapping, n):
    """miss_map.npy is the run of ``mapping`` at ``n`` of results.csv: its per-level sums are that run's misses."""
    summary = json.loads((folder / "summary.json").read_text())
    misses = np.load(folder / "miss_map.npy")
    size = summary["parameters"]["size"]
    assert misses.shape == (size, size, 3) and misses.dtype == np.uint32
    assert summary["miss_map"]["shape"] == [size, size, 3] and summary["miss_map"]["levels"] == ["L1", "L2", "L3"]
    assert summary["miss_map"]["mapping"] == mapping and summary["miss_map"]["n_processes"] == n
    table = pd.read_csv(folder / "results.csv")
    run = table[(table["section"] == "runs") & (table["mapping"] == mapping) & (table["n_processes"] == n)]
    run = run.set_index("metric")["value"].astype(float)
    totals = misses.sum(axis=(0, 1), dtype=np.int64)
    assert totals[2] == run["memory_accesses"]  # an integer, written exactly
    for index, level in enumerate(("L1", "L2")):
        assert totals[index] == pytest.approx(run[f"{level}_misses_per_ray"] * run["rays"], rel=1e-5)
    mapped = table[table["section"] == "miss_map"]
    assert set(mapped["mapping"]) == {mapping} and set(mapped["n_processes"]) == {n}
    assert mapped.set_index(["item", "metric"])["value"].astype(float)[("L3", "total")] == totals[2]
    return summary


def test_miss_map_defaults_to_the_largest_coherence_loss(reports):
    table = pd.read_csv(reports[0] / "results.csv")
    losses = table[(table["section"] == "runs") & (table["n_processes"] == 8) & (table["metric"] == "coherence_loss")]
    worst = losses.set_index("mapping")["value"].astype(float).idxmax()
    summary = _miss_map_matches_its_run(reports[0], worst, 8)
    assert summary["parameters"]["miss_map"]["chosen_by"].startswith("default")


def test_miss_map_option(tmp_path):
    out = tmp_path / "out"
    assert main(["report", "tetra", "--size", "16", "--processes", "2", "--mappings", "S", "R", "--miss-map",
                 "s:2", "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    summary = _miss_map_matches_its_run(out, "S", 2)
    assert summary["parameters"]["miss_map"] == {"mapping": "S", "n_processes": 2, "chosen_by": "given"}


def test_miss_map_option_in_help(capsys):
    with pytest.raises(SystemExit):
        main(["report", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--miss-map MAPPING:N map the misses per pixel of MAPPING at N processes" in text
    assert "miss_map.npy" in text and "miss_map.png" in text


def test_results_table_is_tidy_and_complete(reports):
    table = pd.read_csv(reports[0] / "results.csv")
    assert tuple(table.columns) == RESULT_COLUMNS
    textured_only = {"texture", "texture_layouts", "texture_miss_ratio"}  # balls has no textures
    path_traced_only = {"ray_orders"}  # a Whitted trace has no ray segments
    assert set(table["section"]) == set(SECTIONS) - textured_only - path_traced_only
    runs = table[table["section"] == "runs"]
    assert set(runs["mapping"]) == {"S", "P", "B", "DB"}
    assert set(runs["n_processes"]) == {1, 2, 8}
    assert not table.duplicated(["section", "mapping", "n_processes", "item", "metric"]).any()
    one = runs[(runs["n_processes"] == 1) & (runs["metric"] == "speedup_user")]
    assert np.allclose(one["value"], 1.0)
    for level in ("L1", "L2", "L3"):
        assert (runs["metric"] == f"{level}_hit_rate").any()
    processes = table[(table["section"] == "processes") & (table["n_processes"] == 8)]
    assert set(processes["item"].astype(int)) == set(range(8))
    curves = table[table["section"] == "miss_ratio"]
    assert {"miss_ratio_32B", "miss_ratio_64B"} <= set(curves["metric"])
    assert curves["value"].between(0, 1).all()


def test_every_verdict_number_is_in_the_table(reports):
    first, _ = reports
    summary = json.loads((first / "summary.json").read_text())
    table = pd.read_csv(first / "results.csv")
    text = summary["verdict"]["text"]
    assert summary["verdict"]["headline"] in text
    quoted = table[table["section"] == "verdict"]
    values = set(quoted["value"].astype(float)) | set(table["n_processes"].dropna().astype(float))
    numbers = re.findall(r"\d+(?:\.\d+)?", text)
    assert len(numbers) >= 10
    for number in numbers:
        assert float(number) in values, f"{number} of the verdict is not in results.csv"
    # and each quoted number is the rounding of the run it comes from
    runs = table[table["section"] == "runs"].set_index(["mapping", "n_processes", "metric"])["value"]
    for row in quoted.itertuples():
        if row.metric == "speedup_user":
            source = f"{runs[(row.mapping, row.n_processes, 'speedup_user')]:.2f}"
        else:
            column = {"imbalance_loss_pct": "imbalance_loss", "coherence_loss_pct": "coherence_loss",
                      "coherence_gain_pct": "coherence_loss", "dispatch_loss_pct": "dispatch_loss",
                      "dispatch_gain_pct": "dispatch_loss", "dispatch_share_pct": "dispatch_share"}[row.metric]
            source = format_percent(abs(runs[(row.mapping, row.n_processes, column)]))
        assert float(source) == pytest.approx(row.value, rel=1e-9)


def test_summary_records_parameters_versions_and_headline(reports):
    summary = json.loads((reports[0] / "summary.json").read_text())
    parameters = summary["parameters"]
    assert parameters["scene"] == "balls" and parameters["size"] == int(SIZE)
    assert parameters["background_load"] == 4 and parameters["n_processes"] == [1, 2, 8]
    assert "numpy" in summary["versions"] and "raytrace-coherence" in summary["versions"]
    assert set(summary["headline"]["8"]) == {"S", "P", "B", "DB"}
    assert parameters["workload"] == "modern" and parameters["kd"] == "sah"


def test_the_verdict_names_the_largest_worst_case_loss_in_results_csv(reports):
    """The verdict's rule restated over results.csv: at the verdict's process count, the loss whose
    worst case over the mappings is largest decides. Fails when verdict() ranks the losses in
    ascending order (``key=lambda item: item[1][0]``)."""
    summary = json.loads((reports[0] / "summary.json").read_text())
    n = summary["verdict"]["n_processes"]
    table = pd.read_csv(reports[0] / "results.csv")
    runs = table[(table["section"] == "runs") & (table["n_processes"] == n)]
    worst = {label: runs[runs["metric"] == column]["value"].astype(float).max()
             for column, label in (("imbalance_loss", "load balance"), ("coherence_loss", "coherence"),
                                   ("dispatch_loss", "dispatch overhead"))}
    expected = max(worst, key=worst.get) if max(worst.values()) > 0 else "nothing"
    assert summary["verdict"]["decided_by"] == expected


def test_report_with_the_study_workload(tmp_path):
    from tracer.trace.records import RecordKind, unpack
    from tracer.trace.access import AccessTrace
    from tracer.rendering.workload import WORKLOADS

    out = tmp_path / "out"
    assert main(["report", "tetra", "--size", "16", "--processes", "2", "--mappings", "S", "R", "--workload",
                 "study1997", "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    parameters = json.loads((out / "summary.json").read_text())["parameters"]
    assert parameters["workload"] == "study1997"
    assert parameters["kd"] == WORKLOADS["study1997"].kd_config.builder
    # the cached trace is the study tracer's: it logs the frame buffer, one write per pixel
    entry = next((tmp_path / "cache" / "traces").glob("tetra-16-study1997-*"))
    trace = AccessTrace.load(entry / "trace")
    kinds, _ = unpack(trace.records)
    assert (kinds == RecordKind.FRAME_BUFFER).sum() == 16 * 16


def test_trace_cache_hit_and_key(tmp_path, monkeypatch):
    monkeypatch.setenv(traces.CACHE_ENV, str(tmp_path / "env"))
    assert traces.default_cache_dir() == tmp_path / "env" / "traces"
    scene, trace, info = traces.cached_trace("tetra", 8, progress=False)
    assert not info["cached"] and info["path"].startswith(str(tmp_path / "env"))
    monkeypatch.setattr(tracer.rendering.render, "render", _no_render)
    _, again, info2 = traces.cached_trace("tetra", 8, progress=False)
    assert info2["cached"] and info2["key"] == info["key"]
    assert isinstance(again.records, np.memmap)
    assert np.array_equal(np.asarray(again.records), np.asarray(trace.records))
    assert info2["tree"] == info["tree"]
    keys = {traces.trace_key("tetra", 8, max_depth=2), traces.trace_key("tetra", 16, max_depth=2),
            traces.trace_key("tetra", 8, kd="median", max_depth=2), traces.trace_key("tetra", 8, max_depth=3),
            traces.trace_key("balls", 8, max_depth=2)}
    assert len(keys) == 5


def test_trace_key_follows_file_content(tmp_path):
    path = tmp_path / "one.nff"
    path.write_text("b 0 0 0\nv\nfrom 0 0 -5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\n"
                    "l 0 5 -5\nf 1 0 0 1 0 0 0 0\ns 0 0 0 1\n")
    before = traces.trace_key(path, 8, max_depth=2)
    path.write_text(path.read_text().replace("s 0 0 0 1", "s 0 0 0 1.5"))
    assert traces.trace_key(path, 8, max_depth=2) != before


@pytest.mark.parametrize("argv, message", [
    (["report", "nosuchscene"], "nosuchscene"),
    (["report", "balls", "--mappings", "S", "XX"], "XX"),
    (["report", "balls", "--hierarchy", "nosuch"], "nosuch"),
    (["report", "balls", "--max-processes", "0"], "--max-processes"),
    (["report", "balls", "--miss-map", "P8"], "--miss-map must be MAPPING:N, a mapping and a process count such as P:8"),
    (["report", "balls", "--miss-map", "XX:8"], "--miss-map: unknown mapping 'XX'"),
    (["report", "balls", "--miss-map", "P:0"], "--miss-map process count must be >= 1, got 0"),
    (["report", "balls", "--memory-budget", "10"], "--memory-budget must be at least"),
    (["report", "balls", "--memory-budget", "nan"], "--memory-budget must be a number of MB, got nan"),
])
def test_user_errors_come_before_rendering(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tracer.rendering.render, "render", _no_render)
    assert main([*argv, "--size", "8", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "c")]) == 2
    error = capsys.readouterr().err
    assert "coherence report: error:" in error and message in error
    assert not (tmp_path / "out").exists()


def test_budget_too_small_for_the_image_fails_before_rendering(tmp_path, monkeypatch):
    # The budget is the process's; at 4096^2 the runs alone need more than 1000 MB.
    monkeypatch.setattr(tracer.rendering.render, "render", _no_render)
    with pytest.raises(ValueError, match=r"memory_budget \(--memory-budget\) of 1000 MB is too small.*give at least"):
        build_report(Experiment("balls", 4096, memory_budget=1000 << 20, cache_dir=tmp_path / "c", progress=False),
                     out=tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_output_path_that_is_a_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tracer.rendering.render, "render", _no_render)
    target = tmp_path / "taken"
    target.write_text("not a folder")
    assert main(["report", "balls", "--size", "8", "--out", str(target), "--cache", str(tmp_path / "c")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    nested = target / "below"
    assert main(["report", "balls", "--size", "8", "--out", str(nested), "--cache", str(tmp_path / "c")]) == 2
    assert "is a file" in capsys.readouterr().err


def _runs(losses):
    rows = []
    for mapping, (imbalance, coherence, dispatch) in losses.items():
        rows.append({"mapping": mapping, "n_processes": 8, "speedup_user": 8 * (1 - imbalance) * (1 - coherence),
                     "imbalance_loss": imbalance, "coherence_loss": coherence, "dispatch_loss": dispatch,
                     "dispatch_share": 0.0})
    return pd.DataFrame(rows)


def test_verdict_balance_or_coherence():
    balance = verdict(_runs({"S": (0.41, 0.008, 0.0), "P": (0.01, 0.002, 0.0)}))
    assert balance.decided_by == "load balance"
    assert balance.headline.startswith("Load balance, not coherence, decided the speed-up at 8 processes")
    assert "S reaches a user speed-up of 4.68 and loses 41.0% to imbalance and 0.8% to coherence" in balance.text
    coherence = verdict(_runs({"S": (0.02, 0.30, 0.0), "P": (0.01, -0.004, 0.0)}))
    assert coherence.decided_by == "coherence"
    assert coherence.headline.startswith("Coherence, not load balance")
    assert "gains 0.4% from coherence" in coherence.text
    assert set(coherence.numbers["metric"]) >= {"coherence_gain_pct", "coherence_loss_pct", "imbalance_loss_pct"}
    with pytest.raises(ValueError, match="n_processes == 16"):
        verdict(_runs({"S": (0.1, 0.1, 0.0)}), 16)


def test_format_percent():
    assert format_percent(0.41234) == "41.2"
    assert format_percent(0.008) == "0.8"
    assert format_percent(0.00024) == "0.024"
    assert format_percent(0.0) == "0"
    assert format_percent(0.01) == "1.0"


def test_curves_fed_in_pieces_equal_the_whole_stream(monkeypatch):
    # The report feeds each order's stream to the reuse counter in pieces; with pieces of a few
    # records (so many pieces, some of one pixel) every curve must equal one pass over the stream.
    from analyses import report_curves as report
    from cachesim import reuse_profile
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.studies import place_layout
    from trace_factory import SMALL, random_trace

    trace = random_trace(width=16, height=12, seed=3)
    placed = place_layout(get_layout("compact"), trace)
    mappings = [get_mapping(name) for name in ("S", "B", "DB")]
    monkeypatch.setattr(report, "CURVE_PIECE", 50)
    curves = report.miss_ratio_curves(trace, placed, mappings, SMALL, False)
    records, offsets = np.asarray(trace.records), np.asarray(trace.pixel_offsets)
    for label, order in report.one_process_orders(mappings, 16, 12):
        stream = np.concatenate([records[offsets[p]:offsets[p + 1]] for p in order])
        for line_size in (32, 64):
            mine = curves[(curves["order"] == label) & (curves["line_size"] == line_size)]
            whole = reuse_profile(placed.addresses(stream, line_size), line_size)
            assert mine["misses"].tolist() == whole.misses(mine["capacity_lines"].to_numpy()).tolist(), label
    assert list(report.pieces(np.array([3, 0, 60, 1, 1]), 50)) == [(0, 2), (2, 3), (3, 5)]


def test_report_on_a_dask_cluster_is_byte_identical(tmp_path):
    distributed = pytest.importorskip("distributed")
    args = ["tetra", "--size", "16", "--processes", "2", "4", "--mappings", "S", "DB", "--cache", str(tmp_path / "cache")]
    assert main(["report", *args, "--out", str(tmp_path / "local")]) == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert main(["report", *args, "--out", str(tmp_path / "dask"), "--dask", cluster.scheduler_address]) == 0
        assert "simulate_stored" in cluster.scheduler.task_prefixes  # the runs did go to the cluster
    for name in ("results.csv", "summary.json", "miss_map.npy"):
        assert (tmp_path / "local" / name).read_bytes() == (tmp_path / "dask" / name).read_bytes(), name
