"""Procedural stand-ins for the study's two private scenes, Room and Fluid.

The paper's Room (a CAAD interior of polygon meshes: 7786 elements, 3 lights,
depth 4) and Fluid (a fluid-dynamics visualisation of spheres: 2899 elements,
2 lights, depth 5) came from applications that are not public. These
generators build scenes of the same kind with exactly the same element count,
lights and depth, so that the paper's table can be reproduced and the
what-if studies can grow or shrink them with ``scale``.

Both are deterministic: the same ``scale`` and ``seed`` give identical
arrays (a :class:`numpy.random.Generator` seeded with ``seed`` places the
varied details). The total element count is ``round(paper_count * scale)``
exactly; the fixed structure is built first and a filler that can take any
count (floor tiles in the room, water-surface particles in the fluid) makes
up the rest.

Their materials and Fluid's camera distance were re-tuned once,
so that the study-era tracer (``tracer.rendering.workload``, ``study1997``) makes
about the study's number of intersection tests on them, as it does on the
SPD scenes with no tuning at all: element, light and depth counts did not
change. Room 1.84x -> 1.01x of the study's 114.4 M tests, Fluid 11x -> 1.14x
of 29.3 M (at 64 x 64, scaled by pixel count); see each function.

Coordinates: z is up, metres for the room.
"""
from __future__ import annotations

import math

import numpy as np

from rtcommon.validate import InputError, require_number
from tracer.scenes.model import Camera, Material, Scene, SceneBuilder
from tracer.scenes.study import PAPER_ELEMENTS

__all__ = ["room", "fluid", "ROOM_ELEMENTS", "FLUID_ELEMENTS"]

ROOM_ELEMENTS = PAPER_ELEMENTS["room"]
FLUID_ELEMENTS = PAPER_ELEMENTS["fluid"]


def _target(name: str, paper_count: int, scale, lowest: float, highest: float) -> int:
    require_number(f"{name} scale", scale)
    if not lowest <= scale <= highest:
        raise InputError(f"{name} scale must be in [{lowest}, {highest}], got {scale}")
    return int(round(paper_count * float(scale)))


# ------------------------------------------------------------ mesh helpers
def _box(b: SceneBuilder, lo, hi) -> None:
    """Six quads of an axis-aligned box, counter-clockwise seen from outside."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = (
        [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],  # -z
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],  # +z
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],  # -y
        [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],  # +y
        [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],  # -x
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],  # +x
    )
    for face in faces:
        b.polygon(face)


def _revolve(b: SceneBuilder, center, profile, segments: int, *, cap_bottom=False,
             cap_top=False) -> None:
    """Surface of revolution about the vertical axis through ``center``.

    ``profile`` is a sequence of (radius, height) points; each profile step
    and angular step makes one planar quad (an isosceles trapezoid), or a
    triangle where the radius is zero. Normals face outward where the
    profile climbs and inward where it descends (the inside of a shade).
    Optional caps are convex n-gons at the first/last profile point.
    """
    cx, cy, cz = center
    angles = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    cos, sin = np.cos(angles), np.sin(angles)

    def ring(r, z):
        return np.column_stack([cx + r * cos, cy + r * sin, np.full(segments + 1, cz + z)])

    for (r1, z1), (r2, z2) in zip(profile[:-1], profile[1:]):
        if (r1 == 0.0 and r2 == 0.0) or (r1 == r2 and z1 == z2):
            continue
        lower, upper = ring(r1, z1), ring(r2, z2)
        for k in range(segments):
            if r1 == 0.0:
                b.polygon([lower[0], upper[k + 1], upper[k]])
            elif r2 == 0.0:
                b.polygon([lower[k], lower[k + 1], upper[0]])
            else:
                b.polygon([lower[k], lower[k + 1], upper[k + 1], upper[k]])
    if cap_bottom:
        r, z = profile[0]
        b.polygon(ring(r, z)[:segments][::-1])
    if cap_top:
        r, z = profile[-1]
        b.polygon(ring(r, z)[:segments])


def _cylinder(b: SceneBuilder, center, radius, height, segments, caps=True) -> None:
    _revolve(b, center, [(radius, 0.0), (radius, height)], segments,
             cap_bottom=caps, cap_top=caps)


def _sphere_mesh(b: SceneBuilder, center, radius, rings: int, segments: int) -> None:
    """Latitude-longitude tessellated sphere (quads, triangles at the poles)."""
    phis = np.linspace(-np.pi / 2, np.pi / 2, rings + 1)
    profile = [(0.0 if k in (0, rings) else radius * math.cos(p), radius * math.sin(p))
               for k, p in enumerate(phis)]
    _revolve(b, center, profile, segments)


def _wall(b: SceneBuilder, origin, u, v, u_cuts, v_cuts, hole=None) -> None:
    """A planar wall tessellated on a grid, facing ``u x v``.

    ``origin`` + s u + t v spans the wall; ``u_cuts``/``v_cuts`` are the grid
    coordinates (s, t); cells inside ``hole`` = (s0, s1, t0, t1) are left out.
    """
    origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
    for s0, s1 in zip(u_cuts[:-1], u_cuts[1:]):
        for t0, t1 in zip(v_cuts[:-1], v_cuts[1:]):
            if hole is not None and hole[0] <= s0 and s1 <= hole[1] and hole[2] <= t0 \
                    and t1 <= hole[3]:
                continue
            b.polygon([origin + s0 * u + t0 * v, origin + s1 * u + t0 * v,
                       origin + s1 * u + t1 * v, origin + s0 * u + t1 * v])


def _cuts(length, step, extra=()):
    points = set(np.round(np.arange(0.0, length + 1e-9, step), 9)) | {0.0, float(length)}
    points |= {round(float(e), 9) for e in extra}
    return sorted(points)


# ------------------------------------------------------------------- room
def room(scale: float = 1.0, seed: int = 1999) -> Scene:
    """CAAD-style living room made of polygon meshes (stand-in for *Room*).

    An 8 x 6 x 3 m room: walls, ceiling and skirting tessellated into panels;
    a window with frame, mullions and glass panes (T 0.8, ior 1.5) in the
    +x wall; a framed mirror (Ks 0.85) and a door; a dining table with a
    glossy top (Ks 0.3) and four chairs with turned (tessellated) legs; a
    round coffee table on a turned pedestal; a bookshelf with books; a desk
    with a desk lamp; a ceiling lamp with a tessellated shade; a vase, a
    fruit bowl with fruit and a plant pot (surfaces of revolution); and a
    matte parquet floor whose tile count makes the total exact. Only metal,
    the mirror, ceramics, fruit and the glossy wood reflect; the rest is
    diffuse, as CAAD renderings of the time mostly were (and as the study's
    intersection-test count asks, see the comment at the materials).
    All polygons are planar and convex; boxes are closed, faces
    counter-clockwise seen from outside.

    Three point lights: under the ceiling lamp, in the desk lamp, and near
    the window. Maximum depth 4. The camera stands in the (-x, -y) corner at
    eye height looking across the table towards the window and bookshelf
    (field of view 60 degrees), so a 512 x 512 image shows the room.

    Parameters
    ----------
    scale : float, 0.5..16
        Element count factor: the scene has ``round(7786 * scale)`` elements;
        tessellation of the curved parts and the number of books grow with
        ``scale``, the floor tiles make up the rest.
    seed : int
        Seed of the generator placing the varied details (book sizes and
        colours, tile shades, fruit, leaves).

    Returns
    -------
    Scene
        7786 elements (triangles and polygons) at ``scale=1``, 3 lights,
        depth 4.
    """
    target = _target("room", ROOM_ELEMENTS, scale, 0.5, 16.0)
    rng = np.random.default_rng(seed)
    seg = max(6, int(round(24 * scale)))  # segments around curved parts
    ball = max(6, int(round(24 * math.sqrt(scale))))  # sphere meshes: ball/2 x ball quads
    b = SceneBuilder("room")
    b.max_depth = 4
    b.background = (0.62, 0.76, 0.93)  # sky seen through the window
    b.camera = Camera((0.45, 0.55, 1.65), (5.6, 4.3, 0.95), (0.0, 0.0, 1.0), 60.0, 0.01,
                      (512, 512))
    b.light((3.8, 2.8, 2.05), (0.75, 0.7, 0.6))   # under the ceiling lamp
    b.light((6.55, 5.47, 1.0), (0.5, 0.45, 0.35))  # under the desk lamp's shade, off its arm
    b.light((7.2, 2.2, 2.6), (0.45, 0.5, 0.6))    # daylight near the window
    W, D, H = 8.0, 6.0, 3.0

    wall = Material((0.85, 0.82, 0.74), 0.85, 0.0, 0.0, 0.0, 1.0)
    ceiling = Material((0.95, 0.95, 0.93), 0.9, 0.0, 0.0, 0.0, 1.0)
    # Surfaces with at most a faint highlight (Ks <= 0.15) are matte (Ks 0, so no reflection rays): a
    # CAAD rendering of the time drew most surfaces diffuse, and only with them do the study-era tracer's
    # intersection tests land near the study's count (1.01x at 64x64; 1.84x with the faint highlights).
    trim = Material((0.95, 0.95, 0.95), 0.7, 0.0, 30.0, 0.0, 1.0)
    wood = Material((0.55, 0.35, 0.2), 0.7, 0.3, 60.0, 0.0, 1.0)
    dark_wood = Material((0.35, 0.2, 0.12), 0.75, 0.0, 30.0, 0.0, 1.0)
    metal = Material((0.8, 0.8, 0.82), 0.3, 0.6, 120.0, 0.0, 1.0)
    fabric = Material((0.6, 0.15, 0.12), 0.9, 0.0, 0.0, 0.0, 1.0)
    glass = Material((0.9, 0.95, 1.0), 0.05, 0.0, 200.0, 0.8, 1.5)
    mirror = Material((0.9, 0.9, 0.9), 0.1, 0.85, 500.0, 0.0, 1.0)
    ceramic = Material((0.2, 0.35, 0.6), 0.6, 0.4, 80.0, 0.0, 1.0)
    shade = Material((0.95, 0.9, 0.75), 0.85, 0.0, 10.0, 0.0, 1.0)
    terracotta = Material((0.7, 0.35, 0.2), 0.85, 0.0, 10.0, 0.0, 1.0)
    leaf = Material((0.2, 0.5, 0.2), 0.8, 0.0, 20.0, 0.0, 1.0)

    # Walls (facing the inside), the +x wall with the window opening.
    win = (0.8, 3.6, 0.9, 2.4)  # y0, y1, z0, z1 on the +x wall
    b.material(wall)
    _wall(b, (W, 0, 0), (-1, 0, 0), (0, 0, 1), _cuts(W, 0.5), _cuts(H, 0.5))         # y = 0
    _wall(b, (0, D, 0), (1, 0, 0), (0, 0, 1), _cuts(W, 0.5), _cuts(H, 0.5))          # y = D
    _wall(b, (0, 0, 0), (0, 1, 0), (0, 0, 1), _cuts(D, 0.5), _cuts(H, 0.5))          # x = 0
    hole = (D - win[1], D - win[0], win[2], win[3])  # s runs along -y on this wall
    _wall(b, (W, D, 0), (0, -1, 0), (0, 0, 1), _cuts(D, 0.5, hole[:2]),
          _cuts(H, 0.5, hole[2:]), hole=hole)                                       # x = W
    b.material(ceiling)
    _wall(b, (0, D, H), (1, 0, 0), (0, -1, 0), _cuts(W, 0.5), _cuts(D, 0.5))
    # Skirting boards.
    b.material(trim)
    _box(b, (0, 0, 0), (W, 0.02, 0.1))
    _box(b, (0, D - 0.02, 0), (W, D, 0.1))
    _box(b, (0, 0.02, 0), (0.02, D - 0.02, 0.1))
    _box(b, (W - 0.02, 0.02, 0), (W, D - 0.02, 0.1))

    # Window: frame, mullions, four glass panes (thin closed boxes).
    y0, y1, z0, z1 = win
    ym, zm, t = (y0 + y1) / 2, (z0 + z1) / 2, 0.05
    _box(b, (W - 0.12, y0 - t, z0 - t), (W, y1 + t, z0))
    _box(b, (W - 0.12, y0 - t, z1), (W, y1 + t, z1 + t))
    _box(b, (W - 0.12, y0 - t, z0), (W, y0, z1))
    _box(b, (W - 0.12, y1, z0), (W, y1 + t, z1))
    _box(b, (W - 0.1, ym - 0.02, z0), (W - 0.02, ym + 0.02, z1))
    _box(b, (W - 0.1, y0, zm - 0.02), (W - 0.02, y1, zm + 0.02))
    _box(b, (W - 0.16, y0 - 0.1, z0 - 0.08), (W, y1 + 0.1, z0 - t))  # sill
    b.material(glass)
    for ya, yb in ((y0, ym - 0.02), (ym + 0.02, y1)):
        for za, zb in ((z0, zm - 0.02), (zm + 0.02, z1)):
            _box(b, (W - 0.07, ya, za), (W - 0.055, yb, zb))

    # Mirror with frame on the +x wall, right of the window.
    b.material(dark_wood)
    my0, my1, mz0, mz1 = 4.05, 5.05, 1.0, 2.2
    _box(b, (W - 0.05, my0 - 0.06, mz0 - 0.06), (W, my1 + 0.06, mz0))
    _box(b, (W - 0.05, my0 - 0.06, mz1), (W, my1 + 0.06, mz1 + 0.06))
    _box(b, (W - 0.05, my0 - 0.06, mz0), (W, my0, mz1))
    _box(b, (W - 0.05, my1, mz0), (W, my1 + 0.06, mz1))
    b.material(mirror)
    b.polygon([(W - 0.03, my0, mz0), (W - 0.03, my0, mz1), (W - 0.03, my1, mz1),
               (W - 0.03, my1, mz0)])

    # Door in the +y wall: frame, panel, turned handle.
    b.material(trim)
    _box(b, (3.5, D - 0.06, 0), (3.58, D, 2.1))
    _box(b, (4.5, D - 0.06, 0), (4.58, D, 2.1))
    _box(b, (3.5, D - 0.06, 2.1), (4.58, D, 2.18))
    b.material(dark_wood)
    _box(b, (3.58, D - 0.05, 0.005), (4.5, D - 0.01, 2.095))
    b.material(metal)
    _sphere_mesh(b, (4.4, D - 0.09, 1.0), 0.03, ball // 4, ball)

    # Dining table: glossy top, turned legs.
    tx, ty = 3.8, 2.8
    b.material(wood)
    _box(b, (tx - 0.95, ty - 0.55, 0.72), (tx + 0.95, ty + 0.55, 0.77))
    leg_profile = [(0.03, 0.0), (0.035, 0.1), (0.025, 0.25), (0.035, 0.45), (0.03, 0.6),
                   (0.04, 0.72)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            _revolve(b, (tx + sx * 0.85, ty + sy * 0.45, 0.0), leg_profile, seg,
                     cap_bottom=True)

    # Four chairs around the table.
    chair_leg = [(0.02, 0.0), (0.025, 0.12), (0.018, 0.3), (0.022, 0.44)]
    for cx, cy, facing in ((tx - 0.5, ty - 0.8, 1), (tx + 0.5, ty - 0.8, 1),
                           (tx - 0.5, ty + 0.8, -1), (tx + 0.5, ty + 0.8, -1)):
        b.material(dark_wood)
        for sx in (-1, 1):
            for sy in (-1, 1):
                _revolve(b, (cx + sx * 0.19, cy + sy * 0.19, 0.0), chair_leg, seg,
                         cap_bottom=True)
        back_y = cy - facing * 0.2
        for sx in (-1, 1):
            _cylinder(b, (cx + sx * 0.19, back_y, 0.48), 0.02, 0.5, max(6, seg // 2))
        _box(b, (cx - 0.22, back_y - 0.02, 0.8), (cx + 0.22, back_y + 0.02, 0.95))
        b.material(fabric)
        _box(b, (cx - 0.23, cy - 0.23, 0.44), (cx + 0.23, cy + 0.23, 0.48))

    # Ceiling lamp: cord and a shade shell open at the bottom.
    b.material(metal)
    _cylinder(b, (tx, ty, 2.35), 0.006, H - 2.35, max(6, seg // 3), caps=False)
    b.material(shade)
    shade_profile = []
    for k in range(9):  # outside, climbing: a bell from r 0.3 at z 2.1 to r 0.06 at z 2.35
        a = k / 8
        shade_profile.append((0.3 - 0.24 * a ** 0.7, 2.1 + 0.25 * a))
    for k in range(8, -1, -1):  # inside, descending
        a = k / 8
        shade_profile.append((0.29 - 0.24 * a ** 0.7, 2.1 + 0.24 * a))
    _revolve(b, (tx, ty, 0.0), shade_profile, seg)
    b.material(Material((1.0, 1.0, 0.9), 1.0, 0.0, 0.0, 0.3, 1.0))
    _sphere_mesh(b, (tx, ty, 2.26), 0.05, ball // 4, ball // 2)

    # Round coffee table near the window on a turned pedestal.
    b.material(wood)
    px, py = 6.5, 2.2
    _revolve(b, (px, py, 0.0), [(0.5, 0.48), (0.5, 0.52)], 2 * seg, cap_bottom=True,
             cap_top=True)
    pedestal = [(0.22, 0.0), (0.2, 0.03), (0.08, 0.06), (0.05, 0.12), (0.07, 0.2), (0.04, 0.3),
                (0.05, 0.4), (0.1, 0.48)]
    _revolve(b, (px, py, 0.0), pedestal, seg, cap_bottom=True)
    # Vase (ceramic, glossy) on the coffee table.
    b.material(ceramic)
    vase = [(0.0, 0.0), (0.06, 0.0)] + [
        (0.06 + 0.05 * math.sin(math.pi * k / 10) - 0.025 * (k / 10) ** 2, 0.035 * k)
        for k in range(1, 11)] + [(0.04, 0.38), (0.045, 0.4)]
    _revolve(b, (px, py, 0.52), vase, seg)

    # Fruit bowl on the dining table: bowl shell and tessellated fruit.
    b.material(glass)
    bowl = [(0.0, 0.0), (0.08, 0.0)] + [(0.08 + 0.12 * math.sin(0.5 * math.pi * k / 6),
                                          0.1 * (1 - math.cos(0.5 * math.pi * k / 6)))
                                         for k in range(1, 7)]
    bowl += [(r - 0.01, z) for r, z in reversed(bowl[2:])] + [(0.0, 0.01)]
    _revolve(b, (tx, ty, 0.77), bowl, seg)
    fruit_colors = ((0.9, 0.5, 0.1), (0.8, 0.1, 0.1), (0.9, 0.8, 0.2), (0.3, 0.6, 0.15))
    n_fruit = 5
    for k in range(n_fruit):
        angle = 2 * math.pi * k / n_fruit + rng.uniform(-0.2, 0.2)
        r = 0.04 + 0.005 * rng.random()
        color = fruit_colors[int(rng.integers(len(fruit_colors)))]
        b.material(Material(color, 0.7, 0.25, 50.0, 0.0, 1.0))
        _sphere_mesh(b, (tx + 0.08 * math.cos(angle), ty + 0.08 * math.sin(angle), 0.82 + r),
                     r, ball // 2, ball)

    # Bookshelf against the +y wall, with books.
    sx0, sx1, sd = 0.7, 2.9, 0.35
    b.material(dark_wood)
    _box(b, (sx0, D - sd, 0.0), (sx0 + 0.03, D - 0.02, 2.0))
    _box(b, (sx1 - 0.03, D - sd, 0.0), (sx1, D - 0.02, 2.0))
    _box(b, (sx0 + 0.03, D - 0.03, 0.0), (sx1 - 0.03, D - 0.02, 2.0))
    shelf_z = (0.05, 0.5, 0.95, 1.4, 1.85)
    for z in shelf_z:
        _box(b, (sx0 + 0.03, D - sd, z), (sx1 - 0.03, D - 0.03, z + 0.025))
    _box(b, (sx0, D - sd, 2.0), (sx1, D - 0.02, 2.03))
    book_palette = ((0.6, 0.1, 0.1), (0.1, 0.2, 0.5), (0.15, 0.4, 0.2), (0.8, 0.7, 0.4),
                    (0.2, 0.2, 0.2), (0.5, 0.3, 0.5), (0.9, 0.9, 0.85), (0.7, 0.4, 0.1))
    book_materials = [Material(c, 0.8, 0.0, 20.0, 0.0, 1.0) for c in book_palette]
    fill = min(0.95, 0.7 * math.sqrt(scale))  # fraction of each shelf filled with books
    for z in shelf_z[:-1]:
        x = sx0 + 0.04
        end = x + fill * (sx1 - sx0 - 0.08)
        while True:
            width = rng.uniform(0.02, 0.05) / math.sqrt(scale)
            height = rng.uniform(0.25, 0.4)
            if x + width > end:
                break
            b.material(book_materials[int(rng.integers(len(book_materials)))])
            _box(b, (x, D - sd + rng.uniform(0.0, 0.05), z + 0.025),
                 (x + width, D - 0.04, z + 0.025 + height))
            x += width + 0.002

    # Desk with a desk lamp in the (+x, +y) corner.
    b.material(wood)
    _box(b, (5.6, D - 0.7, 0.73), (7.4, D - 0.02, 0.77))
    for lx in (5.63, 7.33):
        _box(b, (lx, D - 0.67, 0.0), (lx + 0.04, D - 0.05, 0.73))
    b.material(metal)
    lamp_x, lamp_y = 6.55, D - 0.45
    _revolve(b, (lamp_x, lamp_y, 0.77), [(0.09, 0.0), (0.09, 0.015), (0.03, 0.03)], seg,
             cap_bottom=True)
    _cylinder(b, (lamp_x, lamp_y, 0.8), 0.012, 0.4, max(6, seg // 3), caps=False)
    b.material(shade)
    cone = [(0.14, 1.05), (0.035, 1.25), (0.03, 1.25), (0.13, 1.05)]
    _revolve(b, (lamp_x, lamp_y, 0.0), cone, seg)

    # Plant pot in the (+x, -y) corner with leaves.
    b.material(terracotta)
    pot = [(0.0, 0.0), (0.12, 0.0), (0.16, 0.35), (0.18, 0.38), (0.17, 0.38), (0.15, 0.35),
           (0.0, 0.33)]
    pot_x, pot_y = 7.5, 0.5
    _revolve(b, (pot_x, pot_y, 0.0), pot, seg)
    b.material(leaf)
    for k in range(int(round(24 * scale))):
        angle = rng.uniform(0, 2 * math.pi)
        tilt = rng.uniform(0.4, 1.2)
        length = rng.uniform(0.25, 0.5)
        base = np.array([pot_x, pot_y, 0.36])
        direction = np.array([math.cos(angle) * math.sin(tilt), math.sin(angle) * math.sin(tilt),
                              math.cos(tilt)])
        side = np.array([-math.sin(angle), math.cos(angle), 0.0]) * rng.uniform(0.04, 0.07)
        b.polygon([base, base + 0.5 * length * direction - side, base + length * direction,
                   base + 0.5 * length * direction + side])

    # Parquet floor (glossy), the filler: tiles in rows, counts per row
    # differing by at most one, so any number of tiles covers the floor.
    tiles = target - b.n_elements
    if tiles < 16:
        raise InputError(f"room scale {scale} leaves {tiles} floor tiles; use a larger scale")
    rows = max(1, int(round(math.sqrt(tiles * D / W))))
    per_row = np.full(rows, tiles // rows)
    per_row[: tiles % rows] += 1
    floor_shades = [Material((0.62 * s, 0.45 * s, 0.28 * s), 0.75, 0.0, 40.0, 0.0, 1.0)
                    for s in (0.85, 1.0, 1.12)]
    for row, count in enumerate(per_row):
        ya, yb = D * row / rows, D * (row + 1) / rows
        xs = np.linspace(0.0, W, count + 1)
        for xa, xb in zip(xs[:-1], xs[1:]):
            b.material(floor_shades[int(rng.integers(3))])
            b.polygon([(xa, ya, 0.0), (xb, ya, 0.0), (xb, yb, 0.0), (xa, yb, 0.0)])
    scene = b.build()
    if scene.n_elements != target:  # a construction invariant, not user input
        raise RuntimeError(f"built {scene.n_elements} elements instead of {target}: a bug in this generator")
    return scene


# ------------------------------------------------------------------ fluid
def fluid(scale: float = 1.0, seed: int = 1999) -> Scene:
    """Crown splash of a drop hitting a pool, as spheres (stand-in for *Fluid*).

    A particle-method snapshot: the pool surface is a layer of overlapping
    spheres (sunflower pattern on a disk of radius 5) with a crater under
    the impact and outgoing ripples; a crown sheet of spheres rises from the
    crater rim and flares outward; its rim breaks into fingers that shed
    droplets; spray droplets fly ballistically; the tail of the falling drop
    hangs above the centre. Water is drawn opaque and reflective (Ks
    0.25-0.5), as particle visualisations of the time drew particles, so
    reflections reach depth 5 but no refraction trees grow.

    Two point lights (key and fill, above). Maximum depth 5. The camera
    looks down at about 19 degrees from 13 units away (field of view 40
    degrees), so the splash and its pool fill the middle of a 512 x 512
    image with background around them.

    Transparency and the camera distance were set so that the study-era
    tracer's intersection tests land near the study's count (29.3 M at
    512 x 512): transparent water from 6.5 units made 11x as many tests
    (24 rays per pixel), opaque water from 13 units makes 1.14x (probed at
    64 x 64).

    Parameters
    ----------
    scale : float, 0.25..16
        Element count factor: ``round(2899 * scale)`` spheres; crown rings,
        fingers and spray grow with ``sqrt(scale)`` or ``scale``, the surface
        particles make up the rest (finer particles for larger scale).
    seed : int
        Seed of the generator placing the spray, the finger lengths and the
        jitter of the crown.

    Returns
    -------
    Scene
        2899 spheres at ``scale=1``, 2 lights, depth 5.
    """
    target = _target("fluid", FLUID_ELEMENTS, scale, 0.25, 16.0)
    rng = np.random.default_rng(seed)
    root = math.sqrt(scale)
    b = SceneBuilder("fluid")
    b.max_depth = 5
    b.background = (0.12, 0.16, 0.24)
    b.camera = Camera((0.0, -12.4, 4.8), (0.0, 0.0, 0.6), (0.0, 0.0, 1.0), 40.0, 0.01,
                      (512, 512))
    b.light((5.0, -6.0, 9.0), (0.8, 0.8, 0.75))
    b.light((-6.0, -2.0, 5.0), (0.35, 0.4, 0.5))

    surface_water = Material((0.35, 0.55, 0.8), 0.35, 0.5, 80.0, 0.0, 1.33)
    sheet_water = Material((0.6, 0.8, 0.95), 0.2, 0.35, 120.0, 0.0, 1.33)
    droplet = Material((0.8, 0.9, 1.0), 0.1, 0.25, 200.0, 0.0, 1.33)

    crown_radius, crown_height = 1.1, 1.3

    def surface_height(r):
        crater = -0.45 * np.exp(-(r / 0.85) ** 2)
        ripple = np.where(r > crown_radius,
                          0.07 * np.cos(5.0 * (r - crown_radius)) * np.exp(-(r - crown_radius) / 1.8),
                          0.0)
        return crater + ripple

    # Crown sheet: rings of spheres, flaring outward with height.
    around = int(round(64 * root))
    rings = int(round(12 * root))
    sheet_r = 1.1 * math.pi * crown_radius / around  # neighbours overlap: a closed sheet
    b.material(sheet_water)
    for ring in range(rings):
        h = (ring + 0.5) / rings
        z = surface_height(np.array(crown_radius))[()] + crown_height * h
        radius = crown_radius + 0.35 * h ** 2
        thin = 1.0 - 0.35 * h  # the sheet thins towards the rim
        phase = 0.5 * (ring % 2)
        for k in range(around):
            a = 2 * math.pi * (k + phase + rng.uniform(-0.1, 0.1)) / around
            b.sphere((radius * math.cos(a), radius * math.sin(a), z), sheet_r * thin)
    # Rim: a thicker torus of spheres.
    rim_z = crown_height + surface_height(np.array(crown_radius))[()]
    rim_radius = crown_radius + 0.35
    for k in range(around):
        a = 2 * math.pi * k / around
        b.sphere((rim_radius * math.cos(a), rim_radius * math.sin(a), rim_z), 0.8 * sheet_r)
    # Fingers growing out of the rim, each shedding droplets.
    fingers = int(round(22 * root))
    b.material(droplet)
    for f in range(fingers):
        a = 2 * math.pi * (f + rng.uniform(-0.2, 0.2)) / fingers
        outward = np.array([math.cos(a), math.sin(a), 0.0])
        up = np.array([0.0, 0.0, 1.0])
        start = np.array([rim_radius * math.cos(a), rim_radius * math.sin(a), rim_z])
        length = rng.uniform(0.25, 0.45)
        steps = max(3, int(round(5 * root)))
        for s in range(1, steps + 1):
            t = s / steps
            b.sphere(start + length * t * (0.45 * outward + up), 0.8 * sheet_r * (1 - 0.35 * t))
        tip = start + length * (0.45 * outward + up)
        for d in range(2):
            tip = tip + rng.uniform(0.12, 0.22) * (0.5 * outward + up)
            b.sphere(tip, 0.7 * sheet_r * (0.9 - 0.2 * d))
    # Spray: droplets on ballistic arcs around the crown.
    for _ in range(int(round(260 * scale))):
        a = rng.uniform(0, 2 * math.pi)
        r = crown_radius + 0.3 + rng.exponential(0.8)
        z = max(0.15, 1.6 * math.exp(-(r - crown_radius) / 1.3) * rng.uniform(0.3, 1.2))
        b.sphere((r * math.cos(a), r * math.sin(a), z), rng.uniform(0.015, 0.05))
    # Tail of the falling drop above the centre.
    b.sphere((0.0, 0.0, 2.7), 0.16)
    b.sphere((0.0, 0.0, 3.05), 0.06)

    # Pool surface, the filler: a sunflower layer that takes any count.
    particles = target - b.n_elements
    if particles < 200:
        raise InputError(f"fluid scale {scale} leaves {particles} surface particles; "
                         "use a larger scale")
    disk = 5.0
    i = np.arange(particles)
    r = disk * np.sqrt((i + 0.5) / particles)
    theta = i * math.pi * (3.0 - math.sqrt(5.0))
    spacing = disk * math.sqrt(math.pi / particles)
    b.material(surface_water)
    for x, y, z in zip(r * np.cos(theta), r * np.sin(theta), surface_height(r)):
        b.sphere((x, y, z - 0.35 * spacing), 0.75 * spacing)
    scene = b.build()
    if scene.n_elements != target:  # a construction invariant, not user input
        raise RuntimeError(f"built {scene.n_elements} elements instead of {target}: a bug in this generator")
    return scene
