"""Workload presets: selection, one tree rule for every scene, each lever against a reference."""
import numpy as np
import pytest

from jit_mode import shrink
from scene_factory import KINDS, random_rays, random_scene
from tracer.scenes import catalog as scenes
from tracer.kd.closest import closest_hit, closest_hit_bruteforce
from tracer.kd.tree import KdTreeConfig, build_kdtree
from tracer.trace.records import COUNTER_NAMES, COUNTER_OF_KIND, RecordKind, WRITE_FLAG, unpack
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.study import PAPER_SCENES
from tracer.rendering.workload import WORKLOADS, Workload, get_workload


@pytest.fixture(scope="module")
def mixed():
    # every primitive kind, reflection and refraction, two lights
    return random_scene(KINDS, n=120, seed=21, size=0.9, lights=2)


def _counters(result):
    return {name: result.counters[:, i] for i, name in enumerate(COUNTER_NAMES)}


def test_get_workload_by_name_and_errors():
    assert get_workload("modern") is WORKLOADS["modern"]
    assert get_workload(WORKLOADS["study1997"]) is WORKLOADS["study1997"]
    with pytest.raises(ValueError, match="modern, study1997"):
        get_workload("study1998")
    with pytest.raises(ValueError, match="workload"):
        get_workload(None)


@pytest.mark.parametrize("field,kwargs", [
    ("name", {"name": ""}), ("kd_config", {"kd_config": "sah"}),
    ("shadow_nearest", {"shadow_nearest": 1}), ("log_ray_data", {"log_ray_data": "yes"}),
])
def test_workload_validation_names_field(field, kwargs):
    args = {"name": "x", "kd_config": KdTreeConfig()} | kwargs
    with pytest.raises(ValueError, match=f"Workload.{field}"):
        Workload(**args)


def test_modern_is_todays_tracer():
    modern = WORKLOADS["modern"]
    assert modern.kd_config == KdTreeConfig()
    assert not modern.shadow_nearest and not modern.log_ray_data


def test_study_workload_has_the_same_parameters_for_every_paper_scene():
    metadata = []
    for name in PAPER_SCENES:
        trace = render(scenes.load(name), options=RenderOptions(size=4, workload="study1997")).trace
        metadata.append((trace.metadata["kd_config"], trace.metadata["workload"]))
    assert all(entry == metadata[0] for entry in metadata)
    assert metadata[0][1]["name"] == "study1997"
    assert metadata[0][0] == WORKLOADS["study1997"].kd_config.to_dict()


def test_default_render_is_the_modern_workload(mixed):
    default = render(mixed, options=RenderOptions(size=12))
    modern = render(mixed, options=RenderOptions(size=12, workload="modern"))
    assert np.array_equal(default.trace.records, modern.trace.records)
    assert np.array_equal(default.counters, modern.counters)
    assert default.trace.metadata["workload"]["name"] == "modern"
    kinds, _ = unpack(default.trace.records)
    assert kinds.max() <= RecordKind.LIGHT
    assert not np.any(default.trace.records & np.uint32(WRITE_FLAG))


def test_shadow_nearest_changes_test_counts_not_the_picture(mixed):
    tree = build_kdtree(mixed)
    anyhit = render(mixed, tree, RenderOptions(size=20, workload=Workload("a", KdTreeConfig())))
    nearest = render(mixed, tree, RenderOptions(size=20, workload=Workload("n", KdTreeConfig(), shadow_nearest=True)))
    assert np.array_equal(anyhit.image, nearest.image)
    a, n = _counters(anyhit), _counters(nearest)
    assert np.array_equal(a["shadow_blocked"], n["shadow_blocked"])
    assert a["shadow_blocked"].sum() > 0
    assert np.all(n["index_reads"] >= a["index_reads"])
    assert n["index_reads"].sum() > a["index_reads"].sum()


@pytest.mark.parametrize("config", [WORKLOADS["study1997"].kd_config,
                                    KdTreeConfig(builder="median", axis_rule="cycle", tree_depth=10, leaf_size=4)])
def test_study_tree_finds_the_brute_force_nearest_hit_on_segments(config):
    # a shadow ray looking for the nearest hit is a closest-hit query on the
    # segment (epsilon, distance to the light)
    scene = random_scene(KINDS, n=200, seed=3, size=0.8)
    tree = build_kdtree(scene, config)
    o, d = random_rays(shrink(2000), seed=9)
    rng = np.random.default_rng(4)
    tmin = np.full(len(o), 1e-6)
    tmax = rng.uniform(0.5, 8.0, len(o))
    t1, e1, _ = closest_hit(scene, tree, o, d, tmin=tmin, tmax=tmax)
    t2, e2 = closest_hit_bruteforce(scene, o, d, tmin=tmin, tmax=tmax)
    assert np.array_equal(np.isfinite(t1), np.isfinite(t2))
    hit = np.isfinite(t2)
    assert 0.05 < hit.mean() < 0.95
    np.testing.assert_allclose(t1[hit], t2[hit], rtol=1e-12)


def test_study_tree_tests_repeat_objects_in_several_leaves():
    # no mailboxing: a ray through a sphere spanning many leaves tests it in
    # each leaf it visits that lists it, counted against the tree's own leaves
    scene = random_scene(("sphere",), n=40, seed=2, size=1.2)
    config = KdTreeConfig(builder="median", tree_depth=8, leaf_size=1)
    result = render(scene, options=RenderOptions(size=16, workload=Workload("w", config)))
    trace = result.trace
    kinds, index = unpack(trace.records)
    leaf_entries = index[kinds == RecordKind.INDEX_ENTRY]
    primitive_indices = result.tree.primitive_indices
    tested = index[kinds == RecordKind.SPHERE]
    # every test follows the index entry it came from: the same element
    assert np.array_equal(primitive_indices[leaf_entries], tested)
    c = _counters(result)
    assert c["tests_sphere"].sum() > len(np.unique(tested))
    assert np.array_equal(c["tests_sphere"], c["index_reads"])


def test_ray_data_records_match_counters_and_the_ray_tree(mixed):
    result = render(mixed, options=RenderOptions(size=(14, 10), workload="study1997"))
    trace = result.trace
    kinds, index = unpack(trace.records)
    writes = (trace.records & np.uint32(WRITE_FLAG)) != 0
    pixel = np.repeat(np.arange(trace.n_pixels), np.diff(trace.pixel_offsets))
    for kind, name in COUNTER_OF_KIND.items():
        per_pixel = np.bincount(pixel[kinds == kind], minlength=trace.n_pixels)
        assert np.array_equal(per_pixel, result.counters[:, COUNTER_NAMES.index(name)]), name
    c = _counters(result)
    traced = c["primary_rays"] + c["reflection_rays"] + c["refraction_rays"]
    hits = c["primary_hits"] + c["reflection_hits"] + c["refraction_hits"]
    assert c["reflection_rays"].sum() > 0 and c["refraction_rays"].sum() > 0

    def per_pixel(mask):
        return np.bincount(pixel[mask], minlength=trace.n_pixels)

    stack = kinds == RecordKind.RAY_STACK
    assert np.array_equal(per_pixel(stack & writes), traced)  # one push per ray traced
    assert np.array_equal(per_pixel(stack & ~writes), traced)  # and one pop
    hit_record = kinds == RecordKind.HIT_RECORD
    assert np.array_equal(per_pixel(hit_record & writes), traced)
    assert np.array_equal(per_pixel(hit_record & ~writes), hits)
    temps = kinds == RecordKind.SHADING_TEMP
    assert np.array_equal(per_pixel(temps & writes), hits)
    assert np.array_equal(per_pixel(temps & ~writes), hits + c["shadow_rays"])
    frame = kinds == RecordKind.FRAME_BUFFER
    assert np.all(writes[frame])
    assert np.array_equal(index[frame], np.arange(trace.n_pixels))
    # only the tracer's own data is ever written
    assert np.all(kinds[writes] >= RecordKind.RAY_STACK)
    # a pop reads the slot the last push wrote, the pixel's frame-buffer write comes last
    for p in range(trace.n_pixels):
        records = trace.records[trace.pixel_offsets[p]:trace.pixel_offsets[p + 1]]
        k, i = unpack(records)
        w = (records & np.uint32(WRITE_FLAG)) != 0
        stack_slots = []
        for kind, slot, write in zip(k[k == RecordKind.RAY_STACK], i[k == RecordKind.RAY_STACK],
                                     w[k == RecordKind.RAY_STACK]):
            if write:
                assert slot == len(stack_slots)
                stack_slots.append(slot)
            else:
                assert slot == stack_slots.pop()
        assert not stack_slots
        assert k[-1] == RecordKind.FRAME_BUFFER and i[-1] == p
    counts = trace.metadata["record_counts"]
    assert counts["frame_buffer"] == trace.n_pixels
    assert index[stack].max() < counts["ray_stack"] and index[hit_record].max() < counts["hit_record"]


def test_study_image_equals_modern_image_on_the_same_tree(mixed):
    tree = build_kdtree(mixed, WORKLOADS["study1997"].kd_config)
    modern = render(mixed, tree, RenderOptions(size=12, workload="modern"))
    study = render(mixed, tree, RenderOptions(size=12, workload="study1997"))
    assert np.array_equal(modern.image, study.image)


def _leaf_boxes(tree):
    # (lo, hi, count) of every leaf, walking the tree from the root box
    leaves = []
    todo = [(0, tree.bounds[0].copy(), tree.bounds[1].copy())]
    split = tree.nodes.view(np.float32)
    while todo:
        node, lo, hi = todo.pop()
        word = int(tree.nodes[node, 1])
        axis = word & 3
        if axis == 3:
            leaves.append((lo, hi, word >> 2))
            continue
        plane = float(split[node, 0])
        below_hi = hi.copy()
        below_hi[axis] = plane
        above_lo = lo.copy()
        above_lo[axis] = plane
        todo.append((node + 1, lo, below_hi))
        todo.append((word >> 2, above_lo, hi))
    return leaves


def _slab_overlaps(origin, direction, lo, hi, tmin):
    # whether the ray's interval (tmin, inf) meets the box (an obvious slab test)
    t0, t1 = tmin, np.inf
    for a in range(3):
        if direction[a] == 0.0:
            if not lo[a] <= origin[a] <= hi[a]:
                return False
            continue
        ta, tb = sorted(((lo[a] - origin[a]) / direction[a], (hi[a] - origin[a]) / direction[a]))
        t0, t1 = max(t0, ta), min(t1, tb)
    return t0 <= t1


@pytest.mark.parametrize("config", [WORKLOADS["study1997"].kd_config,
                                    KdTreeConfig(builder="median", tree_depth=10, leaf_size=2)])
def test_missing_rays_test_every_object_of_every_leaf_they_cross(config):
    # without mailboxes a ray that hits nothing tests every entry of every
    # leaf its line crosses, however often an object is listed: the slow
    # reference sums the leaf counts of the leaves a slab test says it meets
    from tracer.rendering.camera import camera_rays

    scene = random_scene(("sphere", "triangle"), n=60, seed=5, size=0.5, extent=3.0)
    tree = build_kdtree(scene, config)
    assert tree.stats["references"] > 60  # objects listed in several leaves
    size = 12
    result = render(scene, tree, RenderOptions(size=size, log=False, max_depth=1, workload=Workload("w", config)))
    c = _counters(result)
    origin, directions = camera_rays(scene, size=size)
    leaves = _leaf_boxes(tree)
    missed = np.flatnonzero(c["primary_hits"] == 0)
    assert len(missed) > 10
    crossing = 0
    for p in missed:
        d = directions.reshape(-1, 3)[p]
        expected = sum(count for lo, hi, count in leaves
                       if _slab_overlaps(origin, d, lo, hi, scene.camera.hither))
        assert c["index_reads"][p] == expected
        crossing += expected > 0
    assert crossing > 5  # the check covers rays through the tree, not only past it
