"""SPD reference counts (Havran 1999) with corner rays and SPD rules (depth 5).

The published counts come out with secondary and shadow rays ignoring hits
within ``SPD_EPSILON`` (0.01) of their origin, as the reference tracer did.

Reference: ``tests/data/spd/README.md`` (a copy of ../shared/reference/spd). Counts are deterministic,
so these tests pin them.
"""
from pathlib import Path

import numpy as np
import pytest

from tracer.scenes.nff import read_nff
from tracer.rendering.render import SPD_EPSILON, RenderOptions, render
from tracer.scenes.catalog import load

# Copies of ../shared/reference/spd (output of the original SPD generators).
SPD = Path(__file__).resolve().parent / "data" / "spd"

needs_reference = pytest.mark.skipif(not (SPD / "tetra.nff").is_file(), reason="SPD reference files not found")


@pytest.fixture(scope="module")
def tetra_counts():
    return render(read_nff(SPD / "tetra.nff", max_depth=5),
                  options=RenderOptions(corner_rays=True, log=False, epsilon=SPD_EPSILON)).totals()


@pytest.fixture(scope="module")
def balls_counts():
    return render(read_nff(SPD / "balls.nff", max_depth=5),
                  options=RenderOptions(corner_rays=True, log=False, epsilon=SPD_EPSILON)).totals()


@needs_reference
@pytest.mark.jit_only  # two 513x513 renders
def test_tetra_primary_hits_exact(tetra_counts):
    assert tetra_counts["primary_rays"] == 513 * 513
    assert tetra_counts["primary_hits"] == 49_950
    assert tetra_counts["reflection_rays"] == tetra_counts["refraction_rays"] == 0


@needs_reference
@pytest.mark.jit_only  # two 513x513 renders
def test_tetra_shadow_rays_within_one(tetra_counts):
    # float64 arithmetic gives 46,261; see the xfail below
    assert abs(tetra_counts["shadow_rays"] - 46_262) <= 1
    assert abs(tetra_counts["shadow_blocked"] - 5_538) / 5_538 < 0.01  # 5,551


@needs_reference
@pytest.mark.jit_only  # two 513x513 renders
@pytest.mark.xfail(reason="46,261 is the exact-arithmetic count: ray 92058 (column 231, row 179) "
                          "enters tetrahedron face 633 (facing away from the light) less than 1e-6 from its "
                          "edge with face 635; rounding the camera directions to float32 makes it "
                          "slip past the edge onto face 636, which faces the light (46,262), but "
                          "float32 intersection arithmetic lands on 635 instead (46,261)", strict=False)
def test_tetra_shadow_rays_exact(tetra_counts):
    assert tetra_counts["shadow_rays"] == 46_262


@needs_reference
@pytest.mark.jit_only  # two 513x513 renders
def test_balls_primary_and_shadow_within_two_percent(balls_counts):
    assert balls_counts["primary_hits"] == 263_169
    assert abs(balls_counts["shadow_rays"] / 959_244 - 1) < 0.02
    assert abs(balls_counts["shadow_blocked"] / 285_178 - 1) < 0.02


@needs_reference
@pytest.mark.jit_only  # two 513x513 renders
def test_balls_secondary_within_two_percent(balls_counts):
    # 179,778 and 134,274 (-0.06%, -0.07%); the default tolerance gives
    # 175,921 and 126,753 (-2.2%, -5.7%)
    assert abs(balls_counts["reflection_rays"] / 179_884 - 1) < 0.02
    assert abs(balls_counts["reflection_hits"] / 134_368 - 1) < 0.02


def test_shell_tree_does_not_degenerate():
    # ~90 nearly coincident sphere surfaces pass near every point of the
    # shell, so a few hundred tests per ray are inherent (the study counted
    # 212e6 tests); clipping spheres that enclose a node keeps it there
    scene = load("shell")
    res = render(scene, options=RenderOptions(size=32, log=False))
    t = res.totals()
    assert t["intersection_tests"] / t["rays"] < 350
    assert t["primary_hits"] > 0.2 * t["primary_rays"]


# ------------------------------------------------------------------ concave polygons
def _even_odd_reference(scene, origin, directions, chunk=96):
    """Nearest polygon each ray hits, by brute force in float64, sharing no code with the renderer.

    Each polygon's plane comes from the principal axes of its corners, hit points are
    written in that plane's own 2-D basis, and a point is inside when a
    half-line from it crosses an odd number of edges. Returns the polygon
    index per ray (-1: no polygon).
    """
    offsets, vertices = scene.polygon_offsets, scene.polygon_vertices
    counts = np.diff(offsets)
    width = int(counts.max())
    corners = vertices[offsets[:-1, None] + np.minimum(np.arange(width), counts[:, None] - 1)]  # (P, W, 3)
    centroid = corners.mean(axis=1)
    spread = corners - centroid[:, None, :]
    _, axes = np.linalg.eigh(np.einsum("pwi,pwj->pij", spread, spread))  # principal axes, smallest first
    normal, axis_u, axis_v = axes[:, :, 0], axes[:, :, 1], axes[:, :, 2]
    flat = np.stack([np.einsum("pwk,pk->pw", corners - centroid[:, None], axis_u),
                     np.einsum("pwk,pk->pw", corners - centroid[:, None], axis_v)], axis=2)  # (P, W, 2)
    low, high = flat.min(axis=1), flat.max(axis=1)
    directions = directions.reshape(-1, 3)
    result = np.full(len(directions), -1)
    for start in range(0, len(directions), chunk):
        d = directions[start:start + chunk]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("pk,pk->p", centroid - origin, normal)[None, :] / (d @ normal.T)       # (R, P)
        points = origin + t[:, :, None] * d[:, None, :] - centroid[None]                       # (R, P, 3)
        u = np.einsum("rpk,pk->rp", points, axis_u)
        v = np.einsum("rpk,pk->rp", points, axis_v)
        ray, polygon = np.nonzero((t > 1e-9) & np.isfinite(t) & (u >= low[:, 0]) & (u <= high[:, 0])
                                  & (v >= low[:, 1]) & (v <= high[:, 1]))
        if ray.size == 0:
            continue
        pu, pv = u[ray, polygon][:, None], v[ray, polygon][:, None]
        ku, kv = flat[polygon, :, 0], flat[polygon, :, 1]
        ju, jv = np.roll(ku, 1, axis=1), np.roll(kv, 1, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            crossing = ((kv > pv) != (jv > pv)) & (pu < ku + (pv - kv) * (ju - ku) / (jv - kv))
        inside = crossing.sum(axis=1) % 2 == 1
        ray, polygon, distance = ray[inside], polygon[inside], t[ray[inside], polygon[inside]]
        order = np.lexsort((distance, ray))
        ray, polygon = ray[order], polygon[order]
        first = np.concatenate(([True], ray[1:] != ray[:-1]))
        result[start + ray[first]] = polygon[first]
    return result


def _primary_agreement(scene, size):
    from tracer.rendering.camera import camera_rays
    from tracer.kd.closest import closest_hit
    from tracer.scenes.model import ElementKind

    origin, directions = camera_rays(scene, size)
    ours = closest_hit(scene, None, np.broadcast_to(origin, directions.reshape(-1, 3).shape),
                       directions.reshape(-1, 3)).element
    polygon_of_element = np.where(scene.element_kind == ElementKind.POLYGON, scene.element_index, -1)
    ours = np.where(ours >= 0, polygon_of_element[np.maximum(ours, 0)], -1)
    reference = _even_odd_reference(scene, origin, directions)
    return float(np.mean(ours == reference)), int((reference >= 0).sum()), int((ours >= 0).sum())


def _flat_scene(outline, size=2.0):
    from tracer.scenes.model import Camera, SceneBuilder

    builder = SceneBuilder("outline")
    builder.camera = Camera(eye=(0.3, -0.2, 6.0), look_at=(0.0, 0.0, 0.0), up=(0, 1, 0), angle=45,
                            resolution=(64, 64))
    builder.light((0, 0, 10))
    builder.polygon(np.column_stack([np.asarray(outline, dtype=float) * size, np.zeros(len(outline))]))
    builder.polygon([(-3, -3, -1), (3, -3, -1), (3, 3, -1), (-3, 3, -1)])  # a convex floor behind it
    return builder.build()


L_SHAPE = [(-1, -1), (1, -1), (1, -0.4), (-0.4, -0.4), (-0.4, 1), (-1, 1)]
STAR = [(np.cos(a) * r, np.sin(a) * r) for k in range(10)
        for a, r in [(np.pi / 2 + k * np.pi / 5, 1.0 if k % 2 == 0 else 0.38)]]
PENTAGRAM = [(np.cos(np.pi / 2 + k * 4 * np.pi / 5), np.sin(np.pi / 2 + k * 4 * np.pi / 5)) for k in range(5)]


@pytest.mark.parametrize("outline", [L_SHAPE, STAR, PENTAGRAM], ids=["L", "star", "pentagram"])
def test_concave_outlines_match_an_independent_even_odd_test(outline):
    agreement, reference_hits, our_hits = _primary_agreement(_flat_scene(outline), 64)
    assert agreement >= 0.999 and reference_hits == our_hits


@pytest.mark.parametrize("outline", [L_SHAPE, STAR], ids=["L", "star"])
def test_concave_patches_match_an_independent_even_odd_test(outline):
    # the same outline as a patch (vertex normals): element 0 is the patch, element 1 the floor, as
    # polygons 0 and 1 are in the all-polygon twin the reference reads
    from tracer.rendering.camera import camera_rays
    from tracer.kd.closest import closest_hit
    from tracer.scenes.model import Camera, SceneBuilder

    twin = _flat_scene(outline)
    builder = SceneBuilder("outline-patch")
    builder.camera = twin.camera
    builder.light((0, 0, 10))
    corners = np.column_stack([np.asarray(outline, dtype=float) * 2.0, np.zeros(len(outline))])
    builder.patch(corners, np.tile([0.0, 0.2, 1.0], (len(outline), 1)) / np.hypot(0.2, 1.0))
    builder.polygon([(-3, -3, -1), (3, -3, -1), (3, 3, -1), (-3, 3, -1)])
    scene = builder.build()
    origin, directions = camera_rays(scene, 64)
    ours = closest_hit(scene, None, np.broadcast_to(origin, directions.reshape(-1, 3).shape),
                       directions.reshape(-1, 3)).element
    reference = _even_odd_reference(twin, origin, directions)
    assert (reference == 0).sum() > 500
    assert np.mean(ours == reference) >= 0.999


def test_convexity_is_decided_per_polygon():
    from tracer.rendering.geometry import CONVEX, prepare_geometry

    square = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    nearly = [(-1, -1), (0, -1 - 1e-13), (1, -1), (1, 1), (-1, 1)]  # a collinear vertex, float noise
    axes = [prepare_geometry(_flat_scene(o)).polygon_even_odd_axis[0] for o in (square, nearly, L_SHAPE, STAR)]
    assert axes == [CONVEX, CONVEX, 2, 2]


@pytest.mark.skipif(not (SPD / "gears.nff").is_file(), reason="SPD reference files not found")
@pytest.mark.jit_only  # 4096 primary rays against 9345 polygons
def test_gears_concave_faces_match_an_independent_even_odd_test():
    # 128 concave 144-gons (gear faces); before the even-odd path they were drawn as their convex core
    # and 55.5% of primary rays agreed at 128x128 (100% now: _primary_agreement(gears, 128)).
    agreement, reference_hits, our_hits = _primary_agreement(read_nff(SPD / "gears.nff"), 64)
    assert agreement >= 0.999, (agreement, reference_hits, our_hits)
