"""The what-if over the path-traced workload's ray orders (analyses.order_whatif)."""
import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from analyses.order_whatif import ORDER_WHATIF_EXPERIMENT, order_whatif, save_order_whatif
from analyses.report_orders import order_section
from coherence.studies import place_layout, study
from rtcommon.validate import InputError
from tracer.kd.tree import build_kdtree
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.catalog import load

ORDERS = ("depth-first", "wavefront")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return replace(ORDER_WHATIF_EXPERIMENT, size=8, mappings=("P",), n_processes=(4,),
                   cache_dir=str(tmp_path_factory.mktemp("cache")))


@pytest.fixture(scope="module")
def table(base):
    return order_whatif(base, {"spp": [1, 2], "L1.size": [4096]}, orders=ORDERS, n_jobs=1)


def _direct(base, spp, l1_size):
    """The section as the report computes it, on a trace rendered here, the L1 resized by hand."""
    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=8, workload="pathtrace", spp=spp)).trace
    hierarchy = base.hierarchy_object()
    hierarchy = replace(hierarchy, levels=(replace(hierarchy.levels[0], size=l1_size), *hierarchy.levels[1:]))
    layout, cost, machine, mappings = base.layout_object(), base.cost_model(), base.machine(), base.mapping_objects()
    runs = study(trace, mappings, [1, 4], hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
                 scene=scene, progress=False).runs
    setup = {"mappings": mappings, "hierarchy": hierarchy, "placed": place_layout(layout, trace, scene),
             "cost": cost, "machine": machine, "scene": scene}
    return order_section(trace, runs, setup, 4, ORDERS)


@pytest.mark.parametrize("spp", [1, 2])
def test_points_are_the_report_section(base, table, spp):
    """Each point's rows equal the report's ray-order section computed directly on that point's trace and
    caches. Fails if the point's level sizes were not applied (``_point_levels(...)`` replaced by
    ``experiment.hierarchy_object()``) or the point's spp were dropped (``"spp"`` left out of the keys
    ``replace`` takes) (both checked)."""
    expected = _direct(base, spp, 4096)
    mine = table[table["spp"] == spp].reset_index(drop=True)
    assert list(mine["L1.size"]) == [4096] * len(ORDERS)
    pd.testing.assert_frame_equal(mine[expected.columns], expected, check_exact=False, rtol=1e-12)


def test_net_speedup_is_against_depth_first(table):
    """``net_speedup`` is the depth-first row's slowest process time over the order's, so 1 for depth-first.
    Fails if it were the order's time over depth-first's (the division turned over) (checked)."""
    for _, point in table.groupby("spp"):
        first = point[point["order"] == "depth-first"]["user_seconds_max"].iloc[0]
        np.testing.assert_allclose(point["net_speedup"], first / point["user_seconds_max"], rtol=1e-12)
        assert point[point["order"] == "depth-first"]["net_speedup"].iloc[0] == 1.0


def test_saved_with_its_meta(base, table, tmp_path):
    """The CSV reads back as the table and its .meta.json holds the grid. Fails if the grid were left out of
    the meta (``grid=`` argument dropped) (checked)."""
    path = save_order_whatif(table, base, {"spp": [1, 2], "L1.size": [4096]}, tmp_path)
    back = pd.read_csv(path)
    np.testing.assert_allclose(back["net_speedup"], table["net_speedup"], rtol=1e-12)
    meta = json.loads(path.with_name(path.name + ".meta.json").read_text())
    assert meta["parameters"]["grid"] == {"spp": ["1", "2"], "L1.size": ["4096"]}


def test_pool_and_dask_give_the_serial_table(base, table):
    """The grid's points run in a local pool of 2 processes, and on a Dask cluster of 2 workers, give the
    table of the points run one after another, row for row. Fails if the pool's results were gathered in
    another order than the points' (``futures[::-1]`` in ``_run_tasks``) (checked)."""
    grid = {"spp": [1, 2], "L1.size": [4096]}
    pd.testing.assert_frame_equal(order_whatif(base, grid, orders=ORDERS, n_jobs=2), table)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        on_dask = order_whatif(replace(base, dask=client), grid, orders=ORDERS)
    pd.testing.assert_frame_equal(on_dask, table)


def test_bad_worker_count_is_refused(base):
    """``n_jobs`` below 1 raises an InputError naming it (fails without the ``require_int`` check: the pool
    then refuses 0 workers with its own ValueError) (checked)."""
    with pytest.raises(InputError, match="n_jobs"):
        order_whatif(base, {"spp": [1, 2]}, orders=ORDERS, n_jobs=0)


@pytest.mark.parametrize("grid, words", [({}, "empty"), ({"memory_latency": [80]}, "memory_latency"),
                                         ({"spp": []}, "no values")])
def test_bad_grid_is_refused(base, grid, words):
    """A bad grid raises a one-line InputError naming it. Fails if unknown keys were accepted (the key check
    removed) (checked for the second case)."""
    with pytest.raises(InputError, match=words):
        order_whatif(base, grid)


def test_whitted_base_is_refused(base):
    """The base must be path-traced. Fails without the workload check (checked: a Whitted trace has no
    segments and the section fails elsewhere)."""
    with pytest.raises(InputError, match="pathtrace"):
        order_whatif(replace(base, workload="modern", spp=1), {"L1.size": [4096]})


def test_platform_points_run_on_its_shared_levels(base):
    """Under a platform a point's runs are on its shared levels, an ``<level>.size`` the size of one whole
    level, interleaved at the base's ``interleave_cycles``: the point's rows equal the section on those
    levels. Fails if the point's size were not applied to the shared levels (``_point_levels(...)`` made
    ``machine.hierarchy`` in ``_levels_of``) (checked)."""
    from analyses.order_whatif import _levels_of

    platform = replace(base, platform="apple-m1", interleave_cycles=500)
    levels = _levels_of(platform, {"L2.size": 6 << 20})
    assert levels.machine.hierarchy.levels[1].size == 6 << 20 and levels.interleave_cycles == 500
    assert levels.machine.shared_by == platform.study_hierarchy().machine.shared_by
    table = order_whatif(platform, {"L2.size": [6 << 20]}, orders=ORDERS)
    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=8, workload="pathtrace", spp=1)).trace
    layout, cost, machine, mappings = (platform.layout_object(), platform.cost_model(), platform.machine(),
                                       platform.mapping_objects())
    runs = study(trace, mappings, [1, 4], hierarchy=levels, layout=layout, cost=cost, machine=machine,
                 scene=scene, progress=False).runs
    setup = {"mappings": mappings, "hierarchy": levels, "placed": place_layout(layout, trace, scene),
             "cost": cost, "machine": machine, "scene": scene}
    expected = order_section(trace, runs, setup, 4, ORDERS)
    pd.testing.assert_frame_equal(table[expected.columns], expected, check_exact=False, rtol=1e-12)


def test_cli_writes_the_api_table(base, tmp_path):
    """``coherence whatif --orders`` writes what the Python API gives on the same base and grid (``8KB``
    read as 8192). Fails if the options' process count were overridden by the default base's
    (``experiment_from_args(args, ORDER_WHATIF_EXPERIMENT, n_processes=(8,))``) (checked)."""
    from analyses.cli import main

    out = tmp_path / "out"
    assert main(["whatif", "--orders", "--grid", "L1.size=8KB", "--size", "8", "--processes", "4",
                 "--cache", base.cache_dir, "--out", str(out)]) == 0
    written = pd.read_csv(out / "whatif-orders.csv")
    expected = order_whatif(base, {"L1.size": [8192]})
    assert list(written["order"]) == list(expected["order"])
    np.testing.assert_allclose(written["net_speedup"], expected["net_speedup"], rtol=1e-12)


@pytest.mark.parametrize("flags, words", [(["--grid", "spp"], "NAME=VALUE"),
                                          (["--grid", "spp=1", "--grid", "spp=2"], "more than once"),
                                          (["caches"], "--grid flags only")])
def test_cli_refuses_bad_flags(tmp_path, capsys, flags, words):
    """Bad ``--orders`` flags end with a one-line error naming them and write nothing. Fails if a repeated
    parameter overwrote the first (the repeat check removed) (checked for the second case)."""
    from analyses.cli import main

    assert main(["whatif", "--orders", *flags, "--out", str(tmp_path / "out")]) != 0
    assert words in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
