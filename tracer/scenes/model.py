"""The scene model: flat numpy arrays with explicit dtypes.

Every NFF primitive is one *element*. Elements are numbered in file order
(``element id``); that id is stable and names the element in access traces, so
it is never renumbered. Each element also has a *kind* and an index into the
arrays of that kind, so kernels can work on one homogeneous array per kind.

Kinds (``ElementKind``):

========  ==========================================================
SPHERE    ``sphere_center`` (S, 3), ``sphere_radius`` (S,)
TRIANGLE  ``triangle_vertices`` (T, 3, 3): NFF ``p 3``
POLYGON   planar polygon with n >= 4 vertices, convex or not, CSR:
          ``polygon_offsets`` (P + 1,), ``polygon_vertices`` (V, 3)
PATCH     polygon with vertex normals (NFF ``pp n``), CSR:
          ``patch_offsets`` (Q + 1,), ``patch_vertices`` (W, 3),
          ``patch_normals`` (W, 3)
CONE      cone or cylinder without caps: ``cone_base`` (C, 3),
          ``cone_base_radius`` (C,), ``cone_apex`` (C, 3),
          ``cone_apex_radius`` (C,); negative radii mean the inside is
          visible (NFF convention)
========  ==========================================================

Textures (optional; see :mod:`tracer.rendering.texture`): ``texture_size`` (X, 2)
width and height of each image, ``texture_offsets`` (X + 1,) and
``texture_texels`` (N, 4) uint8 RGBA, the images one after another, each
row-major from its top row. ``material_texture`` (M,) names the texture that
multiplies a material's colour (-1: none) and ``material_uv_scale`` (M,) how
many times it repeats across the surface's (u, v) range. Surfaces get (u, v)
from ``triangle_uv`` (T, 3, 2), ``polygon_uv`` (V, 2) and ``patch_uv`` (W, 2)
(NaN where a file gave none); spheres are mapped by latitude and longitude.
Empty texture and uv arrays mean a scene without them.

All float arrays are float64, index arrays int64, kinds uint8.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
from rtcommon.validate import InputError, require_int

#: The deepest ray tree the renderer takes (``Scene.max_depth``, primary rays = 1): a scene file, a
#: scene or a render option asking for more, or for less than 1, is refused.
MAX_DEPTH = 64


class ElementKind(enum.IntEnum):
    """Primitive kinds; the integer value is stored in ``Scene.element_kind``."""

    SPHERE = 0
    TRIANGLE = 1
    POLYGON = 2
    PATCH = 3
    CONE = 4


@dataclass(frozen=True)
class Camera:
    """SPD/NFF view.

    Parameters
    ----------
    eye, look_at, up : tuple of 3 float
        ``from``, ``at`` and ``up`` of the NFF view; ``up`` need not be
        perpendicular to the viewing direction.
    angle : float
        Full field of view in degrees between the centres of the outermost
        pixel rows/columns (aspect ratio 1).
    hither : float
        Near clipping distance.
    resolution : tuple of 2 int
        Image width and height in pixels.
    """

    eye: tuple[float, float, float] = (0.0, 0.0, 1.0)
    look_at: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    angle: float = 45.0
    hither: float = 1e-3
    resolution: tuple[int, int] = (512, 512)

    def __post_init__(self):
        for name in ("eye", "look_at", "up"):
            value = getattr(self, name)
            if len(value) != 3 or not all(np.isfinite(v) for v in value):
                raise InputError(f"Camera.{name} must be 3 finite numbers, got {value!r}")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        if not 0.0 < self.angle < 180.0:
            raise InputError(f"Camera.angle must be in (0, 180) degrees, got {self.angle}")
        if not self.hither >= 0.0:
            raise InputError(f"Camera.hither must be >= 0, got {self.hither}")
        if len(self.resolution) != 2 or min(self.resolution) < 1:
            raise InputError(f"Camera.resolution must be two positive ints, got {self.resolution!r}")
        object.__setattr__(self, "resolution", (int(self.resolution[0]), int(self.resolution[1])))
        if np.allclose(self.eye, self.look_at):
            raise InputError("Camera.eye and Camera.look_at must differ")


def _f64(shape_tail):
    return field(default_factory=lambda: np.zeros((0, *shape_tail), dtype=np.float64))


def _i64_offsets():
    return field(default_factory=lambda: np.zeros(1, dtype=np.int64))


@dataclass(eq=False)
class Scene:
    """A renderable scene as flat arrays (see module docstring for shapes).

    ``element_kind[e]``, ``element_index[e]`` and ``element_material[e]`` give,
    for element id ``e``, its kind, its row in that kind's arrays and its
    material row. Materials are rows of the ``material_*`` arrays (M,).
    Lights are point lights: ``light_position`` (L, 3), ``light_color`` (L, 3).
    """

    name: str = "scene"
    camera: Camera = field(default_factory=Camera)
    background: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.float64))
    max_depth: int = 5

    element_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.uint8))
    element_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    element_material: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    sphere_center: np.ndarray = _f64((3,))
    sphere_radius: np.ndarray = _f64(())
    triangle_vertices: np.ndarray = _f64((3, 3))
    polygon_offsets: np.ndarray = _i64_offsets()
    polygon_vertices: np.ndarray = _f64((3,))
    patch_offsets: np.ndarray = _i64_offsets()
    patch_vertices: np.ndarray = _f64((3,))
    patch_normals: np.ndarray = _f64((3,))
    cone_base: np.ndarray = _f64((3,))
    cone_base_radius: np.ndarray = _f64(())
    cone_apex: np.ndarray = _f64((3,))
    cone_apex_radius: np.ndarray = _f64(())

    material_color: np.ndarray = _f64((3,))
    material_kd: np.ndarray = _f64(())
    material_ks: np.ndarray = _f64(())
    material_shine: np.ndarray = _f64(())
    material_t: np.ndarray = _f64(())
    material_ior: np.ndarray = _f64(())

    light_position: np.ndarray = _f64((3,))
    light_color: np.ndarray = _f64((3,))

    texture_size: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    texture_offsets: np.ndarray = _i64_offsets()
    texture_texels: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.uint8))
    material_texture: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    material_uv_scale: np.ndarray = _f64(())
    triangle_uv: np.ndarray = _f64((3, 2))
    polygon_uv: np.ndarray = _f64((2,))
    patch_uv: np.ndarray = _f64((2,))

    @property
    def n_textures(self) -> int:
        """Number of texture images."""
        return int(self.texture_size.shape[0])

    @property
    def texels_read(self) -> bool:
        """False for a scene read without its texels (``texels=False``: sizes only, for a summary)."""
        return not is_unread(self.texture_texels)

    def texture(self, index: int) -> np.ndarray:
        """Texture ``index`` as an image, shape (height, width, 4) uint8 RGBA."""
        width, height = (int(v) for v in self.texture_size[index])
        first = int(self.texture_offsets[index])
        return self.texture_texels[first:first + width * height].reshape(height, width, 4)

    @property
    def n_elements(self) -> int:
        """Number of elements (primitives) in the scene."""
        return int(self.element_kind.shape[0])

    @property
    def n_lights(self) -> int:
        """Number of point lights."""
        return int(self.light_position.shape[0])

    def counts(self) -> dict[str, int]:
        """Number of elements per primitive kind.

        Returns
        -------
        dict of str to int
            Keys are the lower-case ``ElementKind`` names in kind order
            (``sphere``, ``triangle``, ``polygon``, ``patch``, ``cone``).
        """
        per_kind = np.bincount(self.element_kind.astype(np.int64), minlength=len(ElementKind))
        return {kind.name.lower(): int(per_kind[kind]) for kind in ElementKind}

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Axis-aligned box around all geometry, or ``None`` without elements.

        Spheres count with ``|radius|``; a cone counts as the boxes of its two
        end discs grown by ``|radius|`` in every axis (conservative).

        Returns
        -------
        (lo, hi) : tuple of ndarray, shape (3,) each, or None
        """
        points = []
        if len(self.sphere_radius):
            r = np.abs(self.sphere_radius)[:, None]
            points += [self.sphere_center - r, self.sphere_center + r]
        if len(self.triangle_vertices):
            points.append(self.triangle_vertices.reshape(-1, 3))
        for vertices in (self.polygon_vertices, self.patch_vertices):
            if len(vertices):
                points.append(vertices)
        if len(self.cone_base_radius):
            for centre, radius in ((self.cone_base, self.cone_base_radius),
                                   (self.cone_apex, self.cone_apex_radius)):
                r = np.abs(radius)[:, None]
                points += [centre - r, centre + r]
        if not points:
            return None
        stacked = np.concatenate(points)
        return stacked.min(axis=0), stacked.max(axis=0)

    def summary(self) -> dict:
        """What the scene holds, as plain Python types (JSON-serialisable).

        Returns
        -------
        dict
            ``name``; ``elements`` (total); ``counts`` (per kind, see
            :meth:`counts`); ``polygon_vertices`` and ``patch_vertices``
            (CSR vertex totals); ``materials``; ``lights``;
            ``bounding_box`` (``{"min": [x, y, z], "max": [x, y, z]}`` or
            ``None``); ``max_depth``; ``camera`` (eye, look_at, up, angle,
            hither, resolution as lists/floats/ints); ``background``; with
            textures, ``textures`` (``[width, height]`` of each).
        """
        box = self.bounding_box()
        cam = self.camera
        summary = {
            "name": str(self.name),
            "elements": self.n_elements,
            "counts": self.counts(),
            "polygon_vertices": int(self.polygon_vertices.shape[0]),
            "patch_vertices": int(self.patch_vertices.shape[0]),
            "materials": int(self.material_kd.shape[0]),
            "lights": self.n_lights,
            "bounding_box": None if box is None else {
                "min": [float(v) for v in box[0]], "max": [float(v) for v in box[1]]},
            "max_depth": int(self.max_depth),
            "camera": {
                "eye": list(cam.eye), "look_at": list(cam.look_at), "up": list(cam.up),
                "angle": float(cam.angle), "hither": float(cam.hither),
                "resolution": list(cam.resolution),
            },
            "background": [float(v) for v in self.background],
        }
        if self.n_textures:
            summary["textures"] = [[int(w), int(h)] for w, h in self.texture_size]
        return summary


# Fields of ``Scene`` that hold arrays, in declaration order.
ARRAY_FIELDS = tuple(
    name for name in Scene.__dataclass_fields__
    if name not in ("name", "camera", "max_depth")
)


def scenes_equal(a: Scene, b: Scene, *, rtol: float = 0.0, atol: float = 0.0) -> bool:
    """Whether two scenes have the same camera, depth and arrays.

    Arrays must agree in dtype and shape; values within ``rtol``/``atol``
    (exactly, by default). The name is not compared.
    """
    if a.camera != b.camera or a.max_depth != b.max_depth:
        return False
    for name in ARRAY_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if x.dtype != y.dtype or x.shape != y.shape:
            return False
        if not np.allclose(x, y, rtol=rtol, atol=atol, equal_nan=True):  # NaN: no (u, v) given
            return False
    return True


@dataclass(frozen=True)
class Material:
    """Surface description of NFF ``f``: ``colour Kd Ks shine T ior``.

    Parameters
    ----------
    color : tuple of 3 float
        Surface colour (r, g, b), each >= 0.
    kd, ks : float
        Diffuse and specular (reflection) coefficients, >= 0; ``ks > 0``
        spawns a reflection ray.
    shine : float
        Phong exponent of the highlight.
    t : float
        Transmittance, >= 0; ``t > 0`` spawns a refraction ray.
    ior : float
        Index of refraction, >= 0 (SPD files give 0 for opaque surfaces).
    texture : int
        Texture (of :meth:`SceneBuilder.texture`) whose texels multiply
        ``color``; -1 for none.
    uv_scale : float
        Times the texture repeats across the surface's (u, v) range (> 0).
    """

    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    kd: float = 1.0
    ks: float = 0.0
    shine: float = 0.0
    t: float = 0.0
    ior: float = 1.0
    texture: int = -1
    uv_scale: float = 1.0

    def __post_init__(self):
        if len(self.color) != 3:
            raise InputError(f"Material.color must be 3 numbers, got {self.color!r}")
        object.__setattr__(self, "color", tuple(float(c) for c in self.color))
        for name in ("kd", "ks", "shine", "t", "ior"):
            object.__setattr__(self, name, float(getattr(self, name)))
        values = (*self.color, self.kd, self.ks, self.shine, self.t, self.ior)
        if not all(np.isfinite(v) for v in values):
            raise InputError(f"Material values must be finite, got {values!r}")
        if min(self.color) < 0.0:
            raise InputError(f"Material.color must be >= 0 in each channel, got {self.color!r}")
        for name in ("kd", "ks", "t", "ior"):  # not shine: any Phong exponent is a highlight
            if getattr(self, name) < 0.0:
                raise InputError(f"Material.{name} must be >= 0, got {getattr(self, name)!r}")
        texture = require_int("Material.texture", self.texture)
        if texture < -1:
            raise InputError(f"Material.texture must be a texture number or -1, got {texture}")
        object.__setattr__(self, "texture", texture)
        object.__setattr__(self, "uv_scale", float(self.uv_scale))
        if not (np.isfinite(self.uv_scale) and self.uv_scale > 0):
            raise InputError(f"Material.uv_scale must be a positive finite number, got {self.uv_scale!r}")

    def as_tuple(self) -> tuple[float, ...]:
        """``(r, g, b, kd, ks, shine, t, ior)`` as in NFF ``f``."""
        return (*self.color, self.kd, self.ks, self.shine, self.t, self.ior)

    def key(self) -> tuple:
        """Everything that makes two materials the same row: :meth:`as_tuple`, texture, uv_scale."""
        return (*self.as_tuple(), self.texture, self.uv_scale)


class SceneBuilder:
    """Collects primitives in element order and builds a :class:`Scene`.

    Materials are deduplicated: identical :class:`Material` values share one
    row, rows are numbered in order of first use by an element, and a
    material never used by an element gets no row. NFF reading and all
    generators go through this class, so their scenes share that canonical
    material order (what makes NFF round trips exact).

    Examples
    --------
    >>> b = SceneBuilder("demo")
    >>> b.material(Material((1, 0, 0), 0.8, 0.2, 20.0))
    >>> b.sphere((0, 0, 0), 1.0)
    0
    >>> b.build().n_elements
    1
    """

    def __init__(self, name: str = "scene"):
        self.name = name
        self.camera = Camera()
        self.background = (0.0, 0.0, 0.0)
        self.max_depth = 5
        self._material = Material()
        self._material_rows: dict[tuple, int] = {}
        self._kind: list[int] = []
        self._index: list[int] = []
        self._element_material: list[int] = []
        self._spheres: list[tuple] = []
        self._triangles: list = []
        self._polygons: list = []
        self._patches: list = []
        self._patch_normals: list = []
        self._cones: list[tuple] = []
        self._lights: list[tuple] = []
        self._textures: list[np.ndarray] = []
        self._triangle_uv: list = []
        self._polygon_uv: list = []
        self._patch_uv: list = []

    @property
    def n_elements(self) -> int:
        """Elements added so far."""
        return len(self._kind)

    def material(self, material: Material) -> None:
        """Use ``material`` for the elements added from now on."""
        self._material = material

    def light(self, position, color=(1.0, 1.0, 1.0)) -> None:
        """Add a point light at ``position`` (3,) with ``color`` (3,)."""
        self._lights.append((tuple(map(float, position)), tuple(map(float, color))))

    def texture(self, image) -> int:
        """Add a texture image, shape (height, width, 4) RGBA or (height, width, 3)
        RGB, uint8 (row 0 at the top); returns its number for :class:`Material`."""
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4) or min(image.shape[:2]) < 1:
            raise InputError(f"a texture must be a uint8 image of shape (height, width, 3 or 4), "
                             f"got {image.dtype} {image.shape}")
        if image.shape[2] == 3:
            image = np.concatenate([image, np.full(image.shape[:2] + (1,), 255, np.uint8)], axis=2)
        self._textures.append(image if is_unread(image) else np.ascontiguousarray(image))
        return len(self._textures) - 1

    def _add(self, kind: ElementKind, index: int) -> int:
        if self._material.texture >= len(self._textures):
            raise InputError(f"material uses texture {self._material.texture}, but only "
                             f"{len(self._textures)} textures were added")
        key = self._material.key()
        row = self._material_rows.setdefault(key, len(self._material_rows))
        self._kind.append(int(kind))
        self._index.append(index)
        self._element_material.append(row)
        return len(self._kind) - 1

    def sphere(self, center, radius: float) -> int:
        """Add a sphere; returns its element id."""
        self._spheres.append((*map(float, center), float(radius)))
        return self._add(ElementKind.SPHERE, len(self._spheres) - 1)

    def triangle(self, vertices, uv=None) -> int:
        """Add a triangle from ``vertices`` (3, 3) and optional texture
        coordinates ``uv`` (3, 2); returns its element id."""
        self._triangles.append(np.asarray(vertices, dtype=np.float64).reshape(3, 3))
        self._triangle_uv.append(_uv(uv, 3))
        return self._add(ElementKind.TRIANGLE, len(self._triangles) - 1)

    def polygon(self, vertices, uv=None) -> int:
        """Add a polygon from ``vertices`` (n, 3), optionally with ``uv`` (n, 2).

        Three vertices make a TRIANGLE element, more a POLYGON element
        (NFF ``p n``); returns the element id.
        """
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        if len(v) < 3:
            raise InputError(f"a polygon needs at least 3 vertices, got {len(v)}")
        if len(v) == 3:
            return self.triangle(v, uv)
        self._polygons.append(v)
        self._polygon_uv.append(_uv(uv, len(v)))
        return self._add(ElementKind.POLYGON, len(self._polygons) - 1)

    def patch(self, vertices, normals, uv=None) -> int:
        """Add a polygon patch with per-vertex normals, both (n, 3), n >= 3,
        and optional ``uv`` (n, 2)."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        if len(v) < 3 or len(v) != len(n):
            raise InputError("a patch needs n >= 3 vertices and as many normals")
        self._patches.append(v)
        self._patch_normals.append(n)
        self._patch_uv.append(_uv(uv, len(v)))
        return self._add(ElementKind.PATCH, len(self._patches) - 1)

    def cone(self, base, base_radius: float, apex, apex_radius: float) -> int:
        """Add a cone or cylinder without caps; returns its element id."""
        self._cones.append((tuple(map(float, base)), float(base_radius),
                            tuple(map(float, apex)), float(apex_radius)))
        return self._add(ElementKind.CONE, len(self._cones) - 1)

    def build(self) -> Scene:
        """The scene with everything added so far (the builder stays usable)."""
        def csr(parts):
            offsets = np.zeros(len(parts) + 1, dtype=np.int64)
            offsets[1:] = np.cumsum([len(p) for p in parts], dtype=np.int64)
            flat = np.concatenate(parts) if parts else np.zeros((0, 3))
            return offsets, np.ascontiguousarray(flat, dtype=np.float64)

        materials = np.array(list(self._material_rows), dtype=np.float64).reshape(-1, 10)
        spheres = np.array(self._spheres, dtype=np.float64).reshape(-1, 4)
        polygon_offsets, polygon_vertices = csr(self._polygons)
        patch_offsets, patch_vertices = csr(self._patches)
        _, patch_normals = csr(self._patch_normals)
        cones = self._cones
        lights = self._lights
        return Scene(
            name=self.name,
            camera=self.camera,
            background=np.array(self.background, dtype=np.float64),
            max_depth=int(self.max_depth),
            element_kind=np.array(self._kind, dtype=np.uint8),
            element_index=np.array(self._index, dtype=np.int64),
            element_material=np.array(self._element_material, dtype=np.int64),
            sphere_center=np.ascontiguousarray(spheres[:, :3]),
            sphere_radius=np.ascontiguousarray(spheres[:, 3]),
            triangle_vertices=np.array(self._triangles, dtype=np.float64).reshape(-1, 3, 3),
            polygon_offsets=polygon_offsets,
            polygon_vertices=polygon_vertices,
            patch_offsets=patch_offsets,
            patch_vertices=patch_vertices,
            patch_normals=patch_normals,
            cone_base=np.array([c[0] for c in cones], dtype=np.float64).reshape(-1, 3),
            cone_base_radius=np.array([c[1] for c in cones], dtype=np.float64),
            cone_apex=np.array([c[2] for c in cones], dtype=np.float64).reshape(-1, 3),
            cone_apex_radius=np.array([c[3] for c in cones], dtype=np.float64),
            material_color=np.ascontiguousarray(materials[:, :3]),
            material_kd=np.ascontiguousarray(materials[:, 3]),
            material_ks=np.ascontiguousarray(materials[:, 4]),
            material_shine=np.ascontiguousarray(materials[:, 5]),
            material_t=np.ascontiguousarray(materials[:, 6]),
            material_ior=np.ascontiguousarray(materials[:, 7]),
            light_position=np.array([p for p, _ in lights], dtype=np.float64).reshape(-1, 3),
            light_color=np.array([c for _, c in lights], dtype=np.float64).reshape(-1, 3),
            **texture_arrays(self._textures),
            material_texture=materials[:, 8].astype(np.int64),
            material_uv_scale=np.ascontiguousarray(materials[:, 9]),
            triangle_uv=np.array(self._triangle_uv, dtype=np.float64).reshape(-1, 3, 2),
            polygon_uv=_stacked_uv(self._polygon_uv),
            patch_uv=_stacked_uv(self._patch_uv),
        )


def vertices_and_uv(scene: Scene, kind: ElementKind, index: int):
    """Vertices (n, 3) and (u, v) (n, 2; NaN where the scene has none) of a triangle, polygon or patch."""
    if kind == ElementKind.TRIANGLE:
        uv = scene.triangle_uv[index] if scene.triangle_uv.size else np.full((3, 2), np.nan)
        return scene.triangle_vertices[index], uv
    offsets, vertices, uv = ((scene.polygon_offsets, scene.polygon_vertices, scene.polygon_uv)
                             if kind == ElementKind.POLYGON else
                             (scene.patch_offsets, scene.patch_vertices, scene.patch_uv))
    first, stop = int(offsets[index]), int(offsets[index + 1])
    return vertices[first:stop], uv[first:stop] if uv.size else np.full((stop - first, 2), np.nan)


#: The one texel every unread texture shows (views of it are the stand-ins; no other array shares it).
_UNREAD_TEXEL = np.zeros(4, dtype=np.uint8)
_UNREAD_TEXEL.flags.writeable = False


def unread_texture(width: int, height: int) -> np.ndarray:
    """A stand-in for a ``width x height`` texture whose texels were not read: shape (height, width, 4)
    uint8, every texel 0, read-only, taking no memory (a summary needs only the size)."""
    return np.broadcast_to(_UNREAD_TEXEL, (int(height), int(width), 4))


def is_unread(texels: np.ndarray) -> bool:
    """Whether ``texels`` (an image (H, W, 4) or the scene's (N, 4)) is a stand-in of :func:`unread_texture`."""
    return texels.size > 0 and np.may_share_memory(texels, _UNREAD_TEXEL)


def texture_arrays(images) -> dict:
    """The :class:`Scene` fields ``texture_size``, ``texture_offsets`` and ``texture_texels`` of ``images``.

    Parameters
    ----------
    images : sequence of ndarray, shape (H, W, 4) uint8
        In texture order. If any is an :func:`unread_texture` stand-in,
        every texel is (the scene keeps its sizes only).
    """
    size = np.array([(image.shape[1], image.shape[0]) for image in images], dtype=np.int64).reshape(-1, 2)
    offsets = np.zeros(len(images) + 1, dtype=np.int64)
    np.cumsum(size[:, 0] * size[:, 1], out=offsets[1:])
    if any(is_unread(image) for image in images):
        texels = np.broadcast_to(_UNREAD_TEXEL, (int(offsets[-1]), 4))
    elif images:
        texels = np.concatenate([image.reshape(-1, 4) for image in images])
    else:
        texels = np.zeros((0, 4), dtype=np.uint8)
    return {"texture_size": size, "texture_offsets": offsets, "texture_texels": texels}


def untextured(n_materials: int, n_triangles: int, n_polygon_vertices: int, n_patch_vertices: int) -> dict:
    """The texture fields of a :class:`Scene` without textures or (u, v), as
    :class:`SceneBuilder` makes them (materials untextured, uv NaN)."""
    return {"material_texture": np.full(n_materials, -1, dtype=np.int64),
            "material_uv_scale": np.ones(n_materials),
            "triangle_uv": np.full((n_triangles, 3, 2), np.nan),
            "polygon_uv": np.full((n_polygon_vertices, 2), np.nan),
            "patch_uv": np.full((n_patch_vertices, 2), np.nan)}


def _uv(uv, n: int) -> np.ndarray:
    """Texture coordinates of ``n`` vertices as (n, 2) float64; NaN when not given."""
    if uv is None:
        return np.full((n, 2), np.nan)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape != (n, 2) or not np.isfinite(uv).all():
        raise InputError(f"uv must be {n} finite (u, v) pairs, shape ({n}, 2), got shape {uv.shape}")
    return uv


def _stacked_uv(parts) -> np.ndarray:
    return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros((0, 2)), dtype=np.float64)
