"""The report's ray-order section (analyses.report_orders) and its place in the report of a path-traced trace."""
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analyses.cli import main
from analyses.experiment import Experiment
from analyses.report_orders import order_section
from coherence.mappings import DynamicBlock, get_mapping
from coherence.studies import place_layout, study
from tracer.kd.tree import build_kdtree
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.catalog import load

FACTORS = ("load_balance", "coherence_factor", "reordering_gain", "reordering_overhead", "dispatch_factor")


@pytest.fixture(scope="module")
def section():
    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=12, workload="pathtrace", spp=2)).trace
    experiment = Experiment(scene="balls", size=12)
    hierarchy, layout, cost, machine = (experiment.hierarchy_object(), experiment.layout_object(),
                                        experiment.cost_model(), experiment.machine())
    mappings = [get_mapping("P"), DynamicBlock(block=3)]
    runs = study(trace, mappings, [1, 4], hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
                 scene=scene, progress=False).runs
    setup = {"mappings": mappings, "hierarchy": hierarchy, "placed": place_layout(layout, trace, scene),
             "cost": cost, "machine": machine, "scene": scene}
    return order_section(trace, runs, setup, 4), runs


def test_depth_first_rows_are_the_study_runs(section):
    """The depth-first rows repeat the study's runs at the section's process count (misses per ray, times,
    speed-up, load balance and coherence) with gain and overhead 1. Fails if T1 were read at the section's
    process count instead of at 1 (``mine.loc[1]`` made ``mine.loc[n_processes]``) (checked)."""
    table, runs = section
    for mapping in ("P", "DB"):
        row = table[(table["mapping"] == mapping) & (table["order"] == "depth-first")].iloc[0]
        run = runs[(runs["mapping"] == mapping) & (runs["n_processes"] == 4)].iloc[0]
        for column in ("L1_misses_per_ray", "L2_misses_per_ray", "user_seconds_max", "real_seconds",
                       "speedup_user", "load_balance", "coherence_factor", "dispatch_factor"):
            assert row[column] == pytest.approx(run[column], rel=1e-12), (mapping, column)
        assert (row["reordering_gain"], row["reordering_overhead"], row["queue_records"]) == (1.0, 1.0, 0)


def test_factors_multiply_to_the_efficiency(section):
    """For every mapping and order, load balance x coherence x gain x overhead x dispatch = efficiency =
    speed-up / n. Fails if the overhead were the order's work over the bare order's (``w0 / w0_bare``)
    (checked)."""
    table, _ = section
    product = np.prod(table[list(FACTORS)].to_numpy(), axis=1)
    np.testing.assert_allclose(product, table["efficiency"], rtol=1e-12)
    np.testing.assert_allclose(table["efficiency"], table["speedup_user"] / 4, rtol=1e-12)


def test_wavefront_pays_for_its_queues(section):
    """The wavefront order writes and reads ray states and queue entries (> 0, the same under both mappings:
    every ray queued once either way), and they cost: overhead < 1. Fails if the buffer records were left out
    of the run (``pieces_unit`` replaced by the bare order in ``registry_orders``) (checked)."""
    table, _ = section
    wavefront = table[table["order"] == "wavefront"]
    assert len(wavefront) == 2 and (table[table["order"] == "treelet"]["queue_records"] > 0).all()
    assert (wavefront["queue_records"] > 0).all() and (wavefront["ray_state_records"] > 0).all()
    assert wavefront["queue_records"].nunique() == 1
    assert (wavefront["reordering_overhead"] < 1).all()


def test_report_of_a_path_traced_trace_has_the_section(tmp_path):
    """``coherence report --workload pathtrace`` writes the section: every registered order and treelet queues
    (sized to the first level, with queue records) in results.csv and summary.json, under the mapping the miss
    map shows, and the page's table, each metric listed in docs/outputs.md; a Whitted report has none. Fails if
    results_table leaves out the order rows (checked)."""
    from coherence.ray_orders import RAY_ORDERS

    out = tmp_path / "out"
    assert main(["report", "balls", "--size", "12", "--processes", "4", "--mappings", "S", "P", "--workload",
                 "pathtrace", "--spp", "2", "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    results = pd.read_csv(out / "results.csv")
    orders = results[results["section"] == "ray_orders"]
    assert set(orders["item"]) == {*RAY_ORDERS, "treelet"}
    summary = json.loads((out / "summary.json").read_text())
    assert {row["order"] for row in summary["ray_orders"]} == {*RAY_ORDERS, "treelet"}
    assert next(row for row in summary["ray_orders"] if row["order"] == "treelet")["queue_records"] > 0
    assert set(orders["mapping"]) == {summary["parameters"]["miss_map"]["mapping"]}
    assert "<h2>Ray orders:" in (out / "index.html").read_text()
    # docs/outputs.md lists exactly the section's metrics (levels as <level>)
    page = (Path(__file__).resolve().parent.parent / "docs" / "outputs.md").read_text(encoding="utf-8")
    documented = {line.split("|")[2].strip().strip("`") for line in page.splitlines()
                  if line.startswith("| `ray_orders` |")}
    assert {re.sub(r"^L\d_", "<level>_", metric) for metric in orders["metric"]} == documented
    whitted = tmp_path / "whitted"
    assert main(["report", "balls", "--size", "12", "--processes", "4", "--mappings", "S", "--out", str(whitted),
                 "--cache", str(tmp_path / "cache")]) == 0
    assert "ray_orders" not in set(pd.read_csv(whitted / "results.csv")["section"])


def test_a_report_under_a_platform_has_the_section(tmp_path):
    """Under a platform the report has the section (results.csv and summary.json), every registered order,
    its depth-first row the study's run on the shared levels, treelets of the platform's whole first level
    (apple-m1: 128 KB L1 a core). Fails with the section left out under a platform (the condition
    ``experiment.platform is None`` put back in build_report) (checked)."""
    from coherence.ray_orders import RAY_ORDERS

    out = tmp_path / "out"
    assert main(["report", "tetra", "--size", "8", "--processes", "2", "--mappings", "S", "--workload",
                 "pathtrace", "--spp", "1", "--platform", "apple-m1", "--out", str(out),
                 "--cache", str(tmp_path / "cache")]) == 0
    results = pd.read_csv(out / "results.csv")
    assert set(results[results["section"] == "ray_orders"]["item"]) == {*RAY_ORDERS, "treelet"}
    summary = json.loads((out / "summary.json").read_text())
    rows = {row["order"]: row for row in summary["ray_orders"]}
    assert rows["treelet"]["treelet_bytes"] == 128 * 1024 and rows["treelet"]["queue_records"] > 0
    def value(section, item, metric):
        chosen = results[(results["section"] == section) & (results["mapping"] == "S")
                         & (results["n_processes"] == 2) & (results["metric"] == metric)]
        return chosen[chosen["item"].fillna("") == item]["value"].astype(float).tolist()

    for metric in ("L1_misses_per_ray", "L2_misses_per_ray", "user_seconds_max"):
        assert value("ray_orders", "depth-first", metric) == value("runs", "", metric) != []


def test_orders_run_on_the_shared_levels_the_study_ran_on():
    """Given a platform's SharedLevels (as the study's runs), each order's row is its run on those levels
    (:func:`coherence.ordered_runs.simulate_ordered_shared`), not on one thread's private view. Fails if the
    section ran the orders on private caches (``if shared is None`` made ``if True`` in ``_ordered_run``)
    (checked)."""
    from coherence.metrics import run_summary
    from coherence.ordered_runs import simulate_ordered_shared
    from coherence.ray_orders import scene_bounds_of
    from analyses.report_orders import registry_orders

    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=8, workload="pathtrace", spp=1)).trace
    experiment = Experiment(scene="balls", size=8, workload="pathtrace", platform="apple-m1", background=0)
    shared, layout, cost, machine = (experiment.study_hierarchy(), experiment.layout_object(),
                                     experiment.cost_model(), experiment.machine())
    mappings = [get_mapping("P")]
    placed = place_layout(layout, trace, scene)
    runs = study(trace, mappings, [1, 4], hierarchy=shared, layout=layout, cost=cost, machine=machine,
                 scene=scene, progress=False).runs
    setup = {"mappings": mappings, "hierarchy": shared, "placed": placed, "cost": cost, "machine": machine,
             "scene": scene}
    table = order_section(trace, runs, setup, 4, ["depth-first", "wavefront"])
    ordered, _ = registry_orders("wavefront", scene_bounds=scene_bounds_of(trace.segments))
    run, _ = simulate_ordered_shared(trace, mappings[0].build(8, 8, 4), ordered, shared, placed, cost, machine)
    levels = shared.hierarchy.level_names
    expected = run_summary(run.run.processes, levels, cost.clock_hz, run.run.real_cycles)
    row = table[table["order"] == "wavefront"].iloc[0]
    for column in [f"{level}_misses_per_ray" for level in levels] + ["user_seconds_max"]:
        assert row[column] == pytest.approx(float(expected[column]), rel=1e-12), column
    depth_first = table[table["order"] == "depth-first"].iloc[0]
    assert depth_first["user_seconds_max"] == pytest.approx(float(runs[runs["n_processes"] == 4]
                                                                  ["user_seconds_max"].iloc[0]), rel=1e-12)


def test_the_tree_is_built_again_as_the_trace_recorded_it():
    """Orders that need the kd-tree (treelet queues) get the tree the trace was rendered with, built again from
    the scene and the trace's kd_config: here a median tree. Fails if it were built with the default rule
    (``KdTreeConfig(**...)`` made ``KdTreeConfig()``) (checked)."""
    from analyses.report_orders import _trace_tree
    from tracer.kd.tree import KdTreeConfig

    scene = load("balls")
    median = build_kdtree(scene, KdTreeConfig(builder="median"))
    trace = path_trace(scene, median, RenderOptions(size=4, workload="pathtrace")).trace
    assert np.array_equal(_trace_tree(trace, scene).nodes, median.nodes)


def test_treelets_follow_the_first_cache_level():
    """With a first level of 4 KB (not the registered 8 KB) and the ``alpha1997`` layout (40-byte nodes), the
    section's treelet order runs with 4 KB treelets of 40-byte nodes, says so in ``treelet_bytes`` (0 for the
    other orders); a treelet order given with its own sizes keeps them. Fails if the section used the registered
    default (``_sized`` returning ``order`` unchanged) (checked)."""
    from dataclasses import replace

    from analyses.report_orders import report_orders
    from coherence.ray_orders import RAY_ORDERS

    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=6, workload="pathtrace", spp=1)).trace
    experiment = Experiment(scene="balls", size=6, layout="alpha1997")
    hierarchy = experiment.hierarchy_object()
    hierarchy = replace(hierarchy, levels=(replace(hierarchy.levels[0], size=4096), *hierarchy.levels[1:]))
    layout, cost, machine = experiment.layout_object(), experiment.cost_model(), experiment.machine()
    mapping = get_mapping("P")
    runs = study(trace, [mapping], [1, 2], hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
                 scene=scene, progress=False).runs
    setup = {"mappings": [mapping], "hierarchy": hierarchy, "placed": place_layout(layout, trace, scene),
             "cost": cost, "machine": machine, "scene": scene}
    treelet = next(order for order in report_orders(setup) if order.name == "treelet")
    assert (treelet.treelet_bytes, treelet.node_bytes) == (4096, 40) != (RAY_ORDERS["treelet"].treelet_bytes,
                                                                           RAY_ORDERS["treelet"].node_bytes)
    table = order_section(trace, runs, setup, 2, orders=["depth-first", "treelet"]).set_index("order")
    assert table.loc["treelet", "treelet_bytes"] == 4096 and table.loc["depth-first", "treelet_bytes"] == 0
    own = order_section(trace, runs, setup, 2, orders=[RAY_ORDERS["treelet"].sized(8192, 40)])
    assert own["treelet_bytes"].iloc[0] == 8192  # a treelet order with sizes of its own keeps them
