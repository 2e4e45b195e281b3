"""SPD reference counts (Havran 1999) with corner rays and SPD rules (depth 5).

The published counts come out with secondary and shadow rays ignoring hits
within ``SPD_EPSILON`` (0.01) of their origin, as the reference tracer did.

Reference: ``tests/data/spd/README.md`` (a copy of ../shared/reference/spd). Counts are deterministic,
so these tests pin them.
"""
from pathlib import Path

import pytest

from tracer.nff import read_nff
from tracer.render import SPD_EPSILON, render
from tracer.scenes import load

# Copies of ../shared/reference/spd (output of the original SPD generators).
SPD = Path(__file__).resolve().parent / "data" / "spd"

needs_reference = pytest.mark.skipif(not (SPD / "tetra.nff").is_file(), reason="SPD reference files not found")


@pytest.fixture(scope="module")
def tetra_counts():
    return render(read_nff(SPD / "tetra.nff", max_depth=5), corner_rays=True, log=False,
                  epsilon=SPD_EPSILON).totals()


@pytest.fixture(scope="module")
def balls_counts():
    return render(read_nff(SPD / "balls.nff", max_depth=5), corner_rays=True, log=False,
                  epsilon=SPD_EPSILON).totals()


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
    res = render(scene, size=32, log=False)
    t = res.totals()
    assert t["intersection_tests"] / t["rays"] < 350
    assert t["primary_hits"] > 0.2 * t["primary_rays"]
