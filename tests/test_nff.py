"""NFF reading and writing: every directive, every error, exact round trips."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracer.scenes.nff import NFFError, format_nff, parse_nff, read_nff, write_nff
from tracer.scenes.model import ElementKind, Material, SceneBuilder, scenes_equal

# Copies of ../shared/reference/spd (output of the original SPD generators).
REFERENCE = Path(__file__).resolve().parent / "data" / "spd"
needs_reference = pytest.mark.skipif(not REFERENCE.is_dir(), reason="reference SPD files absent")

VIEW = """v
from 1 2 3
at 0 0 0
up 0 0 1
angle 40
hither 0.5
resolution 64 32
"""


# ------------------------------------------------------------ directives
def test_view_background_lights_and_material():
    scene = parse_nff("b 0.1 0.2 0.3\n" + VIEW + "l 1 2 3\nl 4 5 6 0.5 0.25 1\n"
                      "f 1 0.5 0 0.7 0.3 20 0.1 1.5\ns 0 0 0 1\n")
    cam = scene.camera
    assert cam.eye == (1, 2, 3) and cam.look_at == (0, 0, 0) and cam.up == (0, 0, 1)
    assert cam.angle == 40 and cam.hither == 0.5 and cam.resolution == (64, 32)
    np.testing.assert_array_equal(scene.background, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(scene.light_position, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(scene.light_color, [[1, 1, 1], [0.5, 0.25, 1]])
    np.testing.assert_array_equal(scene.material_color, [[1, 0.5, 0]])
    assert (scene.material_kd[0], scene.material_ks[0], scene.material_shine[0],
            scene.material_t[0], scene.material_ior[0]) == (0.7, 0.3, 20, 0.1, 1.5)
    assert scene.max_depth == 5  # NFF carries no depth: the SPD default


def test_light_colour_is_optional_before_any_keyword():
    scene = parse_nff(VIEW + "l 1 2 3\nf 1 1 1 1 0 0 0 1\nl 0 0 9\ns 0 0 0 1\nl 1 1 1 0.2 0.2 0.2")
    np.testing.assert_array_equal(scene.light_color, [[1, 1, 1], [1, 1, 1], [0.2, 0.2, 0.2]])


def test_sphere_and_cone_with_numbers_split_over_lines_and_negative_radii():
    scene = parse_nff(VIEW + "s 1 2\n3 0.5\nc 0 0 0 1\n  0 0 2 -0.5\nc 0 0 0 -1 0 0 3 0\n")
    assert list(scene.element_kind) == [ElementKind.SPHERE, ElementKind.CONE, ElementKind.CONE]
    np.testing.assert_array_equal(scene.sphere_center, [[1, 2, 3]])
    np.testing.assert_array_equal(scene.sphere_radius, [0.5])
    np.testing.assert_array_equal(scene.cone_base_radius, [1, -1])
    np.testing.assert_array_equal(scene.cone_apex, [[0, 0, 2], [0, 0, 3]])
    np.testing.assert_array_equal(scene.cone_apex_radius, [-0.5, 0])


def test_polygons_triangles_and_patches_in_file_order():
    text = (VIEW + "p 3\n0 0 0\n1 0 0\n0 1 0\n"
            "p 5 0 0 0 2 0 0 3 1 0 1 2 0 -1 1 0\n"
            "pp 3\n0 0 1 0 0 1\n1 0 1 0 0 1\n0 1 1 0.1 0 1\n"
            "pp 4\n0 0 2 0 0 1\n1 0 2 0 0 1\n1 1 2 0 0 1\n0 1 2 0 0 1\n")
    scene = parse_nff(text)
    assert list(scene.element_kind) == [ElementKind.TRIANGLE, ElementKind.POLYGON,
                                        ElementKind.PATCH, ElementKind.PATCH]
    assert list(scene.element_index) == [0, 0, 0, 1]
    np.testing.assert_array_equal(scene.triangle_vertices[0], [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert list(scene.polygon_offsets) == [0, 5]
    assert list(scene.patch_offsets) == [0, 3, 7]
    np.testing.assert_array_equal(scene.patch_normals[2], [0.1, 0, 1])
    np.testing.assert_array_equal(scene.patch_vertices[6], [0, 1, 2])


def test_comments_are_ignored_anywhere():
    scene = parse_nff("# header\n" + VIEW + "s 0 0 0 1 # trailing\n# s 5 5 5 5\ns 1#glued\n1 1 1\n")
    assert scene.n_elements == 2
    np.testing.assert_array_equal(scene.sphere_center[1], [1, 1, 1])


def test_materials_are_shared_and_numbered_by_first_use():
    scene = parse_nff(VIEW + "f 1 0 0 1 0 0 0 1\nf 0 1 0 1 0 0 0 1\ns 0 0 0 1\n"
                      "f 1 0 0 1 0 0 0 1\ns 0 0 0 1\nf 0 1 0 1 0 0 0 1\ns 0 0 0 1\n")
    assert list(scene.element_material) == [0, 1, 0]
    np.testing.assert_array_equal(scene.material_color, [[0, 1, 0], [1, 0, 0]])


def test_objects_without_material_get_white_diffuse():
    scene = parse_nff(VIEW + "s 0 0 0 1")
    assert scene.material_kd[0] == 1 and scene.material_ks[0] == 0
    np.testing.assert_array_equal(scene.material_color, [[1, 1, 1]])


def test_max_depth_comment_and_override():
    assert parse_nff("# max_depth 3\n" + VIEW + "s 0 0 0 1").max_depth == 3
    assert parse_nff("# max_depth 3\n" + VIEW + "s 0 0 0 1", max_depth=7).max_depth == 7
    assert parse_nff(VIEW + "s 0 0 0 1 # max_depth 3").max_depth == 5  # only a whole-line comment
    assert parse_nff("# max_depth \u0663\n" + VIEW + "s 0 0 0 1").max_depth == 5  # ASCII digits only


@pytest.mark.parametrize("text", ["", "# nothing\n", "\n\n  \n", VIEW, VIEW + "l 1 1 1\nf 1 1 1 1 0 0 0 1\n"])
def test_a_scene_without_objects_is_an_error(text):
    with pytest.raises(NFFError, match="at least one object .* the scene is empty"):
        parse_nff(text, "empty.nff")


# ---------------------------------------------------------------- errors
@pytest.mark.parametrize("text, line, column, expected", [
    ("s 0 0 0", 1, 8, "a number (s: x y z radius)"),                      # missing number
    ("s 0 0\n 0 1\nx 1", 3, 1, "a keyword"),                               # unknown keyword
    ("s 0 zero 0 1", 1, 5, "a number (s: x y z radius)"),                  # not a number
    ("s 0 0 0 nan", 1, 9, "a number"),                                     # not finite
    ("f 1 1 1 1 0 0 0", 1, 16, "a number (f: r g b Kd Ks shine T ior)"),
    ("l 1 2", 1, 6, "a number (x y z of the light)"),
    ("l 1 2 3 0.5 0.5", 1, 16, "a number (r g b of the light)"),
    ("p 2\n0 0 0\n1 0 0", 1, 3, "too few vertices"),
    ("p three", 1, 3, "a vertex count after 'p'"),
    ("p 3\n0 0 0\n1 1 1\n2 2 2", 1, 1, "degenerate polygon"),
    ("pp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 0 0 0 0 1", 1, 1, "degenerate polygon"),
    ("p 4\n0 0 0\n1 0 0\n1 1 0", 4, 6, "a number (p 4: 4 x x y z)"),
    ("pp 3\n0 0 0 0 0 1\n1 0 0 0 0", 3, 10, "x y z nx ny nz"),
    ("s 0 0 0 1\nv\nfrom 0 0 1", 2, 1, "view after objects"),
    ("s 0 0 0 1\nfrom 0 0 1", 2, 1, "view after objects"),
    ("from 0 0 1", 1, 1, "'v' before the view parameter 'from'"),
    ("v\nangle 180", 2, 7, "an angle in (0, 180) degrees"),
    ("v\nresolution 512 51.2", 2, 16, "a positive integer (resolution height)"),
    ("v\nfrom 0 0 0\nat 0 0 0\ns 0 0 0 1", 1, 1, "a complete view: missing 'up', 'angle', 'hither', 'resolution'"),
    ("v\nfrom 0 0 1\nat 0 0 0\nup 0 0 2\nangle 40\nhither 1\nresolution 8 8\ns 0 0 0 1", 4, 1,
     "an 'up' direction not parallel to the view direction"),
    ("v\nfrom 0 0 1\nat 0 0 0\nup 0 0 0\nangle 40\nhither 1\nresolution 8 8\ns 0 0 0 1", 4, 1,
     "an 'up' direction not parallel"),
    ("s 0 0 0 1\ns 1 1 1 1", 1, 1, "a view ('v' with from, at, up, angle, hither, resolution)"),
    ("s 1_0 0 0 1", 1, 3, "a number (s: x y z radius)"),                    # Python-only syntax
    ("s \u0661 0 0 1", 1, 3, "a number (s: x y z radius)"),                # Arabic-Indic digit
    ("s 0x10 0 0 1", 1, 3, "a number"),
    ("s 0 0 0 inf", 1, 9, "a number"),
    ("s 0 0 0 1e", 1, 9, "a number"),
    ("p \u0663 0 0 0 1 0 0 0 1 0", 1, 3, "a vertex count after 'p'"),
    ("v\nresolution 1_0 10", 2, 12, "a positive integer (resolution width)"),
    ("pp 3\n0 0 0 0 0 1\n1 0 0 0 0 0\n0 1 0 0 0 1", 1, 1, "a non-zero normal at every vertex"),
    ("s 0 0 0 -1", 1, 9, "a positive sphere radius"),
    ("c 0 0 0 1 0 0 0 2", 1, 11, "degenerate cone"),
    ("b 0 0", 1, 6, "a number (r g b of the background)"),
])
def test_errors_name_line_column_and_what_was_expected(text, line, column, expected):
    with pytest.raises(NFFError) as caught:
        parse_nff(text, "snippet.nff")
    error = caught.value
    assert (error.file, error.line, error.column) == ("snippet.nff", line, column)
    assert expected in error.expected
    assert str(error).startswith(f"snippet.nff:{line}:{column}: expected ")
    assert isinstance(error, ValueError)


def test_error_at_end_of_file_says_so():
    with pytest.raises(NFFError, match=r"found end of file"):
        parse_nff("s 0 0 0 1\np 3\n0 0 0\n")


def test_read_nff_reports_the_path_and_missing_files(tmp_path):
    bad = tmp_path / "bad.nff"
    bad.write_text("s 0 0 0 1\nq 1 2 3\n")
    with pytest.raises(NFFError, match=r"bad\.nff:2:1: expected a keyword"):
        read_nff(bad)
    with pytest.raises(FileNotFoundError, match="missing.nff"):
        read_nff(tmp_path / "missing.nff")


# ------------------------------------------------------------ round trip
def _every_kind_scene():
    return parse_nff("b 0.1 0.2 0.3\n" + VIEW + "l 1 2 3\nl 4 5 6 0.5 0.25 1\n"
                     "f 0.3 0.1 0.7 0.6 0.4 12.5 0.25 1.33\n"
                     "s 0.1 0.2 0.3 0.123456789012345\n"
                     "p 3 0 0 0 1 0 0 0 1 0\n"
                     "f 1 1 1 1 0 0 0 1\n"
                     "p 4 0 0 0 1 0 0 1 1 0 0 1 0\n"
                     "pp 3 0 0 1 0 0 1 1 0 1 0 0 1 0 1 1 0.1 0 1\n"
                     "c 0 0 0 1 0 0 2 -0.5\n"
                     "f 0.3 0.1 0.7 0.6 0.4 12.5 0.25 1.33\n"
                     "s 1e-300 -2.5e10 3 7\n", max_depth=3)


def test_round_trip_is_exact_for_every_kind(tmp_path):
    scene = _every_kind_scene()
    path = write_nff(scene, tmp_path / "all.nff")
    again = read_nff(path)
    assert scenes_equal(scene, again) and again.max_depth == 3
    assert format_nff(again).splitlines()[1:] == path.read_text().splitlines()[1:]
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_write_is_atomic_and_keeps_the_old_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "scene.nff"
    path.write_text("old")
    import os

    def explode(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", explode)  # the rename that would put the new file in place
    with pytest.raises(OSError):
        write_nff(_every_kind_scene(), path)
    assert path.read_text() == "old"
    assert list(tmp_path.iterdir()) == [path]


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=1e-6, max_value=1e6, allow_nan=False)
non_negative = st.floats(min_value=0.0, max_value=1e6, allow_nan=False)


@st.composite
def scenes(draw):
    builder = SceneBuilder("random")
    builder.background = draw(st.tuples(finite, finite, finite))
    for _ in range(draw(st.integers(0, 3))):
        builder.light(draw(st.tuples(finite, finite, finite)),
                      draw(st.sampled_from([(1.0, 1.0, 1.0), (0.5, 0.2, 0.1)])))
    for _ in range(draw(st.integers(1, 8))):
        builder.material(Material(draw(st.tuples(non_negative, non_negative, non_negative)),
                                  *draw(st.tuples(non_negative, non_negative, finite, non_negative, non_negative))))
        kind = draw(st.sampled_from(["s", "p", "pp", "c"]))
        centre = np.array(draw(st.tuples(finite, finite, finite)))
        size = draw(positive)
        if kind == "s":
            builder.sphere(centre, size)
        elif kind == "c":
            builder.cone(centre, draw(finite), centre + (0, 0, size), draw(finite))
        else:
            n = draw(st.integers(3, 7))
            angles = 2 * np.pi * np.arange(n) / n
            ring = centre + size * np.column_stack([np.cos(angles), np.sin(angles),
                                                    np.zeros(n)])
            if kind == "p":
                builder.polygon(ring)
            else:
                builder.patch(ring, np.tile([0.0, 0.0, 1.0], (n, 1)))
    return builder.build()


@settings(max_examples=40, deadline=None)
@given(scenes())
def test_round_trip_property(scene):
    again = parse_nff(format_nff(scene))
    assert scenes_equal(scene, again)


# --------------------------------------------------------- reference files
@needs_reference
@pytest.mark.parametrize("name, spheres, polygons, triangles, lights, materials", [
    ("balls", 7381, 1, 0, 3, 2),
    ("tetra", 0, 0, 4096, 1, 1),
    ("shells", 5761, 0, 0, 1, 1),
])
def test_reference_files_load_with_documented_counts(name, spheres, polygons, triangles,
                                                     lights, materials):
    scene = read_nff(REFERENCE / f"{name}.nff")
    counts = scene.counts()
    assert (counts["sphere"], counts["polygon"], counts["triangle"]) == \
        (spheres, polygons, triangles)
    assert scene.n_elements == spheres + polygons + triangles
    assert scene.n_lights == lights and len(scene.material_kd) == materials
    assert scene.camera.resolution == (512, 512) and scene.camera.angle == 45
    assert list(scene.element_index[:3]) == [0, 1, 2] or name == "balls"


@needs_reference
def test_reference_views_and_materials():
    balls = read_nff(REFERENCE / "balls.nff")
    assert balls.camera.eye == (2.1, 1.3, 1.7) and balls.camera.up == (0, 0, 1)
    assert balls.camera.hither == 0.01
    np.testing.assert_array_equal(balls.material_ks, [0.0, 0.5])  # floor diffuse, balls shiny
    assert balls.element_kind[0] == ElementKind.POLYGON and balls.element_material[0] == 0
    assert set(balls.element_material[1:]) == {1}
    tetra = read_nff(REFERENCE / "tetra.nff")
    assert tetra.material_ks[0] == 0 and tetra.material_t[0] == 0  # no secondary rays
    assert tetra.camera.hither == 1
    np.testing.assert_array_equal(tetra.light_position, [[2, -18, -5]])
    shells = read_nff(REFERENCE / "shells.nff")
    assert shells.material_ks[0] == 0.2
    assert shells.camera.eye == (-6, -60, 35) and shells.camera.look_at == (0, 8, -15)
    for scene in (balls, tetra, shells):
        np.testing.assert_array_equal(scene.background, [0.078, 0.361, 0.753])
        np.testing.assert_array_equal(scene.light_color, np.ones((scene.n_lights, 3)))


@needs_reference
def test_reference_round_trip(tmp_path):
    scene = read_nff(REFERENCE / "balls.nff")
    again = read_nff(write_nff(scene, tmp_path / "balls.nff"))
    assert scenes_equal(scene, again)
    assert math.isclose(again.sphere_radius[1], 0.166667)


# ------------------------------------------------------- strictness and warnings
def test_errors_found_after_the_tokens_name_the_line_crlf_too():
    text = VIEW.replace("up 0 0 1", "up 1 2 3") + "s 0 0 0 1\n"
    with pytest.raises(NFFError, match=r"^cam\.nff:4:1: expected an 'up' direction not parallel"):
        parse_nff(text.replace("\n", "\r\n"), "cam.nff")


def test_non_planar_polygons_and_flat_cones_warn_once_with_file_and_line():
    bent = "p 4\n0 0 0\n1 0 0\n1 1 0.5\n0 1 0\n"
    text = VIEW + "s 0 0 0 1\n" + bent + bent + "c 0 0 0 0 0 0 1 0\n"
    with pytest.warns(UserWarning) as caught:
        scene = parse_nff(text, "bent.nff")
    messages = sorted(str(w.message) for w in caught)
    assert len(messages) == 2 and messages[0] == "bent.nff:19: cone has both radii 0 (it is invisible)"
    # the corners lie 1/8 above and below the plane through their centroid, tilted a little by the bend
    assert re.fullmatch(r"bent\.nff:9: polygon is not planar \(a vertex lies 0\.1[12] of its size off its "
                        r"plane\); 1 more like it", messages[1]), messages[1]
    assert scene.counts()["polygon"] == 2


def test_planar_reference_scenes_and_huge_coordinates_are_quiet():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy overflow warnings included
        scene = parse_nff(VIEW + "p 3 0 0 0 1e300 0 0 0 1e300 0\np 4 0 0 1 1e300 0 1 1e300 1e300 1 0 1e300 1\n")
        assert scene.counts()["triangle"] == 1 and scene.counts()["polygon"] == 1
        if REFERENCE.is_dir():
            for name in ("balls", "tetra", "shells"):
                read_nff(REFERENCE / f"{name}.nff")


def test_read_nff_refuses_a_fifo_without_blocking(tmp_path):
    import os

    os.mkfifo(tmp_path / "pipe.nff")
    with pytest.raises(ValueError, match="not a regular file"):
        read_nff(tmp_path / "pipe.nff")


def _either(reader, text):
    try:
        return reader(text)
    except NFFError as error:
        return ("error", error.line, error.column, error.expected)


def _positioned(text):
    from tracer.scenes.nff import _normalise_line_breaks, _parse_positioned
    from tracer.scenes.nff_fast import assemble

    parts, _ = _parse_positioned(_normalise_line_breaks(text), "<string>")
    return assemble(parts, "scene", 5)


_WORDS = ["v", "from", "at", "up", "angle", "hither", "resolution", "b", "l", "f", "s", "c", "p", "pp",
          "0", "1", "-1", "2.5", ".5", "1e3", "3", "4", "0.25", "1_0", "inf", "x", "#", "\n", "\u0663", "\r\n"]


@settings(max_examples=300, deadline=2000)
@given(st.lists(st.sampled_from(_WORDS), max_size=60), st.booleans())
def test_fuzzed_text_gives_a_scene_or_an_nff_error_and_both_readers_agree(words, with_view):
    import warnings

    text = (VIEW if with_view else "") + " ".join(words)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fast = _either(parse_nff, text)
        slow = _either(_positioned, text)
    if isinstance(fast, tuple):
        assert fast == slow
    else:
        assert not isinstance(slow, tuple) and scenes_equal(fast, slow)


@settings(max_examples=150, deadline=2000)
@given(st.integers(0, 10**6), st.sampled_from(["delete", "flip", "insert"]), st.text(max_size=3))
def test_damaged_files_never_give_a_traceback(position, damage, extra):
    import warnings

    text = format_nff(_every_kind_scene())
    at = position % len(text)
    if damage == "delete":
        text = text[:at] + text[at + 1:]
    elif damage == "flip":
        text = text[:at] + chr(ord(text[at]) ^ 0x10) + text[at + 1:]
    else:
        text = text[:at] + extra + text[at:]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        try:
            parse_nff(text)
        except NFFError:
            pass
