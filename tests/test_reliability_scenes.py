"""Reliability of scene files: malformed NFF and OBJ input and textures are refused where they stand."""
from __future__ import annotations

import json
import tracemalloc

import pytest

from reliability_files import png_header


# ------------------------------------------------------------- scene files
SCENE_VIEW = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\n"
QUAD_OBJ = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"


def test_a_byte_order_mark_is_skipped(tmp_path):
    """An OBJ, MTL or NFF file that starts with a UTF-8 BOM reads as it does without one. Fails if the
    readers decode with plain "utf-8" (the OBJ then loses its first vertex, the others fail)."""
    from tracer.scenes.nff import read_nff
    from tracer.scenes.obj import read_obj
    from tracer.scenes.model import scenes_equal

    material = "newmtl red\nKd 1 0 0\n"
    obj = "mtllib m.mtl\nusemtl red\n" + QUAD_OBJ
    nff = SCENE_VIEW + "f 1 0 0 1 0 0 0 1\ns 0 0 0 1\n"
    scenes = {}
    for folder, mark in (("plain", b""), ("marked", b"\xef\xbb\xbf")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "m.mtl").write_bytes(mark + material.encode())
        (tmp_path / folder / "q.obj").write_bytes(mark + obj.encode())
        (tmp_path / folder / "s.nff").write_bytes(mark + nff.encode())
        scenes[folder] = read_obj(tmp_path / folder / "q.obj"), read_nff(tmp_path / folder / "s.nff")
    for plain, marked in zip(scenes["plain"], scenes["marked"]):
        assert scenes_equal(plain, marked)
    assert scenes["marked"][0].material_color.tolist() == [[1.0, 0.0, 0.0]]


@pytest.mark.parametrize("field", ["r", "g", "b", "Kd", "Ks", "T", "ior"])
def test_a_negative_nff_material_value_is_refused_where_it_stands(field):
    """Fails if either NFF reader lets a negative colour, Kd, Ks, T or ior through (drop the check in
    the positional reader: the fast reader falls back to it and the file reads)."""
    from tracer.scenes.nff import NFFError, parse_nff
    from tracer.scenes.nff_fast import MATERIAL_FIELDS

    at = MATERIAL_FIELDS.index(field)
    values = ["0.5", "0.5", "0.5", "0.8", "0.1", "30", "0", "1"]
    values[at] = "-0.25"
    text = SCENE_VIEW + "f " + " ".join(values) + "\ns 0 0 0 1\n"
    column = len("f ") + sum(len(v) + 1 for v in values[:at]) + 1
    with pytest.raises(NFFError, match=rf"scene.nff:8:{column}: expected {field} >= 0 .*found '-0.25'"):
        parse_nff(text, "scene.nff")
    values[at], values[5] = "0", "-3"  # a negative Phong exponent is allowed
    assert parse_nff(SCENE_VIEW + "f " + " ".join(values) + "\ns 0 0 0 1\n").material_shine.tolist() == [-3.0]


@pytest.mark.parametrize("field", ["color", "kd", "ks", "t", "ior"])
def test_a_negative_material_is_refused_by_its_config(field):
    """Fails if Material accepts a negative colour, kd, ks, t or ior (drop its check)."""
    from tracer.scenes.model import Material

    value = (0.5, -0.1, 0.5) if field == "color" else -0.1
    with pytest.raises(ValueError, match=f"Material.{field} must be >= 0"):
        Material(**{field: value})


def test_a_max_depth_line_outside_1_to_64_is_refused_naming_file_and_line():
    """Fails if the reader takes '# max_depth 0' (render then refused it without naming the file)."""
    from tracer.scenes.nff import NFFError, parse_nff
    from tracer.scenes.catalog import load

    text = SCENE_VIEW + "s 0 0 0 1\n# max_depth 0\n"
    with pytest.raises(NFFError, match=r"deep.nff:9:13: expected a max_depth in 1\.\.64, found '0'"):
        parse_nff(text, "deep.nff")
    assert parse_nff(text, "deep.nff", max_depth=3).max_depth == 3  # an explicit depth replaces the line
    with pytest.raises(ValueError, match=r"max_depth must be in \[1, 64\], got 0"):
        load("tetra", max_depth=0)


@pytest.mark.parametrize("before, face, expected", [
    ("", "f 1/a 2 3", "q.obj:5: expected a texture coordinate index, found '1/a'"),
    ("vn 0 0 1\n", "f 1//2 2//1 3//1", r"q.obj:5: expected a normal index in 1\.\.1 or negative, found '1//2'"),
    ("vn 0 0 1\n", "f 1/1/1 2/1/1 3/1/9", r"q.obj:5: expected a normal index in 1\.\.1 or negative, found '3/1/9'"),
    ("vt 0 0\n", "f 1//1 2 3", r"q.obj:5: expected a normal index \(none is defined before this line\), found '1//1'"),
])
def test_obj_face_indices_are_checked_even_where_unused(tmp_path, before, face, expected):
    """Fails if a face's normal index is not checked against the 'vn' lines before it, or a texture
    index is only checked once a 'vt' exists ('1/a' was reported as a missing 'vt')."""
    from tracer.scenes.obj import OBJError, read_obj

    (tmp_path / "q.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + (before or "g mesh\n") + face + "\n")
    with pytest.raises(OBJError, match=expected):
        read_obj(tmp_path / "q.obj")


def test_obj_usemtl_without_mtllib_warns_once(tmp_path):
    """Fails if a 'usemtl' that names nothing (no 'mtllib' before it) passes in silence."""
    from tracer.scenes.obj import read_obj

    (tmp_path / "q.obj").write_text("usemtl red\n" + QUAD_OBJ + "usemtl blue\n")
    with pytest.warns(UserWarning, match=r"q.obj:1: 'usemtl red' names a material, but no 'mtllib'") as seen:
        scene = read_obj(tmp_path / "q.obj")
    assert len(seen) == 1 and scene.material_color.tolist() == [[0.8, 0.8, 0.8]]


def test_a_huge_texture_is_refused_from_its_header(tmp_path):
    """A 16384 x 16384 PNG gives one ValueError naming the file, its size and the limit, from its header.
    Fails if read_image lets Pillow judge the size (its DecompressionBombError escapes)."""
    from tracer.scenes.images import MAX_IMAGE_TEXELS, image_size, read_image

    (tmp_path / "huge.png").write_bytes(png_header(16384, 16384))
    (tmp_path / "big.png").write_bytes(png_header(12000, 12000))  # under Pillow's refusal, over ours
    (tmp_path / "fits.png").write_bytes(png_header(4000, 3000))
    for name, side in (("huge.png", 16384), ("big.png", 12000)):
        for reader in (read_image, image_size):
            with pytest.raises(ValueError, match=rf"{name}' is {side} x {side} \({side * side:,} texels\); "
                                                 rf"a texture may hold at most {MAX_IMAGE_TEXELS:,} texels"):
                reader(tmp_path / name)
    assert image_size(tmp_path / "fits.png") == (4000, 3000)


def _textured_nff(folder, textures):
    lines = [f"texture t{k} {spec}" for k, spec in enumerate(textures)]
    uses = "".join(f"usetexture t{k}\ns {3 * k} 0 0 1\n" for k in range(len(textures)))
    (folder / "textured.nff").write_text(SCENE_VIEW + "\n".join(lines) + "\nf 1 1 1 1 0 0 0 1\n" + uses)
    return folder / "textured.nff"


def test_a_scene_summary_does_not_make_its_textures(tmp_path, capsys):
    """'coherence scene' on a file with two 1024^2 procedural textures allocates under 1 MB of texels,
    and prints their sizes; fails if the command loads the scene with its texels (25 MB and more)."""
    from analyses.cli import main
    from tracer.scenes.catalog import load

    path = _textured_nff(tmp_path, ["procedural 1024 1024 1", "procedural 1024 512 2"])
    full = load(path).summary()
    assert main(["scene", str(path), "--json"]) == 0  # the command's imports, outside the measurement
    capsys.readouterr()
    tracemalloc.start()
    try:
        assert main(["scene", str(path), "--json"]) == 0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert json.loads(capsys.readouterr().out) == full and full["textures"] == [[1024, 1024], [1024, 512]]
    assert peak < 1 << 20, peak


def test_a_scene_read_without_texels_is_not_rendered_or_written(tmp_path):
    """Fails if a summary-only scene (texels=False) renders or writes its stand-in texels as black."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load
    from tracer.scenes.nff import write_nff

    (tmp_path / "fits.png").write_bytes(png_header(64, 32))
    scene = load(_textured_nff(tmp_path, ["fits.png", "procedural 16 16 3"]), texels=False)
    assert not scene.texels_read and scene.summary()["textures"] == [[64, 32], [16, 16]]
    with pytest.raises(ValueError, match="read without its texels"):
        render(scene, options=RenderOptions(size=4))
    with pytest.raises(ValueError, match="read without its texels"):
        write_nff(scene, tmp_path / "out.nff")
    assert not (tmp_path / "out.nff").exists()
