"""coherence.miss_map and MissMap: per-pixel misses against the slow reference scheduler, tidy form, drawing."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import SymLogNorm  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from analyses.plots import plot_miss_map  # noqa: E402
from cachesim import Hierarchy  # noqa: E402
from coherence import MissMap, miss_map  # noqa: E402
from coherence.cost import CostModel  # noqa: E402
from coherence.layout import get_layout  # noqa: E402
from coherence.mappings import DynamicBlock, Pixel  # noqa: E402
from coherence.simulation import Machine, simulate_run  # noqa: E402
from coherence.studies import place_layout  # noqa: E402
from tracer.trace.access import COUNTER_NAMES, AccessTrace  # noqa: E402

from reference_scheduler import reference_schedule  # noqa: E402
from trace_factory import SMALL, random_trace  # noqa: E402

COST = CostModel(ray=3, node_visit=1, test_sphere=5, test_triangle=7, shading=11)
INCLUSIVE = Hierarchy(SMALL.levels, memory_latency=50, inclusion="inclusive")


@pytest.mark.parametrize("mapping, background, hierarchy", [
    (Pixel(), 0, SMALL), (Pixel(), 2, INCLUSIVE),
    (DynamicBlock(block=2, dispatch_cycles=300.0), 0, INCLUSIVE),
    (DynamicBlock(block=3, dispatch_cycles=300.0), 2, SMALL)])
def test_miss_map_equals_the_reference_schedule(mapping, background, hierarchy):
    trace = random_trace(width=7, height=5, seed=31)
    machine = Machine(n_cpus=2, quantum_cycles=5000.0, background_load=background, background_footprint=800)
    result = miss_map(trace, mapping, 3, hierarchy=hierarchy, layout="compact", cost=COST, machine=machine)
    placed = place_layout(get_layout("compact"), trace)
    distribution = mapping.build(7, 5, 3)
    expected = reference_schedule(trace, distribution, hierarchy, placed,
                                  COST.compute_cycles(trace.counters, COUNTER_NAMES), machine)
    assert result.misses.tolist() == np.array(expected["pixel_misses"]).reshape(5, 7, 2).tolist()
    assert result.levels == ("L1", "L2") and result.mapping == mapping.name and result.n_processes == 3
    assert result.scene == "trace"  # no scene and no name in the trace's metadata
    # the same machine gives the study's run: the map sums to its processes' misses
    run = simulate_run(trace, distribution, hierarchy, placed, COST, machine)
    for index, level in enumerate(result.levels):
        assert result.misses[:, :, index].sum() == run.processes[f"{level}_misses"].sum() > 0


def test_a_textured_scene_maps_its_texel_misses_too():
    from tracer.trace.records import RecordKind, unpack
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    scene = load("balls-textured")
    trace = render(scene, options=RenderOptions(size=8)).trace
    kinds, _ = unpack(trace.records)
    assert (kinds == RecordKind.TEXEL).sum() > 0
    machine = Machine(n_cpus=2, quantum_cycles=20000.0, background_load=1, background_footprint=512)
    result = miss_map(trace, "P", 3, hierarchy=INCLUSIVE, cost=COST, machine=machine, scene=scene)
    assert result.scene == scene.name
    placed = place_layout(get_layout("compact"), trace, scene)
    expected = reference_schedule(trace, Pixel().build(8, 8, 3), INCLUSIVE, placed,
                                  COST.compute_cycles(trace.counters, COUNTER_NAMES), machine)
    assert result.misses.tolist() == np.array(expected["pixel_misses"]).reshape(8, 8, 2).tolist()


def _hand_map():
    misses = np.zeros((2, 3, 2), dtype=np.int64)
    misses[:, :, 0] = [[1, 2, 3], [4, 5, 6]]
    misses[:, :, 1] = [[0, 0, 7], [0, 0, 0]]
    return MissMap(misses, ("L1", "L2"), "balls", "P", 8)


def test_frame_is_tidy_and_maps_back():
    frame = _hand_map().frame()
    assert list(frame.columns) == ["x", "y", "level", "misses"]
    assert len(frame) == 12 and frame["misses"].dtype == np.int64
    rows = frame.set_index(["level", "y", "x"])["misses"]
    assert rows[("L1", 0, 2)] == 3 and rows[("L1", 1, 0)] == 4 and rows[("L2", 0, 2)] == 7
    assert frame["misses"].sum() == 28


def test_totals_by_hand():
    totals = _hand_map().totals().set_index("level")
    assert totals.loc["L1", "total"] == 21 and totals.loc["L1", "max_per_pixel"] == 6
    assert totals.loc["L1", "mean_per_pixel"] == pytest.approx(3.5)
    # 6 pixels: the 1% worst is one pixel
    assert totals.loc["L1", "top_1pct_share"] == pytest.approx(6 / 21)
    assert totals.loc["L2", "top_1pct_share"] == 1.0
    empty = MissMap(np.zeros((2, 2, 1), dtype=np.int64), ("L1",), "s", "S", 1).totals()
    assert empty["total"].tolist() == [0] and np.isnan(empty["top_1pct_share"].iloc[0])


def test_level_and_validation():
    hand = _hand_map()
    assert hand.level("L2").tolist() == [[0, 0, 7], [0, 0, 0]]
    with pytest.raises(ValueError, match="unknown level 'L3'; this miss map has L1, L2"):
        hand.level("L3")
    with pytest.raises(ValueError, match="MissMap.misses must be an int64 array"):
        MissMap(np.zeros((2, 2, 1), dtype=np.float64), ("L1",), "s", "S", 1)
    with pytest.raises(ValueError, match="MissMap.misses must be an int64 array"):
        MissMap(np.zeros((2, 2), dtype=np.int64), ("L1",), "s", "S", 1)
    with pytest.raises(ValueError, match="MissMap.levels must be 1 distinct"):
        MissMap(np.zeros((2, 2, 1), dtype=np.int64), ("L1", "L2"), "s", "S", 1)
    with pytest.raises(ValueError, match="MissMap.levels must be 2 distinct"):
        MissMap(np.zeros((2, 2, 2), dtype=np.int64), ("L1", "L1"), "s", "S", 1)
    with pytest.raises(ValueError, match="MissMap.n_processes"):
        MissMap(np.zeros((2, 2, 1), dtype=np.int64), ("L1",), "s", "S", 0)


def test_miss_map_argument_errors():
    trace = random_trace(width=4, height=3, seed=32)
    with pytest.raises(ValueError, match="n_processes must be"):
        miss_map(trace, "P", 0, hierarchy=SMALL)
    with pytest.raises(ValueError, match="unknown mapping 'Q'"):
        miss_map(trace, "Q", 2, hierarchy=SMALL)
    with pytest.raises(ValueError, match="machine must be a coherence.Machine"):
        miss_map(trace, "P", 2, hierarchy=SMALL, machine="busy")


def test_scene_name_from_the_trace_metadata():
    trace = random_trace(width=4, height=3, seed=33)
    named = AccessTrace(trace.pixel_offsets, trace.records, trace.counters, 4, 3, {"scene": "tetra"})
    assert miss_map(named, "S", 2, hierarchy=SMALL, cost=COST).scene == "tetra"


def test_plot_draws_the_level_upright_with_its_labels():
    hand = _hand_map()
    ax = plot_miss_map(hand, "L1", Figure().subplots())
    image = ax.images[0]
    assert image.get_array().tolist() == [[1, 2, 3], [4, 5, 6]] and image.origin == "upper"
    assert ax.figure.axes[-1].get_ylabel() == "misses per pixel"  # the colour bar
    title = ax.get_title()
    for part in ("balls", "P", "8 processes", "L1"):
        assert part in title
    # a logarithmic scale above one miss by default, so that rare large counts leave the rest visible
    assert isinstance(image.norm, SymLogNorm) and (image.norm.vmin, image.norm.vmax) == (0, 6)
    linear = plot_miss_map(hand, "L2", Figure().subplots(), log=False).images[0].norm
    assert not isinstance(linear, SymLogNorm) and (linear.vmin, linear.vmax) == (0, 7)
    with pytest.raises(ValueError, match="unknown level"):
        plot_miss_map(hand, "L9", Figure().subplots())
