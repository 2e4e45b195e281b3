"""Users' own mappings: from a callable, or from an image of process ids."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .distribution import _check_coverage, _csr_from_labels, _int_array, _pixel_text
from .mapping_base import Mapping, _static
from rtcommon.validate import InputError

__all__ = ["CustomMapping", "from_owner_image"]


@dataclass(frozen=True)
class CustomMapping(Mapping):
    """A user's static mapping from a callable.

    Parameters
    ----------
    name : str
        Label used in tables and pictures.
    fn : callable
        ``fn(width, height, n_processes)`` returning either

        - a ``numpy.ndarray`` of shape ``(height, width)`` with the process
          id of every pixel (one task per process, scan order inside), or
        - a ``list`` or ``tuple`` of ``n_processes`` pixel-index arrays
          (``y * width + x``), one per process in its render order (one task
          per process).

    Every pixel must be assigned exactly once and ids must be in
    ``[0, n_processes)``; a ValueError says what is wrong.
    """

    name: str
    fn: Callable

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"CustomMapping.name must be a non-empty string, got {self.name!r}")
        if not callable(self.fn):
            raise InputError(f"CustomMapping.fn must be callable as fn(width, height, n), got {self.fn!r}")

    def _build(self, width, height, n):
        owner = f"mapping {self.name!r}"
        result = self.fn(width, height, n)
        process = np.arange(n, dtype=np.int64)
        if isinstance(result, (list, tuple)):
            if len(result) != n:
                raise InputError(
                    f"{owner}: fn returned {len(result)} pixel arrays; expected one per process ({n})"
                )
            parts = [
                _int_array(owner, f"pixels of process {p}", np.asarray(a).reshape(-1), 1)
                for p, a in enumerate(result)
            ]
            offsets = np.zeros(n + 1, dtype=np.int64)
            np.cumsum([a.size for a in parts], out=offsets[1:])
            pixels = np.concatenate(parts)
            _check_coverage(owner, pixels, width, height)  # names missing / duplicated pixels
            return _static(self.name, width, height, n, offsets, pixels, process)
        if not isinstance(result, np.ndarray):
            raise InputError(
                f"{owner}: fn must return a (height, width) array of process ids or a list of "
                f"pixel-index arrays per process, got {type(result).__name__}"
            )
        ids = _owner_labels(owner, result, width, height, n)
        offsets, pixels = _csr_from_labels(ids, n)
        return _static(self.name, width, height, n, offsets, pixels, process)


def _owner_labels(owner: str, image, width: int, height: int, n: int) -> np.ndarray:
    """Validated flat process ids from a ``(height, width)`` owner image."""
    image = np.asarray(image)
    if image.shape != (height, width):
        raise InputError(
            f"{owner}: the owner image must have shape (height, width) = ({height}, {width}), got {image.shape}"
        )
    if image.dtype.kind not in "iu":
        raise InputError(f"{owner}: the owner image must hold integer process ids, got dtype {image.dtype}")
    ids = image.astype(np.int64).ravel()
    bad = np.flatnonzero((ids < 0) | (ids >= n))
    if bad.size:
        raise InputError(
            f"{owner}: process ids must be in [0, {n}); {bad.size} pixels are not "
            f"(first: {_pixel_text(bad[0], width)} has id {int(ids[bad[0]])})"
        )
    return ids


class _FixedOwner:
    """The ``fn`` of :func:`from_owner_image`: returns its image for its size."""

    def __init__(self, name: str, owner: np.ndarray):
        self.name = name
        self.owner = owner

    def __call__(self, width, height, n):
        h, w = self.owner.shape
        if (width, height) != (w, h):
            raise InputError(
                f"mapping {self.name!r} is a fixed {w}x{h} owner image; cannot build it for {width}x{height}"
            )
        return self.owner

    def __repr__(self):
        h, w = self.owner.shape
        return f"<fixed {w}x{h} owner image>"


def from_owner_image(name: str, owner) -> CustomMapping:
    """A static mapping from a fixed ``(height, width)`` array of process ids.

    It builds only for that image size; ``n_processes`` must exceed every id
    (processes without pixels are allowed). Scan order inside each process.
    """
    arr = np.array(owner, copy=True)
    if arr.ndim != 2:
        raise InputError(f"from_owner_image: owner must be a (height, width) array, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise InputError(f"from_owner_image: owner must hold integer process ids, got dtype {arr.dtype}")
    arr.flags.writeable = False
    return CustomMapping(name, _FixedOwner(name, arr))
