"""Eric Haines's Standard Procedural Databases used by the study.

Independent implementations, from the published constructions, of the three
SPD generators the paper used: ``balls`` (sphereflake), ``tetra``
(Sierpinski tetrahedron) and ``shells`` (Pickover seashell). At their default
size factors they reproduce the generators' reference output object by
object, in the same order (depth-first pre-order for balls and tetra), with
the same view, lights, background and materials; the reference files print 6
significant digits, these scenes keep full double precision.

The scenes carry the SPD procedure's maximum depth of 5;
:func:`tracer.scenes.catalog.load` sets the paper's depth (2) for the study.
"""
from __future__ import annotations

import math

import numpy as np

from rtcommon.validate import require_int
from tracer.scenes.model import Camera, Material, Scene, SceneBuilder

__all__ = ["balls", "tetra", "shells", "balls_count", "tetra_count", "shells_count"]

# The SPD generators' shared background ("sky blue").
_BACKGROUND = (0.078, 0.361, 0.753)
_SPD_DEPTH = 5


# ---------------------------------------------------------------- balls
def balls_count(size_factor: int = 4) -> int:
    """Elements of :func:`balls`: ``sum(9**k, k=0..size_factor)`` spheres + 1 quad."""
    return sum(9 ** k for k in range(size_factor + 1)) + 1


def _child_directions() -> np.ndarray:
    """The nine child directions in the parent's frame, shape (9, 3)."""
    sin_up, cos_up = math.sqrt(2.0 / 3.0), math.sqrt(1.0 / 3.0)  # elevation 54.7356 deg
    directions = []
    for group in range(3):
        base = 120.0 * group
        for azimuth, (cos_el, sin_el) in ((base + 45.0, (cos_up, sin_up)),
                                          (base + 15.0, (1.0, 0.0)),
                                          (base + 75.0, (1.0, 0.0))):
            a = math.radians(azimuth)
            directions.append((cos_el * math.cos(a), cos_el * math.sin(a), sin_el))
    return np.array(directions)


def _rotations_from_z(axes: np.ndarray) -> np.ndarray:
    """Smallest rotations taking +z to each unit axis, shape (N, 3, 3).

    Identity when ``a_z >= 0.9999`` and a half turn about y when
    ``a_z <= -0.9999``, as in the SPD library.
    """
    n = len(axes)
    ax, ay, az = axes[:, 0], axes[:, 1], axes[:, 2]
    # k = z x a; R = I + [k]x + [k]x^2 / (1 + cos), cos = a_z (Rodrigues).
    kx, ky = -ay, ax
    skew = np.zeros((n, 3, 3))
    skew[:, 0, 2], skew[:, 2, 0] = ky, -ky
    skew[:, 1, 2], skew[:, 2, 1] = -kx, kx
    with np.errstate(divide="ignore", invalid="ignore"):
        rotation = np.eye(3) + skew + (skew @ skew) / (1.0 + az)[:, None, None]
    rotation[az >= 0.9999] = np.eye(3)
    rotation[az <= -0.9999] = np.diag([-1.0, 1.0, -1.0])
    return rotation


def balls(size_factor: int = 4) -> Scene:
    """SPD ``balls``: a sphereflake over a square floor.

    The root sphere (centre 0, radius 0.5, axis +z) and, recursively for
    ``size_factor`` levels, nine children of radius r/3 touching each sphere at
    distance 4r/3 along directions turned to the parent's axis. Output order
    is the floor quad, then the spheres in depth-first pre-order.

    Parameters
    ----------
    size_factor : int, 0..6
        Size factor (levels of children); the study used 4.

    Returns
    -------
    Scene
        ``balls_count(size_factor)`` elements (7382 at size_factor 4), 3 lights, depth 5.
    """
    size_factor = require_int("balls size_factor", size_factor, 0, 6)
    builder = SceneBuilder("balls")
    builder.background = _BACKGROUND
    builder.camera = Camera((2.1, 1.3, 1.7), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 45.0, 0.01,
                            (512, 512))
    builder.max_depth = _SPD_DEPTH
    for position in ((4, 3, 2), (1, -4, 4), (-3, 1, 5)):
        builder.light(position)
    builder.material(Material((1.0, 0.75, 0.33), 0.8, 0.0, 100000.0, 0.0, 1.0))
    builder.polygon([(12, 12, -0.5), (-12, 12, -0.5), (-12, -12, -0.5), (12, -12, -0.5)])
    builder.material(Material((1.0, 0.9, 0.7), 0.5, 0.5, 3.0827, 0.0, 1.0))

    # Build level by level (vectorised), then emit in pre-order: a sphere at
    # depth j with path digits p_1..p_j has pre-order position
    # sum_i (1 + p_i * subtree_size(i)), subtree_size(i) = sum_{k<=size-i} 9^k.
    directions = _child_directions()
    subtree = [sum(9 ** k for k in range(size_factor - depth + 1)) for depth in range(size_factor + 1)]
    centers, axes, order = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.zeros(1, np.int64)
    radius = 0.5
    all_centers, all_radii, all_order = [centers], [np.full(1, radius)], [order]
    for depth in range(1, size_factor + 1):
        world = np.einsum("nij,kj->nki", _rotations_from_z(axes), directions)  # (N, 9, 3)
        centers = (centers[:, None, :] + (4.0 * radius / 3.0) * world).reshape(-1, 3)
        axes = world.reshape(-1, 3)
        order = (order[:, None] + 1 + np.arange(9)[None, :] * subtree[depth]).reshape(-1)
        radius /= 3.0
        all_centers.append(centers)
        all_radii.append(np.full(len(centers), radius))
        all_order.append(order)
    sequence = np.argsort(np.concatenate(all_order), kind="stable")
    centers = np.concatenate(all_centers)[sequence]
    radii = np.concatenate(all_radii)[sequence]
    for center, r in zip(centers, radii):
        builder.sphere(center, r)
    return builder.build()


# ---------------------------------------------------------------- tetra
def tetra_count(size_factor: int = 6) -> int:
    """Elements of :func:`tetra`: ``4**size_factor`` triangles."""
    return 4 ** size_factor


_CORNERS = np.array([(-1, -1, 1), (-1, 1, -1), (1, -1, -1), (1, 1, 1)], dtype=np.float64)
_FACES = ((0, 1, 2), (3, 2, 1), (2, 3, 0), (1, 0, 3))


def tetra(size_factor: int = 6) -> Scene:
    """SPD ``tetra``: a Sierpinski tetrahedron of triangles.

    A node is a cube (centre c, half-size h; root c = 0, h = 1). With more
    than one level left it recurses into the four sub-cubes
    ``c + (h/2) s_k`` of half-size h/2 at the corners
    ``s = (-,-,+), (-,+,-), (+,-,-), (+,+,+)``; at the last level it emits
    the tetrahedron ``v_k = c + h s_k`` as four triangles (0,1,2), (3,2,1),
    (2,3,0), (1,0,3). Depth-first pre-order.

    Parameters
    ----------
    size_factor : int, 1..10
        Size factor (levels); the study used 6; 10 makes 1,048,576 triangles.

    Returns
    -------
    Scene
        ``4**size_factor`` triangles (4096 at size_factor 6), 1 light, diffuse only, depth 5.
    """
    size_factor = require_int("tetra size_factor", size_factor, 1, 10)
    builder = SceneBuilder("tetra")
    builder.background = _BACKGROUND
    builder.camera = Camera((1.02285, -3.17715, -2.17451), (-0.004103, -0.004103, 0.216539),
                            (-0.816497, -0.816497, 0.816497), 45.0, 1.0, (512, 512))
    builder.max_depth = _SPD_DEPTH
    builder.light((2, -18, -5))
    builder.material(Material((1.0, 0.2, 0.2), 1.0, 0.0, 100000.0, 0.0, 0.0))

    # Leaf centres in pre-order: digits of the path, most significant first.
    leaves = 4 ** (size_factor - 1)
    centers = np.zeros((leaves, 3))
    path = np.arange(leaves)
    half = 1.0
    for level in range(size_factor - 1):
        digit = (path // 4 ** (size_factor - 2 - level)) % 4
        half /= 2.0
        centers += half * _CORNERS[digit]
    for center in centers:
        vertices = center + half * _CORNERS
        for face in _FACES:
            builder.triangle(vertices[list(face)])
    return builder.build()


# ---------------------------------------------------------------- shells
def shells_count(size_factor: int = 5) -> int:
    """Elements of :func:`shells`: ``180 * 2**size_factor + 1`` spheres."""
    return 180 * 2 ** size_factor + 1


def shells(size_factor: int = 5) -> Scene:
    """SPD ``shells``: Pickover's seashell of spheres on a logarithmic spiral.

    With ``N = 180 * 2**size_factor``, for each integer i from trunc(-2N/3) to
    trunc(N/3): ``theta = 18 pi i / N``, ``r = exp(0.15 theta)``, a sphere
    of radius r at ``(r sin theta, r cos theta, -2 r)``. No floor.

    Parameters
    ----------
    size_factor : int, 0..10
        Size factor; the study used 5.

    Returns
    -------
    Scene
        ``180 * 2**size_factor + 1`` spheres (5761 at size_factor 5), 1 light, Ks 0.2,
        depth 5.
    """
    size_factor = require_int("shells size_factor", size_factor, 0, 10)
    builder = SceneBuilder("shells")
    builder.background = _BACKGROUND
    builder.camera = Camera((-6.0, -60.0, 35.0), (0.0, 8.0, -15.0), (0.0, 0.0, 1.0), 45.0, 0.5,
                            (512, 512))
    builder.max_depth = _SPD_DEPTH
    builder.light((-100, -100, 100))
    builder.material(Material((1.0, 0.8, 0.4), 0.8, 0.2, 45.2776, 0.0, 1.0))
    n = 180 * 2 ** size_factor
    for i in range(math.trunc(-2 * n / 3), math.trunc(n / 3) + 1):
        theta = 18.0 * math.pi * i / n
        r = math.exp(0.15 * theta)
        builder.sphere((r * math.sin(theta), r * math.cos(theta), -2.0 * r), r)
    return builder.build()
