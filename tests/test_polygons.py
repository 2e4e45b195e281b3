"""Which polygons are convex (tracer.rendering.polygons.polygon_even_odd_axes), against a slow obvious reference."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from tracer.rendering.polygons import CONVEX, CONVEXITY_TOLERANCE, polygon_even_odd_axes


def _axes_reference(offsets, vertices, normals):
    """Every vertex against every edge's half-plane in plain Python; the dropped axis of each concave one."""
    axes = []
    for i in range(len(offsets) - 1):
        corners = [vertices[k] for k in range(offsets[i], offsets[i + 1])]
        n = len(corners)
        extent = max(max(c[axis] for c in corners) - min(c[axis] for c in corners) for axis in range(3))
        concave = False
        for e in range(n):
            edge = corners[(e + 1) % n] - corners[e]
            for vertex in corners:
                side = float(np.dot(np.cross(edge, vertex - corners[e]), normals[i]))
                concave |= n > 3 and side < -CONVEXITY_TOLERANCE * extent ** 2
        axes.append(int(np.argmax(np.abs(normals[i]))) if concave else CONVEX)
    return axes


def _random_polygons(rng, count):
    """Star-shaped outlines (sorted angles, random radii: some convex, most not) in random planes."""
    parts, normals = [], []
    for _ in range(count):
        n = int(rng.integers(3, 12))
        angles = np.sort(rng.uniform(0, 2 * np.pi, n))
        radii = 1.0 if rng.random() < 0.4 else rng.uniform(0.3, 1.0, n)
        flat = np.column_stack([radii * np.cos(angles), radii * np.sin(angles), np.zeros(n)])
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        parts.append(flat @ rotation.T * rng.uniform(0.1, 100) + rng.normal(size=3))
        normals.append(rotation[:, 2])
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
    return offsets, np.concatenate(parts), np.array(normals)


@pytest.mark.parametrize("seed", range(4))
def test_convexity_matches_a_python_loop_on_random_polygons(seed):
    """Fails if the kernel's test is changed, e.g. ``side < -limit`` made ``side < limit``."""
    offsets, vertices, normals = _random_polygons(np.random.default_rng(seed), 60)
    axes = polygon_even_odd_axes(offsets, vertices, normals)
    assert axes.tolist() == _axes_reference(offsets, vertices, normals)
    assert CONVEX in axes and set(axes.tolist()) - {CONVEX}  # both kinds were tried


def test_hand_checked_polygons():
    """A square is convex, an L drops z, an L in the x = 0 plane drops x; fails if the dropped axis
    were taken from the smallest normal component (``abs(...) > abs(...)`` made ``<``)."""
    square = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    ell = [(0, 0, 0), (2, 0, 0), (2, 1, 0), (1, 1, 0), (1, 2, 0), (0, 2, 0)]
    ell_x = [(0, y, z) for y, z, _ in ell]
    vertices = np.array(square + ell + ell_x, dtype=np.float64)
    offsets = np.array([0, 4, 10, 16])
    normals = np.array([(0, 0, 1), (0, 0, 1), (1, 0, 0)], dtype=np.float64)
    assert polygon_even_odd_axes(offsets, vertices, normals).tolist() == [CONVEX, 2, 0]


def test_a_large_polygon_takes_no_pairwise_table():
    """A 3,000-vertex concave polygon's test allocates under 1 MB; fails on an (n, n, 3) table of
    edge-vertex pairs (216 MB here), as the test once built."""
    n = 3000
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    radii = np.where(np.arange(n) % 2, 1.0, 0.6)
    vertices = np.column_stack([radii * np.cos(angles), radii * np.sin(angles), np.zeros(n)])
    offsets, normals = np.array([0, n]), np.array([[0.0, 0.0, 1.0]])
    polygon_even_odd_axes(offsets[:1], vertices[:0], normals[:0])  # compile outside the measurement
    tracemalloc.start()
    try:
        axes = polygon_even_odd_axes(offsets, vertices, normals)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert axes.tolist() == [2]
    assert peak < 1 << 20, peak
