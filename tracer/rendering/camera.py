"""Camera of the SPD test procedure: the primary ray through each sample.

``angle`` spans the centres of the outermost sample rows; pixels are square.
With ``corner_rays`` the samples are the (W + 1) x (H + 1) pixel corners, the
convention of SPD's published counts.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from tracer.scenes.model import Scene
from rtcommon.validate import InputError


class CameraFrame(NamedTuple):
    """The camera as the kernels read it.

    Sample ``(i, j)`` (column, row from the top) looks along
    ``forward + (i - cx) * pitch * right + (cy - j) * pitch * up`` from ``eye``;
    sample number ``p`` is ``(p % samples_x, p // samples_x)``.
    """

    eye: np.ndarray      #: (3,) float64
    forward: np.ndarray  #: (3,) float64 unit
    right: np.ndarray    #: (3,) float64 unit
    up: np.ndarray       #: (3,) float64 unit
    pitch: float         #: distance between samples on the unit-distance image plane
    cx: float            #: column of the optical axis
    cy: float            #: row of the optical axis
    samples_x: int       #: samples per row


def checked_size(size, name: str = "size") -> tuple[int, int]:
    """An image size, an int or a (width, height) pair, as a pair of ints >= 1.

    Raises
    ------
    ValueError
        Naming ``name``: not an int (a bool or a float is not), below 1, or
        not one or two of them.
    """
    pair = (size, size) if np.ndim(size) == 0 else tuple(size)
    if len(pair) != 2 or any(isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 1
                             for v in pair):
        raise InputError(f"{name} must be an int >= 1 or a (width, height) pair of them, got {size!r}")
    return int(pair[0]), int(pair[1])


def _resolve_size(scene: Scene, size) -> tuple[int, int]:
    return scene.camera.resolution if size is None else checked_size(size)


def camera_frame(scene: Scene, width: int, height: int, corner_rays: bool = False) -> CameraFrame:
    """The :class:`CameraFrame` of ``scene``'s camera for a ``width`` x ``height`` image."""
    cam = scene.camera
    eye = np.array(cam.eye, dtype=np.float64)
    fwd = np.array(cam.look_at, dtype=np.float64) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.array(cam.up, dtype=np.float64))
    if np.linalg.norm(right) == 0.0:
        raise InputError("Camera.up must not be parallel to the viewing direction")
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    span = 2.0 * math.tan(math.radians(cam.angle) / 2.0)
    # angle = between the outermost sample rows; aspect 1 (square pixels).
    # With corner rays the (H + 1) corner rows are the samples, which is the
    # convention SPD's published counts use (tetra's 49,950 primary hits
    # come out exactly only this way).
    if corner_rays:
        pitch = span / height
        cx, cy, sx = width / 2.0, height / 2.0, width + 1
    else:
        pitch = span / (height - 1) if height > 1 else span
        cx, cy, sx = (width - 1) / 2.0, (height - 1) / 2.0, width
    return CameraFrame(eye, fwd, np.ascontiguousarray(right), np.ascontiguousarray(up),
                       float(pitch), float(cx), float(cy), int(sx))


def camera_rays(scene: Scene, size=None, corner_rays: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays of :func:`render` (for comparisons with other tracers).

    Returns
    -------
    origin : ndarray, shape (3,)
    directions : ndarray, shape (H', W', 3) unit vectors, H' = H (+1 with corner rays)
    """
    width, height = _resolve_size(scene, size)
    cam = camera_frame(scene, width, height, corner_rays)
    sx = width + 1 if corner_rays else width
    sy = height + 1 if corner_rays else height
    i = np.arange(sx, dtype=np.float64)
    j = np.arange(sy, dtype=np.float64)
    u = (i - cam.cx) * cam.pitch
    v = (cam.cy - j) * cam.pitch
    d = cam.forward[None, None, :] + u[None, :, None] * cam.right + v[:, None, None] * cam.up
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    return cam.eye.copy(), d
