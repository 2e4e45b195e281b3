"""Writing scenes as NFF (the reader, and the format with our texture extension, are in :mod:`tracer.scenes.nff`).

:func:`format_nff` gives the text, :func:`write_nff` writes it and a
textured scene's images beside it, as one unit. Numbers are written in the
shortest form that reads back as the same float64, so a read of a written
scene gives the same arrays (:func:`tracer.scenes.model.scenes_equal`).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from rtcommon.files import write_files_atomic
from tracer.scenes.nff_fast import KEYWORDS, TOKEN
from tracer.scenes.model import ElementKind, Scene, vertices_and_uv
from rtcommon.validate import InputError

__all__ = ["format_nff", "write_nff"]


def _fmt(value) -> str:
    """Shortest text that reads back as the same float64."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _join(values) -> str:
    return " ".join(_fmt(v) for v in values)


def _element_uv(scene: Scene, kind: int, index: int) -> np.ndarray | None:
    """(n, 2) texture coordinates of a planar element, or None without them (NaN or no uv arrays)."""
    uv = vertices_and_uv(scene, ElementKind(kind), index)[1]
    if np.isnan(uv).all():
        return None
    if not np.isfinite(uv).all():
        raise InputError(f"format_nff: a {ElementKind(kind).name.lower()} (row {index}) has (u, v) at some "
                         "vertices and not at others; NFF gives all or none")
    return uv


def _texture_file_name(name) -> str:
    text = str(name)
    if not text or TOKEN.fullmatch(text) is None or "#" in text or text in KEYWORDS or text == "procedural":
        raise InputError(f"format_nff: texture file name {text!r} must be one token (no whitespace, no '#') "
                         "and not a keyword")
    return text


def format_nff(scene: Scene, texture_files=None) -> str:
    """The NFF text of ``scene`` (see :func:`write_nff`).

    Parameters
    ----------
    scene : Scene
    texture_files : sequence of str, optional
        The file name of each texture, as its ``texture`` line gives it
        (relative to the NFF file); required when the scene has textures.

    Raises
    ------
    ValueError
        An element NFF cannot express: a cone with a textured material, a
        textured polygon or patch without (u, v), (u, v) at only some of an
        element's vertices; a textured scene without ``texture_files``.
    """
    cam = scene.camera
    out = [
        f"# {scene.name}: {scene.n_elements} elements, written by raytrace-coherence",
        f"# max_depth {int(scene.max_depth)}",
        "b " + _join(scene.background),
        "v",
        "from " + _join(cam.eye),
        "at " + _join(cam.look_at),
        "up " + _join(cam.up),
        "angle " + _fmt(cam.angle),
        "hither " + _fmt(cam.hither),
        f"resolution {cam.resolution[0]} {cam.resolution[1]}",
    ]
    for position, color in zip(scene.light_position, scene.light_color):
        if np.all(color == 1.0):
            out.append("l " + _join(position))
        else:
            out.append("l " + _join(position) + " " + _join(color))
    if scene.n_textures:
        if texture_files is None or len(texture_files) != scene.n_textures:
            raise InputError(f"format_nff: the scene has {scene.n_textures} textures; texture_files must name "
                             "a file for each (write_nff writes them)")
        out.extend(f"texture t{k} {_texture_file_name(name)}" for k, name in enumerate(texture_files))
    materials = np.column_stack([scene.material_color, scene.material_kd, scene.material_ks,
                                 scene.material_shine, scene.material_t, scene.material_ior])
    n_materials = len(materials)
    material_texture = scene.material_texture if len(scene.material_texture) == n_materials \
        else np.full(n_materials, -1, dtype=np.int64)
    uv_scale = scene.material_uv_scale if len(scene.material_uv_scale) == n_materials else np.ones(n_materials)
    current = -1
    for element, (kind, index, material) in enumerate(zip(scene.element_kind, scene.element_index,
                                                          scene.element_material)):
        textured = material_texture[material] >= 0
        if material != current:
            out.append("f " + _join(materials[material]))
            if textured:
                scale = "" if uv_scale[material] == 1.0 else " " + _fmt(uv_scale[material])
                out.append(f"usetexture t{int(material_texture[material])}{scale}")
            current = material
        if kind == ElementKind.SPHERE:
            out.append("s " + _join(scene.sphere_center[index]) + " "
                       + _fmt(scene.sphere_radius[index]))
        elif kind in (ElementKind.TRIANGLE, ElementKind.POLYGON, ElementKind.PATCH):
            uv = _element_uv(scene, kind, index)
            if textured and uv is None:
                raise InputError(f"format_nff: element {element} is textured but has no (u, v); "
                                 "NFF cannot say so")
            if kind == ElementKind.TRIANGLE:
                vertices = scene.triangle_vertices[index]
            elif kind == ElementKind.POLYGON:
                vertices = scene.polygon_vertices[scene.polygon_offsets[index]:scene.polygon_offsets[index + 1]]
            else:
                lo, hi = scene.patch_offsets[index], scene.patch_offsets[index + 1]
                vertices = np.column_stack([scene.patch_vertices[lo:hi], scene.patch_normals[lo:hi]])
            keyword = "pp" if kind == ElementKind.PATCH else "p"
            if uv is None:
                out.append(f"{keyword} {len(vertices)}")
                out.extend(_join(v) for v in vertices)
            else:
                out.append(f"t{keyword} {len(vertices)}")
                out.extend(_join(v) + " " + _join(t) for v, t in zip(vertices, uv))
        elif kind == ElementKind.CONE:
            if textured:
                raise InputError(f"format_nff: element {element} is a cone with a textured material; "
                                 "NFF cones have no (u, v)")
            out.append("c " + _join(scene.cone_base[index]) + " "
                       + _fmt(scene.cone_base_radius[index]))
            out.append("  " + _join(scene.cone_apex[index]) + " "
                       + _fmt(scene.cone_apex_radius[index]))
        else:
            raise InputError(f"element kind {kind} has no NFF form")
    out.append("")
    return "\n".join(out)


def write_nff(scene: Scene, path) -> Path:
    """Write ``scene`` as NFF, atomically (temporary files, then rename).

    Every number is printed with the shortest text that reads back to the
    same float64, so :func:`read_nff` gives back identical arrays; the depth
    goes into a ``# max_depth N`` comment. A textured scene's images go
    beside the NFF file as lossless PNG files ``<stem>.t<k>.png`` (texture
    ``k``; whitespace and ``#`` in the stem become ``_``), named by its
    ``texture`` lines; the NFF file and its images are written as one unit.

    Parameters
    ----------
    scene : Scene
    path : str or os.PathLike
        Destination; its folder must exist.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    FileNotFoundError
        The destination's folder does not exist.
    ValueError
        The scene has an element NFF cannot express (see :func:`format_nff`),
        or was read without its texels.
    """
    from tracer.scenes.images import png_bytes

    if not scene.texels_read:
        raise InputError(f"write_nff: scene {scene.name!r} was read without its texels (texels=False); "
                         "read it again with texels to write it")
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
    stem = re.sub(r"[\s#]", "_", path.stem) or "scene"
    names = [f"{stem}.t{k}.png" for k in range(scene.n_textures)]
    files = {path: format_nff(scene, names if names else None)}
    for k, name in enumerate(names):
        files[folder / name] = png_bytes(scene.texture(k))
    write_files_atomic(files)
    return path
