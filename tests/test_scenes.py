"""SPD generators against the reference files, stand-ins, loading by name or path."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tracer.scenes import spd
from tracer.scenes.nff import format_nff, parse_nff, read_nff, write_nff
from tracer.scenes.obj import OBJError, read_obj
from tracer.scenes.model import ARRAY_FIELDS, scenes_equal
from tracer.scenes.catalog import PAPER_DEPTH, PAPER_ELEMENTS, PAPER_SCENES, load
from tracer.scenes.standins import fluid, room

# Copies of ../shared/reference/spd (output of the original SPD generators).
REFERENCE = Path(__file__).resolve().parent / "data" / "spd"
needs_reference = pytest.mark.skipif(not REFERENCE.is_dir(), reason="reference SPD files absent")


def print_tolerance(printed: np.ndarray) -> np.ndarray:
    """Half a unit in the 6th significant digit of each printed number, plus
    a few ulps of the row's magnitude for values that are rounding noise
    around zero (e.g. r sin(6 pi))."""
    printed = np.asarray(printed, dtype=np.float64)
    magnitude = np.abs(printed)
    exponent = np.floor(np.log10(np.where(magnitude > 0, magnitude, 1.0)))
    half_unit = np.where(magnitude > 0, 5.0 * 10.0 ** (exponent - 6), 0.0)
    row = np.abs(printed).reshape(printed.shape[0], -1).max(axis=1)
    row = row.reshape((-1,) + (1,) * (printed.ndim - 1))
    return half_unit * (1 + 1e-9) + 1e-14 * row


@needs_reference
@pytest.mark.parametrize("file, generate", [("balls", spd.balls), ("tetra", spd.tetra),
                                            ("shells", spd.shells)])
def test_generator_reproduces_reference_object_by_object(file, generate):
    reference = read_nff(REFERENCE / f"{file}.nff")
    scene = generate()
    for name in ("element_kind", "element_index", "element_material", "polygon_offsets",
                 "patch_offsets"):
        np.testing.assert_array_equal(getattr(scene, name), getattr(reference, name), name)
    for name in ARRAY_FIELDS:
        mine, printed = getattr(scene, name), getattr(reference, name)
        assert mine.dtype == printed.dtype and mine.shape == printed.shape, name
        if printed.size and printed.dtype == np.float64:
            absent = np.isnan(mine) & np.isnan(printed)  # (u, v) neither gave
            assert np.array_equal(np.isnan(mine), absent), name
            error = np.where(absent, 0.0, np.abs(mine - printed))
            tolerance = np.where(absent, 0.0, print_tolerance(printed))
            worst = np.unravel_index(np.argmax(error - tolerance), error.shape)
            assert np.all(error <= tolerance), (name, worst, mine[worst], printed[worst])
    assert scene.camera == reference.camera
    assert scene.max_depth == 5


@pytest.mark.parametrize("size", [0, 1, 2, 3])
def test_balls_counts(size):
    scene = spd.balls(size)
    assert scene.n_elements == spd.balls_count(size) == sum(9 ** k for k in range(size + 1)) + 1
    assert scene.counts()["polygon"] == 1 and scene.n_lights == 3
    # every child touches its parent: the smallest spheres are r0 / 3**size
    assert np.isclose(scene.sphere_radius.min(), 0.5 / 3 ** size)


def test_balls_other_documented_counts():
    assert spd.balls_count(3) == 821 and spd.balls_count(5) == 66431


@pytest.mark.parametrize("size", [1, 2, 3, 4])
def test_tetra_counts(size):
    scene = spd.tetra(size)
    assert scene.n_elements == scene.counts()["triangle"] == 4 ** size
    lo, hi = scene.bounding_box()
    np.testing.assert_array_equal(lo, [-1, -1, -1])
    np.testing.assert_array_equal(hi, [1, 1, 1])


@pytest.mark.parametrize("size", [0, 1, 3])
def test_shells_counts(size):
    assert spd.shells(size).n_elements == 180 * 2 ** size + 1 == spd.shells_count(size)


@pytest.mark.parametrize("call", [lambda: spd.balls(-1), lambda: spd.tetra(0),
                                  lambda: spd.shells(2.5), lambda: spd.balls(True)])
def test_generator_sizes_are_validated(call):
    with pytest.raises(ValueError, match="size_factor must be"):
        call()


# ------------------------------------------------------------- stand-ins
def polygon_problems(scene) -> list[str]:
    """Slow obvious check: every triangle/polygon planar, convex, non-degenerate."""
    shapes = list(scene.triangle_vertices)
    offsets = scene.polygon_offsets
    shapes += [scene.polygon_vertices[a:b] for a, b in zip(offsets[:-1], offsets[1:])]
    problems = []
    for k, v in enumerate(shapes):
        centre = v.mean(axis=0)
        normal = sum(np.cross(a - centre, b - centre) for a, b in zip(v, np.roll(v, -1, 0)))
        size = np.ptp(v, axis=0).max()
        if np.linalg.norm(normal) <= 1e-9 * size * size:
            problems.append(f"{k} degenerate")
            continue
        normal /= np.linalg.norm(normal)
        if np.abs((v - centre) @ normal).max() > 1e-9 * size:
            problems.append(f"{k} not planar")
        edges = np.roll(v, -1, 0) - v
        if np.any(np.linalg.norm(edges, axis=1) == 0):
            problems.append(f"{k} repeated vertex")
        if np.any(np.cross(edges, np.roll(edges, -1, 0)) @ normal < -1e-12 * size * size):
            problems.append(f"{k} not convex")
    return problems


def test_room_matches_the_paper():
    scene = room()
    assert scene.n_elements == 7786 and scene.n_lights == 3 and scene.max_depth == 4
    counts = scene.counts()
    assert counts["sphere"] == counts["cone"] == counts["patch"] == 0
    assert counts["polygon"] > 5000  # polygon meshes
    used = np.unique(scene.element_material)
    assert np.any(scene.material_ks[used] >= 0.8)  # a mirror
    assert np.any(scene.material_ks[used] > 0)
    assert polygon_problems(scene) == []
    lo, hi = scene.bounding_box()
    eye = np.array(scene.camera.eye)
    assert np.all(lo < eye) and np.all(eye < hi)  # the camera stands inside the room


def test_fluid_matches_the_paper():
    scene = fluid()
    assert scene.n_elements == scene.counts()["sphere"] == 2899
    assert scene.n_lights == 2 and scene.max_depth == 5
    # opaque, reflective water (issue 12: the study's test count), so reflections reach depth 5
    assert np.all(scene.material_t == 0) and np.all(np.isclose(scene.material_ior, 1.33))
    assert np.all(scene.material_ks > 0)
    assert np.all(scene.sphere_radius > 0)


@pytest.mark.parametrize("make, paper", [(room, 7786), (fluid, 2899)])
def test_standins_are_deterministic_and_seeded(make, paper):
    first, again, other = make(seed=7), make(seed=7), make(seed=8)
    assert scenes_equal(first, again)
    assert not scenes_equal(first, other)
    assert other.n_elements == paper


@pytest.mark.parametrize("make, paper, scales", [(room, 7786, (0.5, 2.0)),
                                                 (fluid, 2899, (0.25, 0.5, 3.0))])
def test_standin_scale_sets_the_element_count(make, paper, scales):
    for scale in scales:
        scene = make(scale=scale)
        assert scene.n_elements == round(paper * scale)
    if make is room:
        assert polygon_problems(make(scale=0.5)) == []


@pytest.mark.parametrize("make", [room, fluid])
@pytest.mark.parametrize("scale", [0.0, -1.0, 100.0, "big", True])
def test_standin_scale_is_validated(make, scale):
    with pytest.raises(ValueError, match="scale must be"):
        make(scale=scale)


def test_standins_survive_nff_round_trip():
    for scene in (room(), fluid()):
        again = parse_nff(format_nff(scene))
        assert scenes_equal(scene, again)


# -------------------------------------------------------------- loading
@pytest.mark.parametrize("name", PAPER_SCENES)
def test_load_paper_scenes_with_paper_depths(name):
    scene = load(name)
    assert scene.n_elements == PAPER_ELEMENTS[name]
    assert scene.max_depth == PAPER_DEPTH[name]
    assert scene.name == name
    assert load(name.upper(), max_depth=7).max_depth == 7
    summary = scene.summary()
    assert json.loads(json.dumps(summary)) == summary
    assert summary["elements"] == sum(summary["counts"].values()) == PAPER_ELEMENTS[name]


def test_paper_scene_table():
    assert PAPER_SCENES == ("balls", "tetra", "shell", "room", "fluid")
    assert [PAPER_DEPTH[n] for n in PAPER_SCENES] == [2, 2, 2, 4, 5]
    assert [load(n).n_lights for n in ("balls", "tetra", "shell")] == [3, 1, 1]
    assert load("shells").name == "shell"


def test_load_unknown_name_lists_the_valid_ones():
    with pytest.raises(ValueError, match="balls, tetra, shell, room, fluid"):
        load("teapot")


def test_load_missing_files_name_them(tmp_path):
    for missing in (tmp_path / "gone.nff", str(tmp_path / "gone.obj"), "no/such/scene"):
        with pytest.raises(FileNotFoundError, match="gone|no/such"):
            load(missing)


def test_load_rejects_bad_depth_and_unknown_files(tmp_path):
    with pytest.raises(ValueError, match="max_depth"):
        load("tetra", max_depth=-1)
    other = tmp_path / "scene.txt"
    other.write_text("s 0 0 0 1")
    with pytest.raises(ValueError, match=r"\.nff or \.obj"):
        load(other)


def test_load_nff_keeps_file_depth_unless_overridden(tmp_path):
    path = write_nff(load("fluid"), tmp_path / "fluid.nff")
    assert load(path).max_depth == 5
    assert load(str(path), max_depth=1).max_depth == 1
    plain = tmp_path / "plain.nff"
    plain.write_text("v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\ns 0 0 0 1\n")
    assert load(plain).max_depth == 5


CUBE_OBJ = """# unit cube, quads and a negative index
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vn 0 0 1
f 1 4 3 2
f 5/1/1 6/1/1 7/1/1 8/1/1
f 1 2 6 5
f 2//1 3//1 7//1 6//1
f 3 4 8 7
f -8 -4 -1 -5
"""


def test_load_obj_fan_triangulates_and_frames_the_mesh(tmp_path):
    path = tmp_path / "cube.obj"
    path.write_text(CUBE_OBJ)
    scene = load(path)
    assert scene.n_elements == scene.counts()["triangle"] == 12
    assert scene.n_lights == 1 and scene.max_depth == 5 and scene.name == "cube"
    np.testing.assert_array_equal(scene.triangle_vertices[0],
                                  [[0, 0, 0], [0, 1, 0], [1, 1, 0]])
    eye = np.array(scene.camera.eye)
    assert np.allclose(scene.camera.look_at, [0.5, 0.5, 0.5])
    # the whole bounding sphere lies inside the field of view
    radius = np.sqrt(3) / 2
    distance = np.linalg.norm(eye - 0.5)
    assert np.degrees(np.arcsin(radius / distance)) < scene.camera.angle / 2
    assert load(path, max_depth=2).max_depth == 2


@pytest.mark.parametrize("body, message", [
    ("v 0 0\nf 1 1 1", ":1: expected three finite numbers"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4", ":4: expected a vertex index in 1..3"),
    ("v 0 0 0\nv 1 0 0\nf 1 2", ":3: expected at least three vertices"),
    ("v 0 0 0\nv x 0 0", ":2: expected three numbers"),
    ("v 0 0 0\n", "at least one face"),
])
def test_obj_errors(tmp_path, body, message):
    path = tmp_path / "bad.obj"
    path.write_text(body)
    with pytest.raises(OBJError, match=message):
        read_obj(path)
