"""Wavefront OBJ triangle meshes, with MTL colours and textures, as scenes.

A small reader of our own (images through Pillow, :mod:`tracer.scenes.images`).
It takes these lines and ignores every other one (groups, smoothing, lines);
a UTF-8 byte-order mark at the start of a file is skipped:

* ``v x y z``: a vertex;
* ``vt u [v [w]]``: texture coordinates (``v`` defaults to 0; ``w`` is
  ignored); ``u`` runs right and ``v`` up, so ``v = 1`` is an image's top row;
* ``f``: a face of vertex references ``i``, ``i/t``, ``i//n`` or ``i/t/n``
  (negative indices count back from the last one read), fan-triangulated;
  either every vertex names texture coordinates or none does;
* ``vn x y z``: a vertex normal, counted only, so that a face's normal
  indices can be checked (shading uses the face's own normal);
* ``mtllib FILE...``: material libraries, relative to the OBJ file;
* ``usemtl NAME``: the material of the faces that follow.

An MTL file gives, per ``newmtl NAME``, the diffuse colour ``Kd r [g b]``
and a texture ``map_Kd FILE`` (PNG or JPEG, relative to the MTL file; map
options such as ``-s`` are not supported). Everything else in it is ignored.

Materials: colour ``Kd`` (default 0.8 grey), Kd 0.8, Ks 0.1, shine 30, no
transmission; a ``map_Kd`` image multiplies the colour on faces that have
texture coordinates. A face without them gets NaN (u, v) and its material's
colour untextured. Without a ``usemtl`` faces get the 0.8 grey material; so
do they after a ``usemtl`` that comes before any ``mtllib`` (it has nothing
to name), with one warning per file. Texture coordinate indices in a file
that has read no ``vt`` line yet are ignored (they must still be integers),
with one warning per file. Every index is checked against the lines read
before it.

OBJ carries no view or light, so the scene gets a default camera and one
white light that frame the mesh (see :func:`frame_mesh`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracer.scenes.model import Camera, Material, Scene, SceneBuilder, unread_texture
from rtcommon.validate import InputError

__all__ = ["OBJError", "read_obj", "read_mtl", "frame_mesh"]


class OBJError(InputError):
    """A malformed OBJ file; the message says file, line and what was expected."""

    def __init__(self, file: str, line: int, expected: str, found: str):
        self.file, self.line, self.expected, self.found = file, line, expected, found
        super().__init__(f"{file}:{line}: expected {expected}, found {found!r}")


def frame_mesh(lo, hi, angle: float = 40.0) -> tuple[Camera, tuple[float, float, float]]:
    """A camera and a light position that frame the box ``lo``..``hi``.

    The camera looks at the box centre from the (+x, +y, +z) side with +y up
    (the usual OBJ convention), far enough that the bounding sphere fits in
    the field of view; the light sits above and behind the camera.

    Parameters
    ----------
    lo, hi : array_like, shape (3,)
        Corners of the mesh's bounding box.
    angle : float
        Field of view in degrees.

    Returns
    -------
    camera : Camera
    light : tuple of 3 float
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    direction = np.array([0.45, 0.35, 1.0])
    direction /= np.linalg.norm(direction)
    distance = 1.1 * radius / math.sin(math.radians(angle) / 2)
    eye = center + distance * direction
    light = center + 2.0 * distance * np.array([0.3, 0.8, 0.6])
    camera = Camera(tuple(eye), tuple(center), (0.0, 1.0, 0.0), angle,
                    max(1e-4 * distance, 1e-6), (512, 512))
    return camera, tuple(float(v) for v in light)


#: the material of faces without ``usemtl`` (and the look of every other one but its colour)
DEFAULT_MATERIAL = Material((0.8, 0.8, 0.8), 0.8, 0.1, 30.0, 0.0, 1.0)


@dataclass
class _MtlMaterial:
    """One ``newmtl`` of an MTL file: its colour, and its ``map_Kd`` image path and where it was given."""

    color: tuple = DEFAULT_MATERIAL.color
    image: Path | None = None
    image_at: tuple = ("", 0, "")  # MTL file, line, the file name as written


def _numbers(fields, count_range, source, number, expected, line):
    try:
        values = tuple(float(v) for v in fields)
    except ValueError:
        raise OBJError(source, number, expected, line.strip()) from None
    if not count_range[0] <= len(values) <= count_range[1] or not all(math.isfinite(v) for v in values):
        raise OBJError(source, number, expected, line.strip())
    return values


def read_mtl(path, materials: dict | None = None) -> dict:
    """The materials of an MTL file.

    Parameters
    ----------
    path : str or os.PathLike
    materials : dict, optional
        Add to these (a later definition of a name replaces an earlier one).

    Returns
    -------
    dict of str to _MtlMaterial
        By ``newmtl`` name: the ``Kd`` colour and the ``map_Kd`` image path
        (resolved against the MTL file's folder; the image is read when a
        face first uses it).

    Raises
    ------
    FileNotFoundError
        No such file.
    OBJError
        A malformed ``newmtl``, ``Kd`` or ``map_Kd`` line (file, line and
        what was expected).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such MTL file: {str(path)!r}")
    source = str(path)
    materials = {} if materials is None else materials
    current = None
    with path.open(encoding="utf-8-sig", errors="replace") as stream:
        for number, line in enumerate(stream, start=1):
            fields = line.split("#", 1)[0].split()
            if not fields or fields[0] not in ("newmtl", "Kd", "map_Kd"):
                continue
            if fields[0] == "newmtl":
                if len(fields) < 2:
                    raise OBJError(source, number, "a material name after 'newmtl'", line.strip())
                current = materials[" ".join(fields[1:])] = _MtlMaterial()
                continue
            if current is None:
                raise OBJError(source, number, f"'newmtl' before {fields[0]!r}", line.strip())
            if fields[0] == "Kd":
                values = _numbers(fields[1:], (1, 3), source, number, "one or three finite numbers after 'Kd' "
                                  "(r [g b]; 'spectral' and 'xyz' are not supported)", line)
                if len(values) == 2:
                    raise OBJError(source, number, "one or three finite numbers after 'Kd'", line.strip())
                if min(values) < 0.0:
                    raise OBJError(source, number, "a colour of numbers >= 0 after 'Kd'", line.strip())
                current.color = values * 3 if len(values) == 1 else values
            else:
                if len(fields) < 2:
                    raise OBJError(source, number, "an image file after 'map_Kd'", line.strip())
                if any(field.startswith("-") for field in fields[1:]):
                    raise OBJError(source, number, "an image file after 'map_Kd' (map options such as -s are "
                                   "not supported)", line.strip())
                name = line.split("#", 1)[0].strip()[len("map_Kd"):].strip()
                current.image, current.image_at = path.parent / name, (source, number, name)
    return materials


def read_obj(path, *, max_depth: int = 5, texels: bool = True) -> Scene:
    """Read the triangles of an OBJ file, with its MTL colours and textures.

    Parameters
    ----------
    path : str or os.PathLike
    max_depth : int
        Recursion depth of the scene.
    texels : bool
        False: ``map_Kd`` images keep their sizes only (headers are read;
        see :func:`tracer.scenes.nff.parse_nff`).

    Returns
    -------
    Scene
        One TRIANGLE element per triangle, in file order (a face with n
        vertices gives n - 2 fan triangles in a row; triangles of zero area
        are dropped), with ``triangle_uv`` (T, 3, 2) from ``vt`` (NaN for
        faces without); materials and textures numbered in order of first
        use (see the module docstring); one white light and a camera from
        :func:`frame_mesh`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    OBJError
        On a malformed ``v``, ``vt``, ``f``, ``mtllib`` or ``usemtl`` line, an
        index out of range, a missing MTL file, a malformed MTL line, a
        missing or unreadable ``map_Kd`` image (named with its MTL file and
        line), or a file without faces.

    Warns
    -----
    UserWarning
        Once per file, naming the first line: faces that name texture
        coordinates before any ``vt`` line (those indices are ignored); a
        ``usemtl`` before any ``mtllib`` (its faces get the default material).
    """
    from tracer.scenes.images import image_size, read_image

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such OBJ file: {str(path)!r}")
    source = str(path)
    vertices: list[tuple[float, float, float]] = []
    uvs: list[tuple[float, float]] = []
    triangles: list[tuple[int, int, int]] = []
    triangle_uv: list = []  # per triangle: three uv indices, or None
    triangle_material: list = []  # per triangle: the _MtlMaterial in use, or None
    libraries: dict | None = None  # materials of the mtllib files; None before any mtllib
    material = None
    normals = 0  # 'vn' lines read so far: normals are not used, but their indices must exist
    ignored_uv_line = None
    unnamed_material = None  # (line, name) of the first 'usemtl' without an mtllib to name it
    with path.open(encoding="utf-8-sig", errors="replace") as stream:
        for number, line in enumerate(stream, start=1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            if fields[0] == "v":
                try:
                    xyz = tuple(float(v) for v in fields[1:4])
                except ValueError:
                    raise OBJError(source, number, "three numbers after 'v'", line.strip()) \
                        from None
                if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
                    raise OBJError(source, number, "three finite numbers after 'v'",
                                   line.strip())
                vertices.append(xyz)
            elif fields[0] == "vn":
                normals += 1
            elif fields[0] == "vt":
                values = _numbers(fields[1:], (1, 3), source, number,
                                  "one to three finite numbers after 'vt' (u [v [w]])", line)
                uvs.append((values[0], values[1] if len(values) > 1 else 0.0))
            elif fields[0] == "f":
                corners, corner_uv = [], []
                for item in fields[1:]:
                    parts = item.split("/")
                    if len(parts) > 3:
                        raise OBJError(source, number, "a vertex reference v, v/vt, v/vt/vn or v//vn", item)
                    corners.append(_index(parts[0], len(vertices), source, number, "a vertex index", item))
                    if len(parts) > 1 and parts[1]:
                        if not uvs:
                            _index(parts[1], None, source, number, "a texture coordinate index", item)
                            ignored_uv_line = ignored_uv_line or number
                        else:
                            corner_uv.append(_index(parts[1], len(uvs), source, number,
                                                    "a texture coordinate index", item))
                    if len(parts) > 2 and parts[2]:
                        _index(parts[2], normals, source, number, "a normal index", item)
                if len(corners) < 3:
                    raise OBJError(source, number, "at least three vertices after 'f'",
                                   line.strip())
                if corner_uv and len(corner_uv) != len(corners):
                    raise OBJError(source, number, "texture coordinates at every vertex of the face or at none",
                                   line.strip())
                for k in range(1, len(corners) - 1):
                    triangles.append((corners[0], corners[k], corners[k + 1]))
                    triangle_uv.append((corner_uv[0], corner_uv[k], corner_uv[k + 1]) if corner_uv else None)
                    triangle_material.append(material)
            elif fields[0] == "mtllib":
                if len(fields) < 2:
                    raise OBJError(source, number, "an MTL file after 'mtllib'", line.strip())
                libraries = {} if libraries is None else libraries
                for name in fields[1:]:
                    try:
                        read_mtl(path.parent / name, libraries)
                    except FileNotFoundError:
                        raise OBJError(source, number, f"an MTL file (no such file: "
                                       f"{str(path.parent / name)!r})", name) from None
            elif fields[0] == "usemtl":
                if len(fields) < 2:
                    raise OBJError(source, number, "a material name after 'usemtl'", line.strip())
                if libraries is None:
                    unnamed_material = unnamed_material or (number, " ".join(fields[1:]))
                else:
                    name = " ".join(fields[1:])
                    if name not in libraries:
                        defined = ", ".join(repr(n) for n in libraries) or "none"
                        raise OBJError(source, number, f"a material defined by 'newmtl' in the mtllib files "
                                       f"(defined: {defined})", name)
                    material = libraries[name]
    if not triangles:
        raise OBJError(source, 0, "at least one face ('f' line)", "none")
    if unnamed_material is not None:
        warnings.warn(f"{source}:{unnamed_material[0]}: 'usemtl {unnamed_material[1]}' names a material, but no "
                      "'mtllib' line came before it; faces get the default grey material until an 'mtllib' "
                      "defines the materials", stacklevel=2)
    if ignored_uv_line is not None:
        warnings.warn(f"{source}:{ignored_uv_line}: a face names texture coordinates, but no 'vt' line came "
                      "before it; texture coordinate indices before the first 'vt' are ignored", stacklevel=2)
    points = np.array(vertices, dtype=np.float64)
    tri = points[np.array(triangles)]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    extent = float(np.ptp(tri.reshape(-1, 3), axis=0).max()) or 1.0
    kept = np.flatnonzero(area2 > 1e-14 * extent * extent)
    if not len(kept):
        raise OBJError(source, 0, "a face of non-zero area", "only degenerate faces")
    tri = tri[kept]
    table = np.array(uvs, dtype=np.float64).reshape(-1, 2)

    builder = SceneBuilder(path.stem)
    builder.max_depth = int(max_depth)
    builder.background = (0.1, 0.1, 0.12)
    builder.camera, light = frame_mesh(tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0))
    builder.light(light)
    textures: dict = {}  # image path -> texture number, in order of first use
    looks: dict = {}  # (id of the _MtlMaterial, texture) -> Material
    for triangle, k in zip(tri, kept):
        uv = None if triangle_uv[k] is None else table[list(triangle_uv[k])]
        mtl = triangle_material[k]
        texture = -1
        if mtl is not None and mtl.image is not None and uv is not None:
            key = mtl.image.resolve()
            if key not in textures:
                try:
                    textures[key] = builder.texture(read_image(mtl.image) if texels
                                                    else unread_texture(*image_size(mtl.image)))
                except (OSError, ValueError) as error:
                    raise OBJError(mtl.image_at[0], mtl.image_at[1],
                                   f"a readable PNG or JPEG image after 'map_Kd' ({error})", mtl.image_at[2]) \
                        from None
            texture = textures[key]
        key = (id(mtl), texture)
        if key not in looks:
            color = DEFAULT_MATERIAL.color if mtl is None else mtl.color
            looks[key] = Material(color, 0.8, 0.1, 30.0, 0.0, 1.0, texture=texture)
        builder.material(looks[key])
        builder.triangle(triangle, uv)
    return builder.build()


def _index(text: str, count: int | None, source: str, number: int, what: str, item: str) -> int:
    """The 0-based index of a 1-based or negative (relative) OBJ index ``text`` among ``count`` items.

    With ``count`` None only the syntax is checked (an integer other than 0)."""
    try:
        index = int(text)
    except ValueError:
        raise OBJError(source, number, what, item) from None
    if count is None:
        if index == 0:
            raise OBJError(source, number, f"{what} other than 0", item)
        return index
    resolved = index - 1 if index > 0 else count + index
    if index == 0 or not 0 <= resolved < count:
        where = f"in 1..{count} or negative" if count else "(none is defined before this line)"
        raise OBJError(source, number, f"{what} {where}", item)
    return resolved
