"""kd-tree: builders against brute force, node layout, hand-checked cases."""
import math

import numpy as np
import pytest

from scene_factory import KINDS, one_sphere, random_rays, random_scene
from tracer.kdtree import KdTreeConfig, build_kdtree, default_max_depth
from tracer.render import closest_hit, closest_hit_bruteforce
from tracer.scene import Scene

CONFIGS = {
    "sah": KdTreeConfig(),
    "sah-noclip": KdTreeConfig(clip=False),
    "median": KdTreeConfig(builder="median"),
    "median-leaf4": KdTreeConfig(builder="median", leaf_size=4, max_depth=6),
}


def _assert_same_hits(scene, tree, o, d, **kw):
    t1, e1, _ = closest_hit(scene, tree, o, d, **kw)
    t2, e2 = closest_hit_bruteforce(scene, o, d, **kw)
    assert np.array_equal(np.isfinite(t1), np.isfinite(t2))
    hit = np.isfinite(t2)
    np.testing.assert_allclose(t1[hit], t2[hit], rtol=1e-12, atol=0)
    differ = e1 != e2
    # a different element only where two surfaces coincide at the hit
    assert np.all(np.abs(t1[differ] - t2[differ]) <= 1e-9 * (1 + np.abs(t2[differ])))
    return hit.mean()


@pytest.mark.parametrize("config", CONFIGS, ids=list(CONFIGS))
@pytest.mark.parametrize("kind", KINDS)
def test_closest_hit_matches_brute_force(kind, config):
    scene = random_scene((kind,), n=80, seed=KINDS.index(kind))
    tree = build_kdtree(scene, CONFIGS[config])
    o, d = random_rays(3000, seed=7)
    hit_rate = _assert_same_hits(scene, tree, o, d)
    assert hit_rate > 0.1  # the test exercises hits, not only misses


@pytest.mark.parametrize("config", ["sah", "median"])
def test_mixed_scene_with_ray_intervals(config):
    scene = random_scene(KINDS, n=300, seed=11, size=0.8)
    tree = build_kdtree(scene, CONFIGS[config])
    o, d = random_rays(4000, seed=3)
    rng = np.random.default_rng(5)
    tmin = rng.uniform(0, 2, len(o))
    tmax = tmin + rng.uniform(0, 10, len(o))
    _assert_same_hits(scene, tree, o, d, tmin=tmin, tmax=tmax)


def test_rays_from_inside_overlapping_spheres():
    # heavily overlapping spheres: clipping drops a sphere from nodes inside it
    rng = np.random.default_rng(2)
    scene = random_scene(("sphere",), n=200, seed=4, extent=1.0, size=1.5)
    tree = build_kdtree(scene)
    o = rng.uniform(-1, 1, (3000, 3))
    d = rng.normal(size=(3000, 3))
    _assert_same_hits(scene, tree, o, d)


def test_node_layout_and_stats():
    scene = random_scene(KINDS, n=200, seed=1)
    tree = build_kdtree(scene)
    nodes = tree.nodes
    assert nodes.dtype == np.uint32 and nodes.shape[1] == 2 and nodes.itemsize * 2 == 8
    assert tree.primitive_indices.dtype == np.int32
    flags = nodes[:, 1] & 3
    leaves = flags == 3
    assert tree.stats["nodes"] == len(nodes)
    assert tree.stats["leaves"] == leaves.sum()
    # interior: above child index beyond the node, below child is the next node
    interior = np.flatnonzero(~leaves)
    above = (nodes[interior, 1] >> 2).astype(np.int64)
    assert np.all(above > interior + 1) and np.all(above < len(nodes))
    split = tree.split_view[interior, 0].astype(np.float64)
    lo, hi = tree.bounds
    assert np.all(split >= lo[flags[interior]]) and np.all(split <= hi[flags[interior]])
    # leaves cover primitive_indices exactly once each
    off = nodes[leaves, 0].astype(np.int64)
    cnt = (nodes[leaves, 1] >> 2).astype(np.int64)
    covered = np.zeros(len(tree.primitive_indices), np.int64)
    for a, c in zip(off, cnt):
        covered[a:a + c] += 1
    assert np.all(covered == 1)
    assert set(np.unique(tree.primitive_indices)) == set(range(scene.n_elements))
    assert tree.stats["references"] == cnt.sum()
    assert tree.stats["depth"] <= tree.config.max_depth
    assert tree.stats["sah_cost"] > 0
    assert tree.config.max_depth == default_max_depth(scene.n_elements)


def test_one_sphere_known_distance_and_missing_ray_visits_root():
    scene = one_sphere(radius=1.0)
    tree = build_kdtree(scene)
    o = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 5.0], [0.3, 0.2, 0.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    t, e, visits = closest_hit(scene, tree, o, d)
    assert t[0] == pytest.approx(4.0, abs=1e-12) and e[0] == 0
    assert np.isinf(t[1]) and e[1] == -1 and visits[1] == 1  # away from the box: root only
    assert t[2] == pytest.approx(math.sqrt(1 - 0.13), abs=1e-12)  # from inside


def test_empty_scene_and_single_leaf():
    scene = Scene()
    tree = build_kdtree(scene)
    assert tree.stats["nodes"] == 1 and tree.stats["leaves"] == 1
    t, e, visits = closest_hit(scene, tree, [[0, 0, 0]], [[1, 0, 0]])
    assert np.isinf(t[0]) and e[0] == -1 and visits[0] == 1


def test_sah_tree_is_cheaper_than_median_by_its_own_measure():
    scene = random_scene(("sphere",), n=400, seed=9)
    sah = build_kdtree(scene, KdTreeConfig())
    med = build_kdtree(scene, KdTreeConfig(builder="median"))
    assert sah.stats["sah_cost"] < med.stats["sah_cost"]


@pytest.mark.parametrize("field,value", [
    ("builder", "bvh"), ("max_depth", 0), ("max_depth", 61), ("leaf_size", 0),
    ("traversal_cost", 0.0), ("intersection_cost", float("nan")), ("empty_bonus", 1.0),
    ("force_split", -1),
])
def test_config_validation_names_field(field, value):
    with pytest.raises(ValueError, match=field):
        KdTreeConfig(**{field: value})
