"""Wavefront OBJ triangle meshes as scenes.

A small reader of our own (no dependency): it takes ``v`` and ``f`` lines,
accepts the ``i``, ``i/t``, ``i//n`` and ``i/t/n`` index forms and negative
(relative) indices, fan-triangulates faces with more than three vertices, and
ignores everything else (normals, texture coordinates, groups, materials,
lines). OBJ carries no view or light, so the scene gets a default camera and
one white light that frame the mesh (see :func:`frame_mesh`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tracer.scene import Camera, Material, Scene, SceneBuilder

__all__ = ["OBJError", "read_obj", "frame_mesh"]


class OBJError(ValueError):
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


def read_obj(path, *, max_depth: int = 5) -> Scene:
    """Read the triangles of an OBJ file.

    Parameters
    ----------
    path : str or os.PathLike
    max_depth : int
        Recursion depth of the scene.

    Returns
    -------
    Scene
        One TRIANGLE element per triangle, in file order (a face with n
        vertices gives n - 2 fan triangles in a row; triangles of zero area
        are dropped), one grey diffuse material, one white light, a camera
        from :func:`frame_mesh`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    OBJError
        On a malformed ``v`` or ``f`` line, an index out of range, or a file
        without faces.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such OBJ file: {str(path)!r}")
    source = str(path)
    vertices: list[tuple[float, float, float]] = []
    triangles: list[tuple[int, int, int]] = []
    with path.open(encoding="utf-8", errors="replace") as stream:
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
            elif fields[0] == "f":
                corners = []
                for item in fields[1:]:
                    head = item.split("/", 1)[0]
                    try:
                        index = int(head)
                    except ValueError:
                        raise OBJError(source, number, "a vertex index", item) from None
                    resolved = index - 1 if index > 0 else len(vertices) + index
                    if index == 0 or not 0 <= resolved < len(vertices):
                        raise OBJError(source, number,
                                       f"a vertex index in 1..{len(vertices)} or negative",
                                       item)
                    corners.append(resolved)
                if len(corners) < 3:
                    raise OBJError(source, number, "at least three vertices after 'f'",
                                   line.strip())
                for k in range(1, len(corners) - 1):
                    triangles.append((corners[0], corners[k], corners[k + 1]))
    if not triangles:
        raise OBJError(source, 0, "at least one face ('f' line)", "none")
    points = np.array(vertices, dtype=np.float64)
    tri = points[np.array(triangles)]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    extent = float(np.ptp(tri.reshape(-1, 3), axis=0).max()) or 1.0
    tri = tri[area2 > 1e-14 * extent * extent]
    if not len(tri):
        raise OBJError(source, 0, "a face of non-zero area", "only degenerate faces")

    builder = SceneBuilder(path.stem)
    builder.max_depth = int(max_depth)
    builder.background = (0.1, 0.1, 0.12)
    builder.camera, light = frame_mesh(tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0))
    builder.light(light)
    builder.material(Material((0.8, 0.8, 0.8), 0.8, 0.1, 30.0, 0.0, 1.0))
    for triangle in tri:
        builder.triangle(triangle)
    return builder.build()
