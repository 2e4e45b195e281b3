"""The fast half of the NFF reader: whitespace split, numbers in slices, geometry checked with numpy.

:func:`parse_fast` reads a well-formed file without tracking where tokens
are; anything unusual (a bad token, a degenerate polygon, a missing view)
raises :class:`Fallback`, and :mod:`tracer.scenes.nff`'s positional reader reads
the file again to say where the fault is. Both readers fill the same
:class:`SceneParts`, and :func:`assemble` turns them into a
:class:`~tracer.scenes.model.Scene`, so a file reads the same either way (the tests
compare the two on fuzzed input).

The texture extension (``texture``, ``usetexture``, ``tp``, ``tpp``; see
:mod:`tracer.scenes.nff`) is read by the positional reader only: its keywords are
unknown here and raise :class:`Fallback`, so plain NFF keeps this fast path
unchanged.
"""
from __future__ import annotations

import re

import numpy as np

from tracer.scenes.model import Camera, ElementKind, Material, Scene, is_unread, texture_arrays, untextured
from rtcommon.validate import InputError

TOKEN = re.compile(r"\S+")
DEPTH_PRAGMA = re.compile(r"^[ \t]*#[ \t]*max_depth[ \t]+([0-9]+)[ \t]*$", re.MULTILINE)
LINE_BREAKS = re.compile(r"\r\n|[\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")
COMMENT = re.compile(r"#[^\n]*")
C_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
C_INTEGER = re.compile(r"[+-]?[0-9]+")
VIEW_KEYWORDS = ("from", "at", "up", "angle", "hither", "resolution")
#: the numbers of ``f``; all but ``shine`` must be >= 0
MATERIAL_FIELDS = ("r", "g", "b", "Kd", "Ks", "shine", "T", "ior")
#: the extension's keywords (textures, polygons and patches with (u, v)), read by the positional reader only
TEXTURE_KEYWORDS = ("texture", "usetexture", "tp", "tpp")
OBJECT_KEYWORDS = ("c", "s", "p", "pp", "tp", "tpp")
KEYWORDS = ("v", *VIEW_KEYWORDS, "b", "l", "f", *OBJECT_KEYWORDS, "texture", "usetexture")
CAMERA_FIELDS = {"from": "eye", "at": "look_at", "up": "up", "angle": "angle", "hither": "hither",
                  "resolution": "resolution"}
DEFAULT_MATERIAL = Material().as_tuple()
# element kinds as plain ints, for speed in the loops
SPHERE, TRIANGLE, POLYGON, PATCH, CONE = (int(kind) for kind in (ElementKind.SPHERE, ElementKind.TRIANGLE,
                                                                   ElementKind.POLYGON, ElementKind.PATCH,
                                                                   ElementKind.CONE))
#: A polygon whose area is below this share of its extent squared is degenerate.
DEGENERATE_AREA = 1e-12
#: A polygon with a vertex further than this share of its extent from its plane is not planar.
PLANARITY_TOLERANCE = 1e-4


# --------------------------------------------------------------- geometry checks
def polygon_measures(vertices: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per polygon: whether it is degenerate, and how far (share of its extent) it is from planar.

    Each polygon is moved to its first vertex and scaled by its extent before
    the Newell normal is summed, so coordinates near 1e300 neither overflow
    nor lose the test.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
    offsets : ndarray of int64, shape (N + 1,)
        Polygon ``i`` is ``vertices[offsets[i]:offsets[i + 1]]`` (>= 3 each).

    Returns
    -------
    degenerate : ndarray of bool, shape (N,)
        Zero extent, non-finite extent, or Newell area <= DEGENERATE_AREA.
    deviation : ndarray of float64, shape (N,)
        Largest distance of a vertex from the plane through the centroid
        along the Newell normal, over the extent (0 for degenerate ones).
    """
    starts = offsets[:-1]
    counts = np.diff(offsets)
    if starts.size == 0:
        return np.zeros(0, dtype=bool), np.zeros(0)
    owner = np.repeat(np.arange(starts.size), counts)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        low = np.minimum.reduceat(vertices, starts, axis=0)
        high = np.maximum.reduceat(vertices, starts, axis=0)
        extent = np.max(high - low, axis=1)
        usable = np.isfinite(extent) & (extent > 0)
        scale = np.where(usable, extent, 1.0)
        local = (vertices - vertices[starts][owner]) / scale[owner, None]
        following = np.arange(vertices.shape[0]) + 1
        following[offsets[1:] - 1] = starts
        here, there = local, local[following]
        terms = np.column_stack([(here[:, 1] - there[:, 1]) * (here[:, 2] + there[:, 2]),
                                 (here[:, 2] - there[:, 2]) * (here[:, 0] + there[:, 0]),
                                 (here[:, 0] - there[:, 0]) * (here[:, 1] + there[:, 1])])
        normal = np.add.reduceat(terms, starts, axis=0)
        length = np.linalg.norm(normal, axis=1)
        degenerate = ~usable | ~(length > DEGENERATE_AREA)
        unit = normal / np.where(degenerate, 1.0, length)[:, None]
        centroid = np.add.reduceat(local, starts, axis=0) / counts[:, None]
        distance = np.abs(np.einsum("ij,ij->i", local - centroid[owner], unit[owner]))
        deviation = np.maximum.reduceat(distance, starts)
    return degenerate, np.where(degenerate, 0.0, deviation)


def view_direction_problem(view: dict) -> bool:
    """Whether ``up`` is zero or parallel to the direction from ``from`` to ``at``."""
    direction = np.subtract(view["look_at"], view["eye"])
    up = np.asarray(view["up"], dtype=np.float64)
    scale = np.linalg.norm(direction) * np.linalg.norm(up)
    with np.errstate(over="ignore", invalid="ignore"):
        cross = np.linalg.norm(np.cross(direction / max(np.linalg.norm(direction), 1e-300),
                                        up / max(np.linalg.norm(up), 1e-300)))
    return not (scale > 0 and np.isfinite(scale) and cross > 1e-9)


# ---------------------------------------------------------------------- the fast reader
class Fallback(Exception):
    """The fast reader met something it does not explain: the positional reader will."""


class SceneParts:
    """A scene's contents as flat Python lists, in element order.

    A material row's key is the ``f`` line's 8 numbers, followed by the
    texture's number and uv scale while a texture is in use
    (``material + texture_use``). Texture images and (u, v) lists are filled
    by the positional reader only; the fast reader leaves them empty.
    """

    def __init__(self):
        self.background = (0.0, 0.0, 0.0)
        self.camera = None
        self.lights: list = []
        self.material = DEFAULT_MATERIAL
        self.texture_use: tuple = ()  # () or (texture number, uv scale)
        self.material_rows: dict = {}
        self.textures: list = []  # images, (height, width, 4) uint8
        self.triangle_uv: list = []  # 6 per triangle, NaN without (u, v)
        self.polygon_uv: list = []  # 2 per polygon vertex
        self.patch_uv: list = []  # 2 per patch vertex
        self.kinds: list[int] = []
        self.index: list[int] = []
        self.element_material: list[int] = []
        self.tokens: list[int] = []
        self.spheres: list = []
        self.triangles: list = []
        self.polygons: list = []
        self.polygon_counts: list[int] = []
        self.patches: list = []
        self.patch_counts: list[int] = []
        self.cones: list = []
        self.cone_tokens: list[int] = []

    def _element(self, kind: int, index: int, token: int) -> None:
        material = self.material + self.texture_use
        row = self.material_rows.get(material)
        if row is None:
            row = self.material_rows[material] = len(self.material_rows)
        self.kinds.append(kind)
        self.index.append(index)
        self.element_material.append(row)
        self.tokens.append(token)

    def add_sphere(self, values, token: int) -> None:
        self._element(SPHERE, len(self.spheres) // 4, token)
        self.spheres.extend(values)

    def add_cone(self, values, token: int) -> None:
        self._element(CONE, len(self.cones) // 8, token)
        self.cones.extend(values)
        self.cone_tokens.append(token)

    def add_polygon(self, keyword: str, count: int, values, token: int, uv=None) -> None:
        """Add a ``p`` or ``pp`` element (``values``: ``count`` rows of x y z, or
        x y z nx ny nz), with ``uv`` (2 per vertex) or NaN (u, v)."""
        uv = [float("nan")] * (2 * count) if uv is None else list(uv)
        if keyword == "pp":
            self._element(PATCH, len(self.patch_counts), token)
            self.patch_counts.append(count)
            self.patches.extend(values)
            self.patch_uv.extend(uv)
        elif count == 3:
            self._element(TRIANGLE, len(self.triangles) // 9, token)
            self.triangles.extend(values)
            self.triangle_uv.extend(uv)
        else:
            self._element(POLYGON, len(self.polygon_counts), token)
            self.polygon_counts.append(count)
            self.polygons.extend(values)
            self.polygon_uv.extend(uv)

    def add_texture(self, image) -> int:
        """Add a texture image (height, width, 4) uint8, or an unread stand-in; returns its number."""
        self.textures.append(image if is_unread(image) else np.ascontiguousarray(image, dtype=np.uint8))
        return len(self.textures) - 1


def parse_fast(text: str) -> SceneParts:
    """The scene's parts from a whitespace split, or :class:`Fallback` at anything unusual.

    The loop is written for speed (local names, element bookkeeping inline);
    :meth:`SceneParts.add_sphere` and its siblings say the same more slowly.
    """
    body = COMMENT.sub("", text) if "#" in text else text
    if not body.isascii() or "_" in body:
        raise Fallback
    tokens = body.split()
    parts = SceneParts()
    kinds, index, materials, element_tokens = parts.kinds, parts.index, parts.element_material, parts.tokens
    spheres, triangles, polygons, patches, cones = parts.spheres, parts.triangles, parts.polygons, parts.patches, \
        parts.cones
    rows = parts.material_rows
    row = None  # the current material's row, given at its first use
    view: dict | None = None
    seen_object = False
    position, end = 0, len(tokens)
    keywords = frozenset(KEYWORDS)
    try:
        while position < end:
            keyword = tokens[position]
            start = position
            position += 1
            if keyword == "s":
                x, y, z, radius = map(float, tokens[position:position + 4])
                if not radius > 0.0:
                    raise Fallback
                position += 4
                kinds.append(SPHERE)
                index.append(len(spheres) >> 2)
                spheres += (x, y, z, radius)
            elif keyword == "p" or keyword == "pp":
                count = int(tokens[position])
                width = 3 if keyword == "p" else 6
                values = list(map(float, tokens[position + 1:position + 1 + width * count]))
                if count < 3 or len(values) != width * count:
                    raise Fallback
                position += 1 + width * count
                if keyword == "pp":
                    kinds.append(PATCH)
                    index.append(len(parts.patch_counts))
                    parts.patch_counts.append(count)
                    patches += values
                elif count == 3:
                    kinds.append(TRIANGLE)
                    index.append(len(triangles) // 9)
                    triangles += values
                else:
                    kinds.append(POLYGON)
                    index.append(len(parts.polygon_counts))
                    parts.polygon_counts.append(count)
                    polygons += values
            elif keyword == "f":
                material = tuple(map(float, tokens[position:position + 8]))
                if len(material) != 8 or min(material[:5]) < 0.0 or min(material[6:]) < 0.0:
                    raise Fallback  # the positional reader names a negative value
                parts.material, row = material, None
                position += 8
                continue
            elif keyword == "c":
                values = list(map(float, tokens[position:position + 8]))
                if len(values) != 8 or values[:3] == values[4:7]:
                    raise Fallback
                position += 8
                kinds.append(CONE)
                index.append(len(cones) >> 3)
                cones += values
                parts.cone_tokens.append(start)
            elif keyword == "l":
                values = list(map(float, tokens[position:position + 3]))
                position += 3
                if position < end and tokens[position] not in keywords:
                    values += map(float, tokens[position:position + 3])
                    position += 3
                else:
                    values += (1.0, 1.0, 1.0)
                if len(values) != 6:
                    raise Fallback
                parts.lights.append(tuple(values))
                continue
            elif keyword == "b":
                background = tuple(map(float, tokens[position:position + 3]))
                if len(background) != 3:
                    raise Fallback
                parts.background = background
                position += 3
                continue
            elif keyword == "v":
                if seen_object:
                    raise Fallback
                view = {}
                continue
            elif keyword in CAMERA_FIELDS:
                if seen_object or view is None:
                    raise Fallback
                if keyword == "resolution":
                    view["resolution"] = (int(tokens[position]), int(tokens[position + 1]))
                    position += 2
                elif keyword == "angle" or keyword == "hither":
                    view[CAMERA_FIELDS[keyword]] = float(tokens[position])
                    position += 1
                else:
                    point = tuple(map(float, tokens[position:position + 3]))
                    if len(point) != 3:
                        raise Fallback
                    view[CAMERA_FIELDS[keyword]] = point
                    position += 3
                continue
            else:  # an unknown keyword, or the texture extension's: the positional reader reads both
                raise Fallback
            # an element was added: its material row and where it stands
            seen_object = True
            if row is None:
                row = rows.get(parts.material)
                if row is None:
                    row = rows[parts.material] = len(rows)
            materials.append(row)
            element_tokens.append(start)
    except (ValueError, IndexError):
        raise Fallback from None
    if view is None or len(view) != len(CAMERA_FIELDS) or not parts.kinds:
        raise Fallback
    if not (0.0 < view["angle"] < 180.0 and view["hither"] >= 0.0 and min(view["resolution"]) >= 1):
        raise Fallback
    if view_direction_problem(view):
        raise Fallback
    try:
        parts.camera = Camera(**view)
    except ValueError:
        raise Fallback from None
    return parts


def assemble(parts: SceneParts, name: str, max_depth: int) -> Scene:
    """The :class:`Scene` of a file's parts, or :class:`Fallback` if a number or polygon is bad."""
    def table(values, width):
        return np.array(values, dtype=np.float64).reshape(-1, width)

    def csr(counts):
        offsets = np.zeros(len(counts) + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        return offsets

    spheres, cones, lights = table(parts.spheres, 4), table(parts.cones, 8), table(parts.lights, 6)
    triangles = table(parts.triangles, 9).reshape(-1, 3, 3)
    polygons, patches = table(parts.polygons, 3), table(parts.patches, 6)
    keys = list(parts.material_rows)
    materials = np.array([key[:8] for key in keys], dtype=np.float64).reshape(-1, 8)
    numbers = (spheres, cones, lights, triangles, polygons, patches, materials,
               np.asarray(parts.background, dtype=np.float64))
    if not all(np.isfinite(array).all() for array in numbers):
        raise Fallback
    polygon_offsets, patch_offsets = csr(parts.polygon_counts), csr(parts.patch_counts)
    for vertices, offsets in ((triangles.reshape(-1, 3), np.arange(0, 3 * len(triangles) + 1, 3)),
                              (polygons, polygon_offsets), (patches[:, :3], patch_offsets)):
        if polygon_measures(vertices, offsets)[0].any():
            raise Fallback
    if len(patches) and not np.any(patches[:, 3:] != 0.0, axis=1).all():
        raise Fallback
    return Scene(
        name=name, camera=parts.camera, background=np.array(parts.background, dtype=np.float64),
        max_depth=int(max_depth),
        element_kind=np.array(parts.kinds, dtype=np.uint8),
        element_index=np.array(parts.index, dtype=np.int64),
        element_material=np.array(parts.element_material, dtype=np.int64),
        sphere_center=np.ascontiguousarray(spheres[:, :3]), sphere_radius=np.ascontiguousarray(spheres[:, 3]),
        triangle_vertices=np.ascontiguousarray(triangles),
        polygon_offsets=polygon_offsets, polygon_vertices=np.ascontiguousarray(polygons),
        patch_offsets=patch_offsets, patch_vertices=np.ascontiguousarray(patches[:, :3]),
        patch_normals=np.ascontiguousarray(patches[:, 3:]),
        cone_base=np.ascontiguousarray(cones[:, :3]), cone_base_radius=np.ascontiguousarray(cones[:, 3]),
        cone_apex=np.ascontiguousarray(cones[:, 4:7]), cone_apex_radius=np.ascontiguousarray(cones[:, 7]),
        material_color=np.ascontiguousarray(materials[:, :3]), material_kd=np.ascontiguousarray(materials[:, 3]),
        material_ks=np.ascontiguousarray(materials[:, 4]), material_shine=np.ascontiguousarray(materials[:, 5]),
        material_t=np.ascontiguousarray(materials[:, 6]), material_ior=np.ascontiguousarray(materials[:, 7]),
        light_position=np.ascontiguousarray(lights[:, :3]), light_color=np.ascontiguousarray(lights[:, 3:]),
        **_texture_fields(parts, keys, len(triangles), len(polygons), len(patches)),
    )


def _texture_fields(parts: SceneParts, keys: list, n_triangles: int, n_polygon_vertices: int,
                    n_patch_vertices: int) -> dict:
    """The :class:`Scene` texture fields of a file's parts (as :func:`untextured` without any)."""
    fields = untextured(len(keys), n_triangles, n_polygon_vertices, n_patch_vertices)
    for row, key in enumerate(keys):
        if len(key) > 8:
            fields["material_texture"][row], fields["material_uv_scale"][row] = key[8], key[9]
    for name, values, count in (("triangle_uv", parts.triangle_uv, 6 * n_triangles),
                                ("polygon_uv", parts.polygon_uv, 2 * n_polygon_vertices),
                                ("patch_uv", parts.patch_uv, 2 * n_patch_vertices)):
        if values:  # the positional reader's; the fast reader gives no (u, v)
            if len(values) != count:
                raise InputError(f"{name}: {len(values)} values for {count} coordinates")
            fields[name] = np.array(values, dtype=np.float64).reshape(fields[name].shape)
    fields.update(texture_arrays(parts.textures))
    return fields


