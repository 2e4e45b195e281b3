"""Renderer and access trace: logging is exact, complete and harmless."""
import json

import numba
import numpy as np
import pytest

from scene_factory import KINDS, one_sphere, random_scene
from tracer.kd.tree import KdTreeConfig, build_kdtree
import tracer.rendering.render as render_module
from tracer.rendering.camera import camera_rays
from tracer.kd.closest import closest_hit
from tracer.rendering.render import RenderOptions, render, save_png
from tracer.trace.records import INDEX_MASK, PLAIN_FORMAT_VERSION
from tracer.trace.access import COUNTER_NAMES, COUNTER_OF_KIND, AccessTrace, RecordKind, TraceWriter, pack, unpack


@pytest.fixture(scope="module")
def mixed():
    scene = random_scene(KINDS, n=120, seed=21, size=0.9, lights=2)
    return scene, build_kdtree(scene)


def _per_pixel_kind_counts(trace):
    kinds, _ = unpack(trace.records)
    pixel = np.repeat(np.arange(trace.n_pixels), np.diff(trace.pixel_offsets))
    out = np.zeros((trace.n_pixels, 16), np.int64)
    np.add.at(out, (pixel, kinds.astype(np.int64)), 1)
    return out


def test_logging_does_not_change_image_or_counters(mixed):
    scene, tree = mixed
    plain = render(scene, tree, RenderOptions(size=(24, 20), log=False))
    logged = render(scene, tree, RenderOptions(size=(24, 20), log=True))
    assert plain.trace is None
    assert plain.image.shape == (20, 24, 3)
    assert np.array_equal(plain.image, logged.image)  # bit for bit
    assert np.array_equal(plain.counters, logged.counters)


def test_epsilon_applies_to_both_passes(mixed):
    scene, tree = mixed
    plain = render(scene, tree, RenderOptions(size=(16, 12), log=False, epsilon=0.05))
    logged = render(scene, tree, RenderOptions(size=(16, 12), log=True, epsilon=0.05))
    assert np.array_equal(plain.image, logged.image)
    assert np.array_equal(plain.counters, logged.counters)
    assert logged.trace.metadata["epsilon"] == 0.05


def test_counters_equal_record_counts_per_pixel(mixed):
    scene, tree = mixed
    res = render(scene, tree, RenderOptions(size=24))
    t = res.totals()
    # every ray type and primitive kind occurs, so the check covers them all
    for name in ("reflection_rays", "refraction_rays", "shadow_blocked", "tests_sphere",
                 "tests_triangle", "tests_polygon", "tests_patch", "tests_cone"):
        assert t[name] > 0, name
    per_kind = _per_pixel_kind_counts(res.trace)
    for kind, name in COUNTER_OF_KIND.items():
        assert np.array_equal(per_kind[:, kind], res.counters[:, COUNTER_NAMES.index(name)]), name
    assert per_kind[:, 9:].sum() == 0
    c = {n: res.counters[:, i] for i, n in enumerate(COUNTER_NAMES)}
    assert np.all(c["primary_rays"] == 1)
    assert np.array_equal(c["shading"], c["primary_hits"] + c["reflection_hits"] + c["refraction_hits"])
    assert np.array_equal(c["light_reads"], c["shading"] * scene.n_lights)
    assert np.all(c["index_reads"] == sum(c[f"tests_{k}"] for k in KINDS))


def test_logging_is_deterministic(mixed):
    scene, tree = mixed
    a = render(scene, tree, RenderOptions(size=16)).trace
    b = render(scene, tree, RenderOptions(size=16)).trace
    assert np.array_equal(a.pixel_offsets, b.pixel_offsets)
    assert np.array_equal(a.records, b.records)


def test_record_indices_are_in_range(mixed):
    scene, tree = mixed
    trace = render(scene, tree, RenderOptions(size=16)).trace
    kinds, index = unpack(trace.records)
    limits = {RecordKind.KD_NODE: len(tree.nodes), RecordKind.INDEX_ENTRY: len(tree.primitive_indices),
              RecordKind.SPHERE: len(scene.sphere_radius), RecordKind.TRIANGLE: len(scene.triangle_vertices),
              RecordKind.POLYGON: len(scene.polygon_offsets) - 1, RecordKind.PATCH: len(scene.patch_offsets) - 1,
              RecordKind.CONE: len(scene.cone_base_radius), RecordKind.MATERIAL: len(scene.material_kd),
              RecordKind.LIGHT: scene.n_lights}
    for kind, limit in limits.items():
        sel = kinds == kind
        assert np.all(index[sel] < limit), kind.name
    # an index entry is followed by the test of the primitive it names
    entry = np.flatnonzero(kinds == RecordKind.INDEX_ENTRY)
    elements = tree.primitive_indices[index[entry]]
    assert np.array_equal(kinds[entry + 1], scene.element_kind[elements] + 2)
    assert np.array_equal(index[entry + 1], scene.element_index[elements])


def test_one_sphere_hand_checked_records():
    scene = one_sphere()
    res = render(scene, options=RenderOptions(size=9))
    trace = res.trace
    centre = 4 * 9 + 4
    # root is a leaf with the one sphere: node, entry, test; shading reads the
    # material and the light; the shadow ray leaves the top of the sphere,
    # which is the top of the scene box, so it reads the root only
    expected = pack([0, 1, 2, 7, 8, 0], [0, 0, 0, 0, 0, 0])
    assert np.array_equal(trace.pixel(centre), expected)
    # a corner ray misses the scene box: it reads the root only
    assert np.array_equal(trace.pixel(0), pack([0], [0]))
    assert res.image[4, 4].sum() > res.image[0, 0].sum()
    o, d = camera_rays(scene, size=9)
    t, e, _ = closest_hit(scene, None, np.broadcast_to(o, (1, 3)), d[4:5, 4])
    assert t[0] == pytest.approx(4.0, abs=1e-12)


def test_max_depth_limits_secondary_rays(mixed):
    scene, tree = mixed
    one = render(scene, tree, RenderOptions(size=16, max_depth=1, log=False)).totals()
    more = render(scene, tree, RenderOptions(size=16, max_depth=4, log=False)).totals()
    assert one["reflection_rays"] == one["refraction_rays"] == 0
    assert more["reflection_rays"] > 0 and more["primary_hits"] == one["primary_hits"]


def test_median_tree_gives_same_image(mixed):
    scene, tree = mixed
    a = render(scene, tree, RenderOptions(size=16, log=False))
    b = render(scene, options=RenderOptions(kd_config=KdTreeConfig(builder="median"), size=16, log=False))
    hits = COUNTER_NAMES.index("primary_hits")
    assert np.array_equal(a.counters[:, hits], b.counters[:, hits])
    np.testing.assert_allclose(a.image, b.image, atol=1e-9)


def test_trace_save_load_round_trip(tmp_path, mixed):
    scene, tree = mixed
    res = render(scene, tree, RenderOptions(size=12), metadata={"note": "round trip"})
    path = res.trace.save(tmp_path / "t")
    back = AccessTrace.load(path)
    assert isinstance(back.records, np.memmap)
    assert np.array_equal(back.records, res.trace.records)
    assert np.array_equal(back.pixel_offsets, res.trace.pixel_offsets)
    assert np.array_equal(back.counters, res.trace.counters)
    assert (back.width, back.height) == (12, 12)
    meta = back.metadata
    assert meta["scene"] == scene.name and meta["note"] == "round trip"
    assert meta["kd_config"]["builder"] == "sah" and "numba" in meta["versions"]
    assert json.loads((path / "meta.json").read_text())["format_version"] == PLAIN_FORMAT_VERSION
    # saving again over the same path replaces it and leaves no temporaries
    res.trace.save(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t"]


def test_chunked_trace_equals_in_memory_trace(tmp_path, mixed):
    scene, tree = mixed
    full = render(scene, tree, RenderOptions(size=12)).trace
    budget = 4 * 997  # far below the trace's size: many chunks
    assert 4 * full.n_records > 10 * budget
    chunked = render(scene, tree, RenderOptions(size=12, memory_budget=budget), trace_path=tmp_path / "c")
    assert isinstance(chunked.trace.records, np.memmap)
    assert np.array_equal(chunked.trace.records, full.records)
    assert np.array_equal(chunked.trace.pixel_offsets, full.pixel_offsets)
    assert np.array_equal(AccessTrace.load(tmp_path / "c").counters, full.counters)
    assert chunked.trace.totals() == full.totals()
    assert np.array_equal(chunked.counters, full.counters)  # filled in the trace's file, not in memory
    with pytest.raises(ValueError, match="memory_budget"):
        render(scene, tree, RenderOptions(size=12, memory_budget=budget))


def test_counters_filled_in_their_file_survive_dropped_pages(tmp_path):
    # the writer's counters are a map of counters.npy; rows written, released (flushed, pages dropped)
    # and written again must all be in the published trace, with the right checksum
    rng = np.random.default_rng(5)
    expected = rng.integers(0, 1000, (3000, len(COUNTER_NAMES)))
    with TraceWriter(tmp_path / "t") as writer:
        counters = writer.counters_array(*expected.shape)
        for rows in np.array_split(np.arange(3000), 7):
            counters[rows] = expected[rows]
            writer.release_counter_pages()
        del counters
        writer.append(np.zeros(3000, np.uint32))
        trace = writer.finish(np.arange(3001, dtype=np.int64), None, 60, 50, {})
    assert np.array_equal(trace.counters, expected)
    assert np.array_equal(AccessTrace.load(tmp_path / "t").counters, expected)  # checksums verified on load


def test_trace_does_not_depend_on_slots_batches_or_threads(monkeypatch, mixed):
    # records are logged into a fixed slot per work item of CHUNK samples; an
    # item that overflows its slot is traced again. Slots of the median item
    # size make about half the items overflow, three items per batch give
    # several batches, the in-memory array starts tiny, and one thread
    # against all must not matter.
    scene, tree = mixed
    ref = render(scene, tree, RenderOptions(size=24))
    per_item = np.add.reduceat(np.diff(ref.trace.pixel_offsets),
                               np.arange(0, ref.trace.n_pixels, render_module.CHUNK))
    slot = int(np.median(per_item))
    monkeypatch.setattr(render_module, "BATCH_CHUNKS", 3)
    monkeypatch.setattr(render_module, "SLOT_BUFFER_BYTES", 4 * slot * 3)
    monkeypatch.setattr(render_module._GrowingRecords, "initial_capacity", 5)  # grows many times
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        one = render(scene, tree, RenderOptions(size=24))
    finally:
        numba.set_num_threads(threads)
    assert 0 < np.sum(per_item > slot) < len(per_item)
    assert np.array_equal(one.trace.records, ref.trace.records)
    assert np.array_equal(one.trace.pixel_offsets, ref.trace.pixel_offsets)
    assert np.array_equal(one.image, ref.image) and np.array_equal(one.counters, ref.counters)


def test_trace_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        AccessTrace.load(tmp_path / "missing")
    (tmp_path / "x").mkdir()
    with pytest.raises(FileNotFoundError, match="meta.json"):
        AccessTrace.load(tmp_path / "x")


def test_pack_unpack():
    kinds = np.array([0, 1, 8, 4])
    idx = np.array([0, 5, INDEX_MASK, 123456])
    rec = pack(kinds, idx)
    assert rec.dtype == np.uint32
    k, i = unpack(rec)
    assert np.array_equal(k, kinds) and np.array_equal(i, idx)
    with pytest.raises(ValueError, match="index"):
        pack(0, INDEX_MASK + 1)
    with pytest.raises(ValueError, match="kind"):
        pack(max(RecordKind) + 1, 0)


def test_render_validation(mixed):
    scene, tree = mixed
    with pytest.raises(ValueError, match="size"):
        render(scene, tree, RenderOptions(size=0))
    with pytest.raises(ValueError, match="max_depth"):
        render(scene, tree, RenderOptions(size=4, max_depth=0))
    with pytest.raises(ValueError, match="scene"):
        render("balls")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="epsilon"):
            render(scene, tree, RenderOptions(size=4, epsilon=bad))


def test_save_png(tmp_path):
    res = render(one_sphere(), options=RenderOptions(size=9, log=False))
    path = save_png(res.image, tmp_path / "img" / "one.png")
    assert path.stat().st_size > 0
    with pytest.raises(ValueError, match="shape"):
        save_png(np.zeros((4, 4)), tmp_path / "bad.png")


@pytest.mark.parametrize("field, value", [("triangle", 1e300), ("sphere", -1e120), ("triangle", -2e100)])
def test_huge_coordinates_are_refused_before_any_overflow(field, value):
    import warnings

    from tracer.scenes.model import Material, SceneBuilder
    from scene_factory import one_sphere

    b = SceneBuilder("huge")
    b.camera = one_sphere().camera
    b.material(Material((1.0, 1.0, 1.0), 1.0, 0.0, 1.0, 0.0, 1.0))
    if field == "triangle":
        b.triangle([[0.0, 0.0, 0.0], [value, 0.0, 0.0], [0.0, 1.0, 0.0]])
    else:
        b.sphere((value, 0.0, 0.0), 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy overflow warning fails the test
        with pytest.raises(ValueError, match=rf"Scene\.{field}_\w+: row 0 holds .*within \+-1e\+100"):
            render(b.build(), options=RenderOptions(size=4))


@pytest.mark.parametrize("field, value", [("size", True), ("size", 2.0), ("size", (4,)), ("size", (4, 0)),
                                          ("corner_rays", 1), ("log", "yes"), ("keep_records", None),
                                          ("kd_config", "sah"), ("max_depth", 0), ("max_depth", 65),
                                          ("memory_budget", 3), ("epsilon", 0.0), ("epsilon", True),
                                          ("workload", "1997"), ("texture_filter", "cubic")])
def test_render_options_name_the_bad_field(field, value):
    """Each bad value is refused by RenderOptions naming its field; fails if a check is dropped (e.g. a
    size of True was taken as 1, as render(scene, size=True) once was)."""
    with pytest.raises(ValueError, match=f"RenderOptions.{field}"):
        RenderOptions(**{field: value})


def test_camera_rays_refuse_a_boolean_size():
    """Fails if checked_size takes True for 1 (``isinstance(v, bool)`` dropped)."""
    from tracer.rendering.camera import camera_rays

    with pytest.raises(ValueError, match="size must be an int >= 1"):
        camera_rays(one_sphere(), True)


def test_counted_records_equal_kept_ones_within_any_budget(mixed):
    """keep_records=False gives the image, counters and record count of a kept trace, and needs no
    memory for the trace: a budget far below it, which a kept trace refuses, passes. Fails if the
    counting path keeps the records in memory (_GrowingRecords) or drops the count."""
    scene, tree = mixed
    kept = render(scene, tree, RenderOptions(size=12))
    budget = 4 * 997
    assert 4 * kept.trace.n_records > 10 * budget
    counted = render(scene, tree, RenderOptions(size=12, keep_records=False, memory_budget=budget))
    assert counted.trace is None and counted.n_records == kept.trace.n_records == kept.n_records
    assert np.array_equal(counted.image, kept.image) and np.array_equal(counted.counters, kept.counters)
    assert counted.totals() == kept.totals()
    with pytest.raises(ValueError, match=rf"memory_budget \({budget / 2**20:.4g} MB of records\); pass trace_"):
        render(scene, tree, RenderOptions(size=12, memory_budget=budget))
    assert render(scene, tree, RenderOptions(size=4, log=False)).n_records is None
