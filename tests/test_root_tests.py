"""Tests that take a square root: counted per pixel, and charged by the cost model.

A sphere (or cone) test takes a square root only when its quadratic has real
roots. On the study's Alpha 21164 that root is a library call, so the
renderer counts such tests (``root_tests``) and the cost model charges them
``test_root`` cycles on top of the test.
"""
import math

import numpy as np
import pytest

from scene_factory import one_sphere, random_scene
from coherence.calibration import STUDY1997_COSTS
from coherence.cost import SQUARE_ROOT_CYCLES_21164, CostModel, alpha8400, modern
from tracer.rendering.camera import camera_rays
from tracer.rendering.geometry import hit_sphere
from tracer.rendering.render import RenderOptions, render
from tracer.trace.access import COUNTER_NAMES, RecordKind, unpack


def _ray(origin, direction):
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return (*map(float, origin), *map(float, d))


@pytest.mark.parametrize("origin, direction, t, roots", [
    ((0, 0, -4), (0, 0, 1), 3.0, 1),          # straight through: near root
    ((0, 0, 0.5), (0, 0, 1), 0.5, 1),         # from inside: the far root
    ((2, 0, -4), (0, 0, 1), math.inf, 0),     # passes beside: no real root, no square root
    ((0, 0, 4), (0, 0, 1), math.inf, 1),      # sphere behind: real roots, both out of range
    ((1, 0, -4), (0, 0, 1), 4.0, 1),          # grazing: discriminant exactly 0
])
def test_hit_sphere_reports_its_square_root(origin, direction, t, roots):
    centre = np.zeros((1, 3))
    radius = np.ones(1)
    got_t, got_roots = hit_sphere(centre, radius, 0, _ray(origin, direction), 1e-9, math.inf)
    assert got_roots == roots
    assert got_t == pytest.approx(t) if math.isfinite(t) else got_t == math.inf


def test_one_sphere_root_tests_follow_the_discriminants():
    # A pixel tests the sphere with its primary ray (when the ray enters the
    # scene box) and with its shadow ray (when that does not leave the box at
    # once). A shadow ray starts on the sphere, so its quadratic always has
    # real roots; a primary ray's has them where b^2 - c >= 0, computed here
    # in numpy, apart from the renderer's code.
    scene = one_sphere()
    trace = render(scene, options=RenderOptions(size=9)).trace
    origin, directions = camera_rays(scene, size=9)
    d = directions.reshape(-1, 3)
    b = d @ origin                               # sphere at the origin, radius 1
    disc = b * b - (origin @ origin - 1.0)
    kinds, _ = unpack(trace.records)
    pixel = np.repeat(np.arange(trace.n_pixels), np.diff(trace.pixel_offsets))
    sphere_tests = np.bincount(pixel[kinds == RecordKind.SPHERE], minlength=trace.n_pixels)
    expected = sphere_tests - ((sphere_tests >= 1) & (disc < 0))
    assert ((sphere_tests >= 1) & (disc < 0)).any() and (sphere_tests >= 2).any()
    assert np.array_equal(trace.counter("root_tests").ravel(), expected)


def test_root_tests_are_a_subset_of_sphere_and_cone_tests():
    scene = random_scene(("sphere", "cone", "triangle"), n=90, seed=4)
    counters = render(scene, options=RenderOptions(size=24)).trace.counters
    col = {name: i for i, name in enumerate(COUNTER_NAMES)}
    roots = counters[:, col["root_tests"]]
    quadratic = counters[:, col["tests_sphere"]] + counters[:, col["tests_cone"]]
    assert roots.sum() > 0
    assert (roots <= quadratic).all()
    assert (roots < quadratic).any()


def test_triangles_take_no_square_roots():
    scene = random_scene(("triangle", "polygon"), n=60, seed=5)
    assert render(scene, options=RenderOptions(size=16)).trace.totals()["root_tests"] == 0


def test_cost_model_charges_root_tests():
    model = CostModel(ray=0, node_visit=0, index_read=0, test_sphere=10, test_triangle=0, test_polygon=0,
                      test_patch=0, test_cone=0, shading=0, light_read=0, test_root=7)
    counters = np.zeros((2, len(COUNTER_NAMES)), np.int64)
    counters[:, COUNTER_NAMES.index("tests_sphere")] = [4, 4]
    counters[:, COUNTER_NAMES.index("root_tests")] = [0, 3]
    assert model.compute_cycles(counters, COUNTER_NAMES).tolist() == [40.0, 61.0]


def test_presets_and_study_structure_price_the_root():
    assert alpha8400().test_root == SQUARE_ROOT_CYCLES_21164
    assert modern().test_root == 0.0
    assert CostModel().test_root == 0.0
    # fixed in the study's structure, never fitted
    assert STUDY1997_COSTS.fixed == {"test_root": SQUARE_ROOT_CYCLES_21164}
    assert all("test_root" not in cost.multiples for cost in STUDY1997_COSTS.fitted)
