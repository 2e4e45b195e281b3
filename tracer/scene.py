"""The scene model: flat numpy arrays with explicit dtypes.

Every NFF primitive is one *element*. Elements are numbered in file order
(``element id``); that id is stable and names the element in access traces, so
it is never renumbered. Each element also has a *kind* and an index into the
arrays of that kind, so kernels can work on one homogeneous array per kind.

Kinds (``ElementKind``):

========  ==========================================================
SPHERE    ``sphere_center`` (S, 3), ``sphere_radius`` (S,)
TRIANGLE  ``triangle_vertices`` (T, 3, 3): NFF ``p 3``
POLYGON   convex planar polygon with n >= 4 vertices, CSR:
          ``polygon_offsets`` (P + 1,), ``polygon_vertices`` (V, 3)
PATCH     polygon with vertex normals (NFF ``pp n``), CSR:
          ``patch_offsets`` (Q + 1,), ``patch_vertices`` (W, 3),
          ``patch_normals`` (W, 3)
CONE      cone or cylinder without caps: ``cone_base`` (C, 3),
          ``cone_base_radius`` (C,), ``cone_apex`` (C, 3),
          ``cone_apex_radius`` (C,); negative radii mean the inside is
          visible (NFF convention)
========  ==========================================================

All float arrays are float64, index arrays int64, kinds uint8.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


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
                raise ValueError(f"Camera.{name} must be 3 finite numbers, got {value!r}")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        if not 0.0 < self.angle < 180.0:
            raise ValueError(f"Camera.angle must be in (0, 180) degrees, got {self.angle}")
        if not self.hither >= 0.0:
            raise ValueError(f"Camera.hither must be >= 0, got {self.hither}")
        if len(self.resolution) != 2 or min(self.resolution) < 1:
            raise ValueError(f"Camera.resolution must be two positive ints, got {self.resolution!r}")
        object.__setattr__(self, "resolution", (int(self.resolution[0]), int(self.resolution[1])))
        if np.allclose(self.eye, self.look_at):
            raise ValueError("Camera.eye and Camera.look_at must differ")


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

    @property
    def n_elements(self) -> int:
        """Number of elements (primitives) in the scene."""
        return int(self.element_kind.shape[0])

    @property
    def n_lights(self) -> int:
        """Number of point lights."""
        return int(self.light_position.shape[0])
