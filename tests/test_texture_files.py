"""Textures in scene files: the NFF extension, OBJ with MTL, PNG and JPEG images."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

import tracer.scenes.nff as nff
from tracer.scenes.images import png_bytes, read_image, write_png
from tracer.scenes.nff import NFFError, format_nff, parse_nff, read_nff, write_nff
from tracer.scenes.nff_fast import Fallback, parse_fast
from tracer.scenes.obj import OBJError, read_obj
from tracer.trace.records import RecordKind
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.model import Camera, ElementKind, Material, SceneBuilder, scenes_equal, untextured
from tracer.rendering.texture import procedural_texture

DATA = Path(__file__).resolve().parent / "data" / "textures"
NAN = np.nan
# tests/data/textures/board.png, 4 x 2 texels, row 0 at the top
BOARD = np.array([[(255, 0, 0, 255), (0, 255, 0, 255), (0, 0, 255, 255), (255, 255, 255, 255)],
                  [(0, 0, 0, 255), (128, 128, 128, 255), (255, 255, 0, 128), (0, 255, 255, 0)]], dtype=np.uint8)

VIEW = "v\nfrom 0 -6 3\nat 0 0 0\nup 0 0 1\nangle 45\nhither 0.01\nresolution 16 16\n"
TRIANGLE_UV = "tp 3\n-1 0 0 0 0\n1 0 0 1 0\n0 0 1 0.5 1\n"


@pytest.fixture
def textures(tmp_path):
    """A folder with board.png and board.nff (copied from tests/data/textures)."""
    for name in ("board.png", "board.nff"):
        shutil.copy(DATA / name, tmp_path / name)
    return tmp_path


# ------------------------------------------------------------------ images
def test_the_png_fixture_reads_as_its_texels():
    np.testing.assert_array_equal(read_image(DATA / "board.png"), BOARD)


def test_grey_and_sixteen_bit_pngs_become_rgba(tmp_path):
    grey = read_image(DATA / "grey.png")  # 8-bit grey [[0, 64], [128, 255]]
    np.testing.assert_array_equal(grey[..., 0], [[0, 64], [128, 255]])
    np.testing.assert_array_equal(grey[..., 1], grey[..., 0])
    np.testing.assert_array_equal(grey[..., 3], 255)
    Image.fromarray(np.array([[0, 256], [65535, 4660]], dtype=np.uint16)).save(tmp_path / "deep.png")
    np.testing.assert_array_equal(read_image(tmp_path / "deep.png")[..., 2], [[0, 1], [255, 18]])  # high byte


def test_jpeg_reads_as_rgba_close_to_what_was_saved(tmp_path):
    colour = np.zeros((16, 16, 3), dtype=np.uint8)
    colour[:] = (200, 100, 50)
    Image.fromarray(colour).save(tmp_path / "flat.jpg", quality=95)
    image = read_image(tmp_path / "flat.jpg")
    assert image.shape == (16, 16, 4) and image.dtype == np.uint8
    assert np.abs(image[..., :3].astype(int) - (200, 100, 50)).max() <= 3  # lossy, but a flat colour survives
    np.testing.assert_array_equal(image[..., 3], 255)


def test_written_png_reads_back_exactly(tmp_path):
    image = procedural_texture(7, 5, seed=3)
    image[0, 0, 3] = 17  # alpha is kept too
    assert write_png(image, tmp_path / "t.png") == tmp_path / "t.png"
    np.testing.assert_array_equal(read_image(tmp_path / "t.png"), image)
    assert list(tmp_path.iterdir()) == [tmp_path / "t.png"]


def test_image_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"no such image file: .*gone\.png"):
        read_image(tmp_path / "gone.png")
    with pytest.raises(IsADirectoryError, match="is a folder"):
        read_image(tmp_path)
    (tmp_path / "notes.png").write_text("not an image")
    with pytest.raises(ValueError, match=r"not a PNG or JPEG image: .*notes\.png"):
        read_image(tmp_path / "notes.png")
    Image.fromarray(BOARD[..., :3]).save(tmp_path / "board.gif")
    with pytest.raises(ValueError, match=r"not a PNG or JPEG image: .*board\.gif"):
        read_image(tmp_path / "board.gif")
    (tmp_path / "cut.png").write_bytes(png_bytes(procedural_texture(64, seed=1))[:200])
    with pytest.raises(ValueError, match=r"unreadable image .*cut\.png"):
        read_image(tmp_path / "cut.png")
    with pytest.raises(ValueError, match=r"uint8 of shape \(height, width, 4\)"):
        png_bytes(np.zeros((2, 2, 3), dtype=np.uint8))


# ------------------------------------------------------- NFF: reading the extension
def test_board_nff_parses_to_the_expected_arrays():
    scene = read_nff(DATA / "board.nff")
    assert list(scene.element_kind) == [ElementKind.POLYGON, ElementKind.SPHERE, ElementKind.TRIANGLE,
                                        ElementKind.PATCH, ElementKind.TRIANGLE, ElementKind.SPHERE]
    # rows by first use: white + board x2, blue + noise, blue untextured; the last sphere reuses row 0
    assert list(scene.element_material) == [0, 0, 1, 1, 2, 0]
    assert list(scene.material_texture) == [0, 1, -1]
    assert list(scene.material_uv_scale) == [2.0, 1.0, 1.0]
    np.testing.assert_array_equal(scene.material_color, [[1, 1, 1], [0.5, 0.5, 1], [0.5, 0.5, 1]])
    np.testing.assert_array_equal(scene.texture_size, [[4, 2], [8, 4]])
    assert list(scene.texture_offsets) == [0, 8, 40]
    np.testing.assert_array_equal(scene.texture(0), BOARD)
    np.testing.assert_array_equal(scene.texture(1), procedural_texture(8, 4, seed=5, cells=2))
    np.testing.assert_array_equal(scene.polygon_uv, [[0, 0], [1, 0], [1, 1], [0, 1]])
    np.testing.assert_array_equal(scene.polygon_vertices[2], [2, 2, 0])
    np.testing.assert_array_equal(scene.triangle_uv, [[[0, 0], [0.5, 1], [1, 0]], [[NAN, NAN]] * 3])
    np.testing.assert_array_equal(scene.triangle_vertices[0], [[-1, 0, 0.5], [0, 0, 1.5], [1, 0, 0.5]])
    np.testing.assert_array_equal(scene.patch_uv, [[0, 0], [1, 0], [0.5, 1]])
    np.testing.assert_array_equal(scene.patch_normals, [[0, -1, 0]] * 3)
    np.testing.assert_array_equal(scene.patch_vertices[2], [0, 1, 1.5])


def test_a_texture_lasts_until_the_next_f_or_usetexture_none():
    text = (VIEW + "texture a procedural 2 2 1\n"
            "usetexture a\ns 0 0 0 1\n"                    # white default material, textured
            "f 1 0 0 1 0 0 0 1\ns 0 0 0 1\n"                # f: untextured again
            "usetexture a 0.5\ns 0 0 0 1\nusetexture none\ns 0 0 0 1\n"
            "usetexture a 0.5\ns 0 0 0 1\n")
    scene = parse_nff(text)
    assert list(scene.element_material) == [0, 1, 2, 1, 2]
    assert list(scene.material_texture) == [0, -1, 0]
    assert list(scene.material_uv_scale) == [1, 1, 0.5]


def test_uv_without_a_texture_in_use_is_kept_and_unused_textures_count():
    scene = parse_nff(VIEW + "texture a procedural 3 1 0\ntexture a2 procedural 1 2 0 1\n" + TRIANGLE_UV)
    np.testing.assert_array_equal(scene.texture_size, [[3, 1], [1, 2]])
    assert list(scene.material_texture) == [-1]
    np.testing.assert_array_equal(scene.triangle_uv[0], [[0, 0], [1, 0], [0.5, 1]])


def test_texture_files_are_found_beside_the_nff_file_not_in_the_current_folder(textures, tmp_path_factory,
                                                                                 monkeypatch):
    monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))
    np.testing.assert_array_equal(read_nff(textures / "board.nff").texture(0), BOARD)
    text = (textures / "board.nff").read_text()
    np.testing.assert_array_equal(parse_nff(text, str(textures / "board.nff")).texture(0), BOARD)
    np.testing.assert_array_equal(parse_nff(text, folder=textures).texture(0), BOARD)
    with pytest.raises(NFFError, match=r"^<string>:11:15: expected a readable PNG or JPEG image file "
                                        r"\(no such image file: 'board\.png'\), found 'board\.png'"):
        parse_nff(text)  # no folder: the current one, which has no board.png


@pytest.mark.parametrize("text, line, column, expected", [
    ("texture t\n", 2, 1, "an image file or 'procedural' after the texture name"),
    ("texture t s 0 0 0 1\n", 1, 11, "an image file or 'procedural' after the texture name"),
    ("texture s board.png\n", 1, 9, "a texture name after 'texture' (not a keyword)"),
    ("texture none procedural 2 2 1\n", 1, 9, "a new texture name ('none' is reserved)"),
    ("texture t procedural 2 2 1\ntexture t procedural 2 2 1\n", 2, 9, "('t' is already defined)"),
    ("texture t procedural 0 2 1\n", 1, 22, "a positive procedural texture size"),
    ("texture t procedural 2 2.5 1\n", 1, 24, "a positive integer (procedural texture height)"),
    ("texture t procedural 100000 100000 1\n", 1, 22, "a procedural texture of at most 134217728 texels"),
    ("texture t procedural 2 2 -1\n", 1, 26, "an integer >= 0 (procedural texture seed)"),
    ("texture t procedural 2 2 1 0\n", 1, 28, "a positive number of procedural texture cells"),
    ("texture t procedural 2 2 1 x\n", 1, 28, "a positive integer (procedural texture cells) or a keyword"),
    ("usetexture\n", 2, 1, "a texture name or 'none' after 'usetexture'"),
    ("texture t procedural 2 2 1\nusetexture oak\n", 2, 12,
     "a texture defined by an earlier 'texture' line or 'none' (defined: 't')"),
    ("usetexture oak\ntexture oak procedural 2 2 1\n", 1, 12, "(defined: none yet)"),
    ("texture t procedural 2 2 1\nusetexture t 0\n", 2, 14, "a positive uv scale"),
    ("texture t procedural 2 2 1\nusetexture t -2\n", 2, 14, "a positive uv scale"),
    ("texture t procedural 2 2 1\nusetexture t nan\n", 2, 14, "a number (uv scale of 'usetexture') or a keyword"),
    ("texture t procedural 2 2 1\nusetexture t\np 3 0 0 0 1 0 0 0 0 1\n", 3, 1,
     "'tp' (with u v per vertex) while texture 't' is in use: 'p' gives no (u, v) ('usetexture none' first)"),
    ("texture t procedural 2 2 1\nusetexture t\npp 3 0 0 0 0 1 0 1 0 0 0 1 0 0 0 1 0 1 0\n", 3, 1,
     "'tpp' (with u v per vertex) while texture 't' is in use"),
    ("texture t procedural 2 2 1\nusetexture t\nc 0 0 0 1 0 0 1 1\n", 3, 1,
     "no cone while texture 't' is in use (a cone has no (u, v); 'usetexture none' first)"),
    ("tp 3\n0 0 0 0 0\n1 0 0 1 0\n0 0 1 0\n", 5, 1, "a number (tp 3: 3 x x y z u v)"),
    ("tp 3\n0 0 0 0 0\n1 0 0 1 0\n0 0 1 0 inf\n", 4, 9, "a number (tp 3: 3 x x y z u v)"),
    ("tp 2\n0 0 0 0 0\n1 0 0 1 0\n", 1, 4, "a polygon with at least 3 vertices"),
    ("tp 3\n0 0 0 0 0\n1 0 0 1 0\n2 0 0 0 1\n", 1, 1, "degenerate polygon"),
    ("tpp 3\n0 0 0 0 1 0 0 0\n1 0 0 0 1 0 1 0\n0 0 1 0 0 0 0 1\n", 1, 1,
     "a non-zero normal at every vertex of 'tpp' (zero normal)"),
    ("tpp 3\n0 0 0 0 1 0 0 0\n1 0 0 0 1 0 1 0\n0 0 1 0 1 0 0", 4, 14, "a number (tpp 3: 3 x x y z nx ny nz u v)"),
])
def test_extension_errors_name_line_column_and_what_was_expected(text, line, column, expected):
    with pytest.raises(NFFError) as caught:
        parse_nff(VIEW + text, "snippet.nff")
    error = caught.value
    assert expected in error.expected, error.expected
    assert (error.file, error.line - 7, error.column) == ("snippet.nff", line, column), str(error)


def test_an_object_with_uv_before_the_view_is_an_object_before_the_view():
    with pytest.raises(NFFError, match=r"^s\.nff:5:1: expected the view \('v \.\.\.'\) before the first object "
                                       r"\(view after objects\), found 'v'"):
        parse_nff(TRIANGLE_UV + VIEW, "s.nff")


def test_missing_and_unreadable_images_name_the_nff_file_line_and_image(textures):
    (textures / "notes.txt").write_text("not an image")
    lines = (textures / "board.nff").read_text().splitlines()
    for replacement, reason in (("texture board gone.png", r"no such image file: '.*gone\.png'"),
                                ("texture board notes.txt", r"not a PNG or JPEG image: '.*notes\.txt'"),
                                ("texture board .", r"not an image file: '.*' is a folder")):
        lines[10] = replacement
        (textures / "bad.nff").write_text("\n".join(lines))
        with pytest.raises(NFFError, match=rf"bad\.nff:11:15: expected a readable PNG or JPEG image file "
                                           rf"\({reason}\), found "):
            read_nff(textures / "bad.nff")


# --------------------------------------------------------- NFF: fast path and strict path
def _plain_text():
    return (f"b 0.1 0.2 0.3\n{VIEW}l 1 2 3\nl 4 5 6 0.5 0.25 1\nf 0.3 0.1 0.7 0.6 0.4 12.5 0.25 1.33\n"
            "s 0.1 0.2 0.3 0.5\np 3 0 0 0 1 0 0 0 1 0\nf 1 1 1 1 0 0 0 1\np 4 0 0 0 1 0 0 1 1 0 0 1 0\n"
            "pp 3 0 0 1 0 0 1 1 0 1 0 0 1 0 1 1 0.1 0 1\nc 0 0 0 1 0 0 2 -0.5\n")


def test_plain_nff_takes_the_fast_path_with_the_positional_readers_result(monkeypatch):
    from tracer.scenes.nff_fast import assemble

    text = _plain_text()
    positional, _ = nff._parse_positioned(text, "<string>")
    slow = assemble(positional, "scene", 5)

    def refuse(*args, **kwargs):
        raise AssertionError("plain NFF went to the positional reader")

    monkeypatch.setattr(nff, "_parse_positioned", refuse)
    fast = parse_nff(text)
    assert scenes_equal(fast, slow)
    fields = untextured(2, 1, 4, 3)
    for name, value in fields.items():
        np.testing.assert_array_equal(getattr(fast, name), value)
    assert fast.n_textures == 0 and fast.texture_texels.shape == (0, 4)
    # a reference SPD file too, when present
    reference = Path(__file__).resolve().parent / "data" / "spd" / "balls.nff"
    if reference.is_file():
        assert read_nff(reference).n_elements == 7382


def test_the_extension_goes_to_the_positional_reader(monkeypatch):
    for keyword_line in ("texture a procedural 2 2 1\n", "usetexture none\n", TRIANGLE_UV,
                         "tpp 3 0 0 0 0 1 0 0 0 1 0 0 0 1 0 1 0 0 0 1 0 1 0 0 1\n"):
        with pytest.raises(Fallback):
            parse_fast(VIEW + "s 0 0 0 1\n" + keyword_line)
    calls = []
    original = nff._parse_positioned
    monkeypatch.setattr(nff, "_parse_positioned", lambda *args: calls.append(1) or original(*args))
    scene = parse_nff(VIEW + "l 1 1 1\ntexture a procedural 2 2 1\nusetexture a\ns 0 0 0 1\n")
    assert calls == [1] and list(scene.material_texture) == [0]
    np.testing.assert_array_equal(scene.light_color, [[1, 1, 1]])  # 'texture' ends the light's optional colour


# ------------------------------------------------------------- NFF: writing
def _textured_scene():
    builder = SceneBuilder("mixed")
    builder.camera = Camera((0.0, -6.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 45.0, 0.01, (16, 16))
    builder.light((0, -5, 8))
    unused = builder.texture(procedural_texture(3, 2, seed=9))
    wood = builder.texture(procedural_texture(8, 4, seed=1, cells=2))
    board = builder.texture(BOARD)
    assert (unused, wood, board) == (0, 1, 2)
    builder.material(Material((1, 0.9, 0.8), 0.7, 0.2, 10, 0, 1, texture=wood, uv_scale=2.5))
    builder.polygon([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], uv=[[0, 0], [1, 0], [1, 1], [0, 1]])
    builder.sphere((0, 0, 1), 0.5)
    builder.material(Material((0.3, 0.3, 0.3), texture=board))
    builder.triangle([[-1, 0, 0.5], [1, 0, 0.5], [0, 0, 1.5]], uv=[[0.1, 0.2], [0.9, 0.2], [0.5, 0.95]])
    builder.patch([[-1, 1, 0.5], [1, 1, 0.5], [0, 1, 1.5]], [[0, -1, 0]] * 3, uv=[[0, 0], [1, 0], [0.5, 1]])
    builder.material(Material((0.3, 0.3, 0.3)))  # the same colour untextured: a row of its own
    builder.triangle([[-1, -1, 0.1], [1, -1, 0.1], [0, -1, 1.1]], uv=[[0, 0], [1, 0], [0, 1]])  # uv, unused
    builder.polygon([[3, 0, 0], [4, 0, 0], [4, 1, 0], [3, 1, 0]])
    builder.cone((3, 3, 0), 0.5, (3, 3, 1), 0.25)
    return builder.build()


def test_textured_round_trip_is_exact_and_writes_pngs_beside_the_nff(tmp_path):
    scene = _textured_scene()
    path = write_nff(scene, tmp_path / "mixed.nff")
    names = ["mixed.t0.png", "mixed.t1.png", "mixed.t2.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mixed.nff", *names]
    text = path.read_text()
    assert [line for line in text.splitlines() if line.startswith(("texture", "usetexture"))] == \
        [f"texture t{k} {name}" for k, name in enumerate(names)] + ["usetexture t1 2.5", "usetexture t2"]
    again = read_nff(path)
    assert scenes_equal(scene, again)
    np.testing.assert_array_equal(read_image(tmp_path / "mixed.t2.png"), BOARD)
    assert format_nff(again, names).splitlines()[1:] == text.splitlines()[1:]


def test_a_read_textured_file_round_trips_jpeg_textures_included(textures):
    colour = procedural_texture(16, 8, seed=2)[..., :3]
    Image.fromarray(colour).save(textures / "photo.jpg", quality=80)
    text = (textures / "board.nff").read_text().replace("texture noise procedural 8 4 5 2", "texture noise photo.jpg")
    (textures / "photo.nff").write_text(text)
    scene = read_nff(textures / "photo.nff")
    np.testing.assert_array_equal(scene.texture(1), read_image(textures / "photo.jpg"))
    out = textures / "out"
    out.mkdir()
    again = read_nff(write_nff(scene, out / "copy.nff"))
    assert scenes_equal(scene, again)  # the JPEG's decoded texels, kept exactly as PNG


def test_plain_scenes_are_written_as_plain_nff(tmp_path):
    scene = parse_nff(_plain_text())
    text = write_nff(scene, tmp_path / "plain.nff").read_text()
    assert not any(line.split()[0] in ("texture", "usetexture", "tp", "tpp") for line in text.splitlines()
                   if line.strip())
    assert list(tmp_path.iterdir()) == [tmp_path / "plain.nff"]


def test_a_folder_name_with_spaces_gives_texture_files_of_one_token(tmp_path):
    path = write_nff(_textured_scene(), tmp_path / "my scene #1.nff")
    assert (tmp_path / "my_scene__1.t0.png").is_file()
    assert scenes_equal(read_nff(path), _textured_scene())


def test_scenes_nff_cannot_express_are_refused_by_the_writer(tmp_path):
    import dataclasses

    names = ["a.png", "b.png", "c.png"]
    scene = _textured_scene()
    with pytest.raises(ValueError, match="texture_files must name a file for each"):
        format_nff(scene)
    with pytest.raises(ValueError, match="must be one token"):
        format_nff(scene, ["a.png", "b c.png", "d.png"])
    bare_polygon = scene.element_material.copy()
    bare_polygon[5] = 1  # the polygon without (u, v) gets the board material
    with pytest.raises(ValueError, match="element 5 is textured but has no"):
        format_nff(dataclasses.replace(scene, element_material=bare_polygon), names)
    textured_cone = scene.element_material.copy()
    textured_cone[6] = 0
    with pytest.raises(ValueError, match="element 6 is a cone with a textured material"):
        format_nff(dataclasses.replace(scene, element_material=textured_cone), names)
    half = scene.triangle_uv.copy()
    half[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"\(u, v\) at some vertices and not at others"):
        format_nff(dataclasses.replace(scene, triangle_uv=half), names)
    with pytest.raises(ValueError):
        write_nff(dataclasses.replace(scene, triangle_uv=half), tmp_path / "half.nff")
    assert list(tmp_path.iterdir()) == []  # nothing written


# ---------------------------------------------------------------- rendering
def test_a_textured_nff_renders_with_texel_records_and_the_plain_one_without():
    scene = read_nff(DATA / "board.nff")
    counts = render(scene, options=RenderOptions(size=8)).trace.kind_counts()
    assert counts[RecordKind.TEXEL] > 0 and counts[RecordKind.TEXTURE] > 0
    plain_text = "\n".join(line for line in (DATA / "board.nff").read_text().splitlines()
                           if not line.startswith("usetexture"))
    plain = render(parse_nff(plain_text, str(DATA / "board.nff")), options=RenderOptions(size=8)).trace.kind_counts()
    assert plain[RecordKind.TEXEL] == 0 and plain[RecordKind.TEXTURE] == 0
    assert plain[RecordKind.SPHERE] == counts[RecordKind.SPHERE]  # the same geometry, traversed alike


# --------------------------------------------------------------------- OBJ
def test_obj_with_mtl_parses_to_the_expected_arrays():
    scene = read_obj(DATA / "quad.obj")
    assert scene.counts()["triangle"] == 4
    # the quad (2 fan triangles) and the face without vt use 'board' (its texture only where uv exist)
    assert list(scene.element_material) == [0, 0, 1, 2]
    np.testing.assert_array_equal(scene.material_color, [[1, 0.5, 0.25], [1, 0, 0], [1, 0.5, 0.25]])
    assert list(scene.material_texture) == [0, -1, -1]
    np.testing.assert_array_equal(scene.material_kd, [0.8] * 3)
    np.testing.assert_array_equal(scene.texture(0), BOARD)  # map_Kd ../board.png, relative to the MTL
    np.testing.assert_array_equal(scene.triangle_uv, [[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]],
                                                      [[0, 0], [1, 0], [1, 1]], [[NAN, NAN]] * 3])
    np.testing.assert_array_equal(scene.triangle_vertices[2], [[-1, -1, 0], [1, -1, 0], [0, 0, 1]])
    counts = render(scene, options=RenderOptions(size=8)).trace.kind_counts()
    assert counts[RecordKind.TEXEL] > 0


def _write_obj(folder, body, mtl=None):
    if mtl is not None:
        (folder / "m.mtl").write_text(mtl)
    (folder / "t.obj").write_text(body)
    return folder / "t.obj"


GEOMETRY = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"


def test_obj_without_materials_or_uv_reads_as_before(tmp_path):
    scene = read_obj(_write_obj(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl ignored\nf 1 2 3\n"))
    assert list(scene.material_texture) == [-1] and scene.n_textures == 0
    np.testing.assert_array_equal(scene.material_color, [[0.8, 0.8, 0.8]])
    assert (scene.material_kd[0], scene.material_ks[0], scene.material_shine[0]) == (0.8, 0.1, 30.0)
    assert np.isnan(scene.triangle_uv).all()


def test_obj_vt_defaults_and_relative_indices(tmp_path):
    scene = read_obj(_write_obj(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.25\nvt 0.5 0.75 0.1\n"
                                          "f 1/-2 2/-1 3/1\n"))
    np.testing.assert_array_equal(scene.triangle_uv[0], [[0.25, 0], [0.5, 0.75], [0.25, 0]])


def test_texture_indices_before_any_vt_are_ignored_with_one_warning(tmp_path):
    path = _write_obj(tmp_path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/2 3/3\nf 1/7 2/7 3/7\n")
    with pytest.warns(UserWarning, match=r"t\.obj:4: a face names texture coordinates, but no 'vt'") as caught:
        scene = read_obj(path)
    assert len(caught) == 1 and np.isnan(scene.triangle_uv).all()


def test_two_materials_sharing_an_image_share_one_texture(tmp_path):
    shutil.copy(DATA / "board.png", tmp_path / "b.png")
    mtl = "newmtl a\nKd 1 1 1\nmap_Kd b.png\nnewmtl b\nKd 0.5\nmap_Kd ./b.png\n"
    scene = read_obj(_write_obj(tmp_path, "mtllib m.mtl\n" + GEOMETRY + "usemtl a\nf 1/1 2/2 3/3\n"
                                          "usemtl b\nf 1/1 2/2 3/3\n", mtl))
    assert scene.n_textures == 1 and list(scene.material_texture) == [0, 0]
    np.testing.assert_array_equal(scene.material_color, [[1, 1, 1], [0.5, 0.5, 0.5]])  # 'Kd 0.5': grey


@pytest.mark.parametrize("body, mtl, message", [
    (GEOMETRY + "vt 1 x\nf 1 2 3", None, r"t\.obj:7: expected one to three finite numbers after 'vt'"),
    (GEOMETRY + "vt\nf 1 2 3", None, r"t\.obj:7: expected one to three finite numbers after 'vt'"),
    (GEOMETRY + "f 1/1 2/4 3/3", None, r"t\.obj:7: expected a texture coordinate index in 1\.\.3 or negative, "
                                       r"found '2/4'"),
    (GEOMETRY + "f 1/1 2/x 3/3", None, r"t\.obj:7: expected a texture coordinate index, found '2/x'"),
    (GEOMETRY + "f 1/1 2 3/3", None, r"t\.obj:7: expected texture coordinates at every vertex of the face or at "
                                     r"none"),
    (GEOMETRY + "f 1/1/1/1 2 3", None, r"t\.obj:7: expected a vertex reference v, v/vt, v/vt/vn or v//vn"),
    ("mtllib gone.mtl\n" + GEOMETRY + "f 1 2 3", None, r"t\.obj:1: expected an MTL file \(no such file: "
                                                       r"'.*gone\.mtl'\), found 'gone\.mtl'"),
    ("mtllib\n" + GEOMETRY + "f 1 2 3", None, r"t\.obj:1: expected an MTL file after 'mtllib'"),
    ("mtllib m.mtl\n" + GEOMETRY + "usemtl b\nf 1 2 3", "newmtl a\n", r"t\.obj:8: expected a material defined "
                                                                     r"by 'newmtl' in the mtllib files "
                                                                     r"\(defined: 'a'\), found 'b'"),
    ("mtllib m.mtl\n" + GEOMETRY + "usemtl\nf 1 2 3", "newmtl a\n", r"t\.obj:8: expected a material name"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "Kd 1 1 1\n", r"m\.mtl:1: expected 'newmtl' before 'Kd'"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "newmtl\n", r"m\.mtl:1: expected a material name after 'newmtl'"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "newmtl a\nKd 1 1\n", r"m\.mtl:2: expected one or three finite"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "newmtl a\nKd spectral x.spd\n",
     r"m\.mtl:2: expected one or three finite numbers after 'Kd' \(r \[g b\]; 'spectral'"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "newmtl a\nmap_Kd\n", r"m\.mtl:2: expected an image file after"),
    ("mtllib m.mtl\n" + GEOMETRY + "f 1 2 3", "newmtl a\nmap_Kd -s 2 2 1 b.png\n",
     r"m\.mtl:2: expected an image file after 'map_Kd' \(map options such as -s are not supported\)"),
    ("mtllib m.mtl\n" + GEOMETRY + "usemtl a\nf 1/1 2/2 3/3", "newmtl a\n\nmap_Kd gone.png\n",
     r"m\.mtl:3: expected a readable PNG or JPEG image after 'map_Kd' \(no such image file: '.*gone\.png'\), "
     r"found 'gone\.png'"),
    ("mtllib m.mtl\n" + GEOMETRY + "usemtl a\nf 1/1 2/2 3/3", "newmtl a\nmap_Kd m.mtl\n",
     r"m\.mtl:2: expected a readable PNG or JPEG image after 'map_Kd' \(not a PNG or JPEG image"),
])
def test_obj_and_mtl_errors_name_file_line_and_what_was_expected(tmp_path, body, mtl, message):
    with pytest.raises(OBJError, match=message):
        read_obj(_write_obj(tmp_path, body, mtl))


def test_a_missing_image_of_an_unused_or_uv_less_material_is_never_read(tmp_path):
    mtl = "newmtl a\nmap_Kd gone.png\nnewmtl b\nKd 0 1 0\n"
    scene = read_obj(_write_obj(tmp_path, "mtllib m.mtl\n" + GEOMETRY + "usemtl a\nf 1 2 3\nusemtl b\n"
                                          "f 1/1 2/2 3/3\n", mtl))
    assert scene.n_textures == 0 and list(scene.material_texture) == [-1, -1]


# ------------------------------------------------------------------- fuzzing
_WORDS = ["texture", "usetexture", "tp", "tpp", "none", "procedural", "t", "s", "p", "f", "c", "board.png",
          "0", "1", "2", "-1", "0.5", "3", "1e3", "x", "#", "\n"]


@settings(max_examples=200, deadline=2000)
@given(st.lists(st.sampled_from(_WORDS), max_size=40))
def test_fuzzed_extension_text_gives_a_scene_or_an_nff_error_and_scenes_round_trip(words):
    import tempfile
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        try:
            scene = parse_nff(VIEW + " ".join(words), folder=DATA)
        except NFFError:
            return
        assert scene.n_elements >= 1
        with tempfile.TemporaryDirectory() as folder:
            again = read_nff(write_nff(scene, Path(folder) / "fuzz.nff"))
    assert scenes_equal(scene, again)


def test_the_documented_nff_example_reads_as_it_says(tmp_path):
    import re

    readme = (Path(__file__).resolve().parent.parent / "docs" / "scene_files.md").read_text(encoding="utf-8")
    (example,) = re.findall(r"```text\n(.*?)```", readme, re.S)
    write_png(procedural_texture(16, 8, seed=0), tmp_path / "wood.png")
    scene = parse_nff(VIEW + example, folder=tmp_path)
    np.testing.assert_array_equal(scene.texture_size, [[16, 8], [256, 256]])
    assert list(scene.element_kind) == [ElementKind.POLYGON, ElementKind.SPHERE]
    assert list(scene.material_texture) == [0] and list(scene.material_uv_scale) == [4.0]
    np.testing.assert_array_equal(scene.polygon_uv, [[0, 0], [1, 0], [1, 1], [0, 1]])
