"""Memory layouts (record -> addresses) and the cycle cost model."""
import numpy as np
import pandas as pd
import pytest

from coherence.cost import CostModel, alpha8400, get_cost_model, modern
from coherence.layout import MemoryLayout, RecordLayout, get_layout, record_counts_of
from tracer.trace.access import COUNTER_NAMES, RecordKind, pack
from tracer.trace.records import KIND_SHIFT


def reference_addresses(placed, records, line_size):
    """Every line_size line each record's bytes touch, by a plain loop."""
    out = []
    for record in records:
        kind, index = int(record) >> 28, int(record) & ((1 << 28) - 1)
        row = int(placed.kind_first[kind]) + index
        start, size = int(placed.record_start[row]), int(placed.record_size[row])
        line = start // line_size
        while line * line_size <= start + size - 1:
            out.append(line * line_size)
            line += 1
    return out


def test_compact_layout_by_hand():
    placed = get_layout("compact").place({"kd_node": 10, "index_entry": 5, "triangle": 4, "material": 2})
    base = 0x10000000
    assert placed.record_start[3] == base + 3 * 8  # fourth node
    # Index entries start on the next 4 KB region after 80 bytes of nodes.
    first_index = placed.kind_first[RecordKind.INDEX_ENTRY]
    assert placed.record_start[first_index] == base + 4096
    triangles = placed.kind_first[RecordKind.TRIANGLE]
    assert placed.record_start[triangles + 1] - placed.record_start[triangles] == 36
    # Triangle 1 occupies bytes 36..71 of its region: the 32 B lines at 32
    # and 64, or the 64 B lines at 0 and 64.
    records = pack([RecordKind.TRIANGLE], [1])
    addresses = placed.addresses(records, 32)
    region = int(placed.record_start[triangles])
    assert addresses.tolist() == [region + 32, region + 64]
    assert placed.addresses(records, 64).tolist() == [region, region + 64]


@pytest.mark.parametrize("name", ["compact", "alpha1997"])
@pytest.mark.parametrize("line_size", [16, 32, 64])
def test_addresses_equal_reference(name, line_size):
    rng = np.random.default_rng(3)
    counts = {kind: int(rng.integers(1, 50)) for kind in RecordKind}
    vertices = {RecordKind.POLYGON: rng.integers(3, 12, counts[RecordKind.POLYGON])}
    placed = get_layout(name).place(counts, vertices, [[(counts[RecordKind.TEXEL], 1)]])
    kinds = rng.integers(0, len(RecordKind), 2000)
    indices = np.array([rng.integers(0, counts[RecordKind(k)]) for k in kinds])
    records = pack(kinds, indices)
    assert placed.addresses(records, line_size).tolist() == reference_addresses(placed, records, line_size)
    # Regions do not overlap.
    order = np.argsort(placed.record_start)
    ends = placed.record_start[order] + placed.record_size[order]
    assert np.all(ends[:-1] <= placed.record_start[order][1:])


def test_polygon_size_grows_with_vertices():
    layout = get_layout("alpha1997")
    placed = layout.place({"polygon": 2}, {"polygon": np.array([3, 48])})
    polygon = layout.record("polygon")
    assert polygon.per_vertex > 0
    assert placed.record_size.tolist() == [polygon.size + 3 * polygon.per_vertex, polygon.size + 48 * polygon.per_vertex]


def test_bad_layouts_and_records():
    with pytest.raises(ValueError, match="align must be a power of two"):
        RecordLayout(8, 3)
    with pytest.raises(ValueError, match="missing"):
        MemoryLayout(records={"kd_node": RecordLayout(8)})
    with pytest.raises(ValueError, match="unknown memory layout 'tiny'"):
        get_layout("tiny")
    placed = get_layout("compact").place({"sphere": 3})
    with pytest.raises(ValueError, match="sphere 7, but the layout holds only 3"):
        placed.addresses(pack([RecordKind.SPHERE], [7]), 32)
    good = pack([RecordKind.SPHERE] * 3, [0, 2, 1])
    with pytest.raises(ValueError, match="record 3 is sphere 3, but"):  # the first bad one is named
        placed.addresses(np.concatenate([good, pack([RecordKind.SPHERE] * 2, [3, 9])]), 32)
    with pytest.raises(ValueError, match="record 1 has kind 15, which is not a RecordKind"):
        placed.addresses(np.array([good[0], np.uint32(15 << KIND_SHIFT)], dtype=np.uint32), 32)
    assert placed.addresses(good, 32).size == 3
    with pytest.raises(ValueError, match="vertex_counts"):
        get_layout("compact").place({"polygon": 2}, {"polygon": [3]})


def test_record_counts_from_trace_records():
    class Trace:
        records = pack([0, 0, 2, 7], [5, 1, 9, 0])
        metadata = {}
    counts = record_counts_of(Trace())
    assert counts[RecordKind.KD_NODE] == 6 and counts[RecordKind.SPHERE] == 10
    assert counts[RecordKind.MATERIAL] == 1 and counts[RecordKind.LIGHT] == 0


def test_compute_cycles_in_chunks_equal_one_product(tmp_path, monkeypatch):
    # a memory-mapped trace's counters go through in chunks of rows; the cycles are those of one product
    import coherence.cost as cost_module

    monkeypatch.setattr(cost_module, "COMPUTE_ROWS", 97)
    rng = np.random.default_rng(3)
    counters = rng.integers(0, 5000, (1000, len(COUNTER_NAMES)))
    np.save(tmp_path / "counters.npy", counters)
    mapped = np.load(tmp_path / "counters.npy", mmap_mode="r")
    for model in (alpha8400(), modern()):
        expected = counters.astype(np.float64) @ model.weights(COUNTER_NAMES)
        assert np.array_equal(model.compute_cycles(mapped, COUNTER_NAMES), expected)


def test_cost_weights_and_compute_cycles():
    model = CostModel(ray=10, node_visit=2, test_sphere=7, shading=100)
    counters = np.zeros((2, len(COUNTER_NAMES)), dtype=np.int64)
    column = {name: i for i, name in enumerate(COUNTER_NAMES)}
    counters[0, column["primary_rays"]] = 1
    counters[0, column["shadow_rays"]] = 3
    counters[0, column["node_visits"]] = 20
    counters[1, column["tests_sphere"]] = 5
    counters[1, column["shading"]] = 2
    assert model.compute_cycles(counters, COUNTER_NAMES).tolist() == [4 * 10 + 20 * 2, 5 * 7 + 2 * 100]


def test_calibrate_recovers_known_costs():
    rng = np.random.default_rng(8)
    truth = CostModel(ray=300, node_visit=50, index_read=9, test_sphere=400, test_triangle=250, shading=1200)
    rows = pd.DataFrame({
        "primary_rays": rng.integers(1e5, 3e5, 8), "shadow_rays": rng.integers(1e5, 5e5, 8),
        "node_visits": rng.integers(1e6, 9e6, 8), "index_reads": rng.integers(1e6, 5e6, 8),
        "tests_sphere": rng.integers(1e6, 9e6, 8), "tests_triangle": rng.integers(0, 5e6, 8),
        "shading": rng.integers(1e5, 3e5, 8), "memory_cycles": rng.integers(1e8, 1e9, 8),
    })
    operations = [column for column in rows if column != "memory_cycles"]
    cycles = truth.compute_cycles(rows[operations], operations)
    rows["seconds"] = (cycles + rows["memory_cycles"]) / 300e6
    model, residuals = CostModel.calibrate(rows, clock_hz=300e6)
    for name in ("ray", "node_visit", "index_read", "test_sphere", "test_triangle", "shading"):
        assert getattr(model, name) == pytest.approx(getattr(truth, name), rel=1e-6)
    assert np.abs(residuals["relative_error"]).max() < 1e-9


def test_calibrate_with_fixed_costs_and_errors():
    rows = pd.DataFrame({"tests_sphere": [1e6, 2e6], "seconds": [1.0, 2.0]})
    model, _ = CostModel.calibrate(rows, clock_hz=1e6, fixed={"ray": 5})
    assert model.test_sphere == pytest.approx(1.0) and model.ray == 5
    with pytest.raises(ValueError, match="'seconds'"):
        CostModel.calibrate(rows.drop(columns="seconds"))
    with pytest.raises(ValueError, match="unknown operations"):
        CostModel.calibrate(rows, fixed={"warp": 1})
    with pytest.raises(ValueError, match="CostModel.shading"):
        CostModel(shading=-1)
    assert get_cost_model("alpha8400") == alpha8400() and modern().clock_hz == 3e9
    with pytest.raises(ValueError, match="unknown cost model"):
        get_cost_model("cray")



def test_render_metadata_counts_every_record_kind():
    from scene_factory import random_scene
    from tracer.rendering.render import RenderOptions, render

    scene = random_scene(n=40, seed=3)
    trace = render(scene, options=RenderOptions(size=(12, 12))).trace
    counts = record_counts_of(trace)
    assert counts[RecordKind.SPHERE] == scene.sphere_radius.size
    assert counts[RecordKind.POLYGON] == scene.polygon_offsets.size - 1
    assert counts[RecordKind.LIGHT] == scene.light_position.shape[0]
    read = record_counts_of(type("T", (), {"records": trace.records, "metadata": {}})())
    assert all(read[kind] <= counts[kind] for kind in RecordKind)


def test_record_lines_and_writes_flag_every_line_of_a_written_record():
    from coherence.record_lines import record_lines, record_lines_and_writes
    from tracer.trace.records import pack

    rng = np.random.default_rng(11)
    placed = get_layout("alpha1997").place({kind: 50 for kind in RecordKind}, textures=[[(10, 5)]])
    kinds = rng.integers(0, len(RecordKind), 400)
    ids = rng.integers(0, 50, 400)
    writes = rng.random(400) < 0.3
    records = pack(kinds, ids, writes)
    shift = 5
    lines, count = record_lines(records, 0, 400, placed.placement, shift, np.empty(4, dtype=np.uint64))
    got, flags, n, n_writes = record_lines_and_writes(records, 0, 400, placed.placement, shift,
                                            np.empty(4, dtype=np.uint64), np.empty(4, dtype=np.bool_))
    assert n == count and np.array_equal(got[:n], lines[:count])
    # by hand: each record's flag once per line it spans
    expected = []
    for record, write in zip(records, writes):
        one, k = record_lines(np.array([record]), 0, 1, placed.placement, shift, np.empty(8, dtype=np.uint64))
        expected += [bool(write)] * k
    assert flags[:n].tolist() == expected and n_writes == sum(expected)


@pytest.mark.parametrize("shift", [3, 5, 6])
def test_record_lines_equal_a_slow_reference_whether_counted_first_or_not(shift):
    # Records of 1 to 40+ lines (polygons of many vertices), written and not;
    # a buffer too short for the bound makes the kernel count first, one long
    # enough lets it fill straight away. Either way: every line of every
    # record, in order, each flagged as its record is.
    from coherence.record_lines import FILL_AHEAD, line_span_bound, record_lines_and_writes
    from tracer.trace.records import pack

    rng = np.random.default_rng(shift)
    n_vertices = rng.integers(3, 60, 30)
    placed = get_layout("alpha1997").place({kind: 30 for kind in RecordKind},
                                           {RecordKind.POLYGON: n_vertices, RecordKind.PATCH: n_vertices},
                                           textures=[[(6, 5)]])
    kinds, ids, writes = rng.integers(0, len(RecordKind), 500), rng.integers(0, 30, 500), rng.random(500) < 0.3
    records = pack(kinds, ids, writes)
    expected, expected_flags = [], []
    for kind, index, write in zip(kinds, ids, writes):
        row = int(placed.kind_first[kind]) + int(index)
        start, size = int(placed.record_start[row]), int(placed.record_size[row])
        span = list(range(start >> shift, ((start + size - 1) >> shift) + 1))
        expected += [line << shift for line in span]
        expected_flags += [bool(write)] * len(span)
    bound = line_span_bound(placed.placement, shift)
    assert bound >= max(len(range(s >> shift, ((s + z - 1) >> shift) + 1))
                        for s, z in zip(placed.record_start, placed.record_size))
    for size in (3, records.size * bound + FILL_AHEAD):
        got, flags, n, n_writes = record_lines_and_writes(records, 0, records.size, placed.placement, shift,
                                                          np.zeros(size, dtype=np.uint64),
                                                          np.zeros(size, dtype=np.bool_))
        assert got[:n].tolist() == expected and flags[:n].tolist() == expected_flags
        assert n_writes == sum(expected_flags) and got.size >= n + FILL_AHEAD
