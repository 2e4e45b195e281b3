"""kd-tree: builders against brute force, node layout, hand-checked cases."""
import math

import numpy as np
import pytest

from jit_mode import shrink
from scene_factory import KINDS, one_sphere, random_rays, random_scene
from naive_kdtree import build_per_node_sah
from tracer.kd.tree import KdTreeConfig, build_kdtree, default_tree_depth
from tracer.kd.closest import closest_hit, closest_hit_bruteforce
from tracer.scenes.model import ElementKind, Material, Scene, SceneBuilder

CONFIGS = {
    "sah": KdTreeConfig(),
    "sah-noclip": KdTreeConfig(clip=False),
    "median": KdTreeConfig(builder="median"),
    "median-leaf4": KdTreeConfig(builder="median", leaf_size=4, tree_depth=6),
    "median-cycle": KdTreeConfig(builder="median", axis_rule="cycle", tree_depth=12),
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
    o, d = random_rays(shrink(3000), seed=7)
    hit_rate = _assert_same_hits(scene, tree, o, d)
    assert hit_rate > 0.1  # the test exercises hits, not only misses


@pytest.mark.parametrize("config", ["sah", "median", "median-cycle"])
def test_mixed_scene_with_ray_intervals(config):
    scene = random_scene(KINDS, n=300, seed=11, size=0.8)
    tree = build_kdtree(scene, CONFIGS[config])
    o, d = random_rays(shrink(4000), seed=3)
    rng = np.random.default_rng(5)
    tmin = rng.uniform(0, 2, len(o))
    tmax = tmin + rng.uniform(0, 10, len(o))
    _assert_same_hits(scene, tree, o, d, tmin=tmin, tmax=tmax)


def _interior_axes_by_depth(tree):
    # (depth, axis) of every interior node, walking the tree from the root
    # (below child = next node, above child in word 1; leaves have axis 3)
    out = []
    todo = [(0, 0)]
    while todo:
        node, depth = todo.pop()
        axis = int(tree.nodes[node, 1] & 3)
        if axis == 3:
            continue
        out.append((depth, axis))
        todo.append((node + 1, depth + 1))
        todo.append((int(tree.nodes[node, 1] >> 2), depth + 1))
    return out


def test_cycling_median_tree_splits_axis_depth_mod_3():
    scene = random_scene(KINDS, n=300, seed=11, size=0.8)
    cycled = _interior_axes_by_depth(build_kdtree(scene, KdTreeConfig(builder="median", axis_rule="cycle",
                                                                      tree_depth=9)))
    assert len(cycled) > 20 and max(depth for depth, _ in cycled) >= 5
    assert all(axis == depth % 3 for depth, axis in cycled)
    # on a scene 8 times wider in x than in y and z (16 x 2 x 2), the
    # longest-axis rule splits x at depths 0, 1 and 2 (hand-checked), where
    # cycling splits x, y, z
    rng = np.random.default_rng(3)
    b = SceneBuilder("wide")
    b.material(Material((1.0, 1.0, 1.0), 1.0, 0.0, 1.0, 0.0, 1.0))
    for x, y, z in rng.uniform(-1, 1, (200, 3)):
        b.sphere((8 * x, y, z), 0.02)
    wide = b.build()
    longest = _interior_axes_by_depth(build_kdtree(wide, KdTreeConfig(builder="median", tree_depth=9)))
    assert all(axis == 0 for depth, axis in longest if depth < 3)
    cycled = _interior_axes_by_depth(build_kdtree(wide, KdTreeConfig(builder="median", axis_rule="cycle",
                                                                    tree_depth=9)))
    assert all(axis == depth % 3 for depth, axis in cycled)


def test_rays_from_inside_overlapping_spheres():
    # heavily overlapping spheres: clipping drops a sphere from nodes inside it
    rng = np.random.default_rng(2)
    scene = random_scene(("sphere",), n=200, seed=4, extent=1.0, size=1.5)
    tree = build_kdtree(scene)
    o = rng.uniform(-1, 1, (shrink(3000), 3))
    d = rng.normal(size=(shrink(3000), 3))
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
    assert tree.stats["depth"] <= tree.config.tree_depth
    assert tree.stats["sah_cost"] > 0
    assert tree.config.tree_depth == default_tree_depth(scene.n_elements)


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
    ("builder", "bvh"), ("tree_depth", 0), ("tree_depth", 61), ("leaf_size", 0),
    ("traversal_cost", 0.0), ("intersection_cost", float("nan")), ("empty_bonus", 1.0),
    ("force_split", -1), ("axis_rule", "random"),
])
def test_config_validation_names_field(field, value):
    with pytest.raises(ValueError, match=field):
        KdTreeConfig(**{field: value})


# --------------------------------------------------------------------------
# SAH: every split against a brute-force evaluation of every candidate plane
# --------------------------------------------------------------------------

def _reference_shapes(scene):
    """Per element: ('sphere', centre, radius) or ('polygon', vertices), and its box."""
    shapes, lo, hi = [], [], []
    for kind, i in zip(scene.element_kind, scene.element_index):
        if kind == ElementKind.SPHERE:
            c, r = scene.sphere_center[i], abs(scene.sphere_radius[i])
            shapes.append(("sphere", c, r))
            lo.append(c - r)
            hi.append(c + r)
            continue
        if kind == ElementKind.TRIANGLE:
            v = scene.triangle_vertices[i]
        elif kind == ElementKind.POLYGON:
            v = scene.polygon_vertices[scene.polygon_offsets[i]:scene.polygon_offsets[i + 1]]
        else:
            raise ValueError(f"the reference knows spheres and polygons only, got {kind}")
        shapes.append(("polygon", v))
        lo.append(v.min(axis=0))
        hi.append(v.max(axis=0))
    return shapes, np.array(lo), np.array(hi)


def _reference_clip(shape, lo_e, hi_e, lo, hi, clip):
    """The element's box clipped to the node box [lo, hi], or None if it leaves the node."""
    a, b = np.maximum(lo_e, lo), np.minimum(hi_e, hi)
    if np.any(a > b):
        return None
    if not clip or (np.all(lo_e >= lo) and np.all(hi_e <= hi)):
        return a, b
    if shape[0] == "sphere":
        c, r = shape[1], shape[2]
        nearest = np.clip(c, lo, hi)
        farthest = np.where(np.abs(c - lo) > np.abs(hi - c), lo, hi)
        if np.sum((nearest - c) ** 2) > r * r or np.sum((farthest - c) ** 2) < r * r:
            return None  # misses the node, or the node lies inside the ball
        return a, b
    poly = list(shape[1])  # Sutherland-Hodgman against the six faces
    for axis in range(3):
        for upper in (False, True):
            bound = hi[axis] if upper else lo[axis]
            inside = (lambda x: x <= bound) if upper else (lambda x: x >= bound)
            out = []
            for k, p in enumerate(poly):
                q = poly[(k + 1) % len(poly)]
                if inside(p[axis]):
                    out.append(p)
                if inside(p[axis]) != inside(q[axis]):
                    r = p + (bound - p[axis]) / (q[axis] - p[axis]) * (q - p)
                    r[axis] = bound
                    out.append(r)
            poly = out
            if not poly:
                return None
    pts = np.array(poly)
    return np.maximum(pts.min(axis=0), lo), np.minimum(pts.max(axis=0), hi)


def _area(lo, hi):
    d = hi - lo
    return 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])


def _sah_costs(boxes_lo, boxes_hi, lo, hi, axis, sides, config):
    """SAH cost of each candidate of one axis, by counting every primitive.

    A candidate is a side of a primitive's box (float64). As in the builder,
    its counts are taken at that side and its areas at the float32 plane the
    tree would store. (Where rounding moves the plane past box sides, the
    partition then differs from the count, e.g. a side on a face of the
    float64 root box seen as an empty cut; see ``tracer.kd.split._sah_sweep``.)
    A primitive lying in the plane is put left, then right; the cheaper counts.
    """
    a = boxes_lo[:, axis][None, :]
    b = boxes_hi[:, axis][None, :]
    s = sides[:, None]
    n_left = (a < s).sum(axis=1)
    n_right = (b > s).sum(axis=1)
    n_planar = ((a == s) & (b == s)).sum(axis=1)
    planes = sides.astype(np.float32).astype(np.float64)
    left_hi, right_lo = hi.copy(), lo.copy()
    area_left, area_right = [], []
    for p in planes:
        left_hi[axis] = right_lo[axis] = p
        area_left.append(_area(lo, left_hi))
        area_right.append(_area(right_lo, hi))
    area_left, area_right = np.array(area_left), np.array(area_right)
    costs = []
    for nl, nr in ((n_left + n_planar, n_right), (n_left, n_right + n_planar)):
        c = (area_left * nl + area_right * nr) / _area(lo, hi)
        c = np.where((nl == 0) | (nr == 0), c * (1.0 - config.empty_bonus), c)
        costs.append(config.traversal_cost + config.intersection_cost * c)
    return np.minimum(*costs), planes


def _check_splits_by_brute_force(scene, config):
    """Walk the tree, rebuilding each node's primitives from the rules; returns nodes checked."""
    tree = build_kdtree(scene, config)
    cfg = tree.config
    shapes, elo, ehi = _reference_shapes(scene)
    nodes, splits = tree.nodes, tree.split_view[:, 0].astype(np.float64)
    checked = 0
    stack = [(0, tree.bounds[0].copy(), tree.bounds[1].copy(), list(range(scene.n_elements)), 0)]
    while stack:
        index, lo, hi, candidates, depth = stack.pop()
        members, blo, bhi = [], [], []
        for e in candidates:
            box = _reference_clip(shapes[e], elo[e], ehi[e], lo, hi, cfg.clip)
            if box is not None:
                members.append(e)
                blo.append(box[0])
                bhi.append(box[1])
        m = len(members)
        blo, bhi = np.array(blo).reshape(m, 3), np.array(bhi).reshape(m, 3)
        best = np.inf
        node_best = {}
        if m > cfg.leaf_size and depth < cfg.tree_depth:
            for axis in range(3):
                costs, planes = _sah_costs(blo, bhi, lo, hi, axis, np.unique(np.r_[blo[:, axis], bhi[:, axis]]), cfg)
                inside = (planes > lo[axis]) & (planes < hi[axis])
                node_best[axis] = costs[inside], planes[inside]
                best = min(best, costs[inside].min(initial=np.inf))
        splits_worth_it = best < cfg.intersection_cost * m * (1 - 1e-9)
        word1 = int(nodes[index, 1])
        if word1 & 3 == 3:
            assert sorted(members) == list(tree.primitive_indices[nodes[index, 0]:][:word1 >> 2])
            assert not splits_worth_it, f"node {index}: leaf of {m} where a split costs {best}"
            continue
        axis, split = word1 & 3, splits[index]
        assert lo[axis] < split < hi[axis]
        # random coordinates are no float32 numbers: no primitive lies in a
        # stored plane, so which side takes planar primitives does not matter
        assert not np.any((blo[:, axis] == split) & (bhi[:, axis] == split))
        if splits_worth_it:
            costs, planes = node_best[axis]
            cost = costs[planes == split].min(initial=np.inf)
            assert cost <= best * (1 + 1e-9), f"node {index}: split costs {cost}, best plane {best}"
            checked += 1
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[axis] = right_lo[axis] = split
        left = [e for e, a in zip(members, blo[:, axis]) if a < split]
        right = [e for e, b in zip(members, bhi[:, axis]) if b > split]
        stack.append((word1 >> 2, right_lo, hi, right, depth + 1))
        stack.append((index + 1, lo, left_hi, left, depth + 1))
    return checked


@pytest.mark.parametrize("config", [KdTreeConfig(), KdTreeConfig(clip=False),
                                    KdTreeConfig(leaf_size=3, empty_bonus=0.0, traversal_cost=2.0)],
                         ids=["sah", "sah-noclip", "sah-leaf3"])
@pytest.mark.parametrize("seed", [21, 22])
def test_sah_splits_are_the_cheapest_planes(seed, config):
    scene = random_scene(("sphere", "triangle", "polygon"), n=60, seed=seed, size=1.0)
    assert _check_splits_by_brute_force(scene, config) >= 10


def _lattice_scene(seed, n, step):
    """Up to ``n`` triangles, tilted quads and spheres on a coarse lattice.

    Shapes touch each other and the planes the builder picks, where
    Sutherland-Hodgman against different faces rounds differently.
    """
    rng = np.random.default_rng(seed)
    b = SceneBuilder(f"lattice-{seed}")
    b.material(Material((1.0, 1.0, 1.0), 1.0, 0.0, 1.0, 0.0, 1.0))
    for _ in range(n):
        kind = rng.integers(4)
        c = rng.integers(-12, 13, 3) * step
        if kind == 0:
            v = c + rng.integers(-6, 7, (3, 3)) * step
            if np.abs(np.cross(v[1] - v[0], v[2] - v[0])).sum() > 1e-9:
                b.triangle(v)
        elif kind == 1:
            u = rng.integers(-4, 5, 3) * step
            w = np.cross(u, rng.normal(size=3))
            w = np.round(w / max(np.abs(w).max(), 1e-9) * 4) * step
            if np.linalg.norm(np.cross(u, w)) > 1e-9:
                b.polygon(np.array([c, c + u, c + u + w, c + w]))
        else:
            b.sphere(c, rng.integers(1, 8) * step)
    b.light((0.0, 0.0, 10.0))
    return b.build()


@pytest.mark.parametrize("config", [KdTreeConfig(), KdTreeConfig(clip=False),
                                    KdTreeConfig(leaf_size=2, force_split=6),
                                    KdTreeConfig(tree_depth=6, empty_bonus=0.9)],
                         ids=["sah", "sah-noclip", "sah-force", "sah-shallow"])
def test_presorted_events_build_the_per_node_sort_tree(config):
    # the O(N log N) builder keeps events of primitives on one side of a
    # split instead of re-clipping and re-sorting them: the same trees
    for seed, scene in enumerate([random_scene(KINDS, n=200, seed=31, extent=1.0, size=1.5),
                                  random_scene(("triangle", "polygon"), n=150, seed=32, extent=2.0, size=2.5),
                                  random_scene(("sphere",), n=150, seed=33, extent=1.0, size=1.5),
                                  # keeping every one-sided box as it was (no
                                  # second clip where the shape reaches the
                                  # split face) changes these two trees
                                  _lattice_scene(11, 40, 1 / 3), _lattice_scene(3, 60, 0.125)]):
        new = build_kdtree(scene, config)
        old_nodes, old_indices, old_cost = build_per_node_sah(scene, config)
        np.testing.assert_array_equal(new.nodes, old_nodes)
        np.testing.assert_array_equal(new.primitive_indices, old_indices)
        assert new.stats["sah_cost"] == old_cost
