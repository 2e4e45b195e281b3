"""Space-filling-curve orders as mappings: contiguous curve segments, or curve-ordered tiles."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rtcommon.validate import InputError, require_bool, require_int

from .curves import CURVES, curve_order, hilbert_order, morton_keys
from .mapping_base import DEFAULT_DISPATCH_CYCLES, Mapping, _check_dynamic, _dynamic, _static

__all__ = ["CurveSegments", "CurveTiles"]


@dataclass(frozen=True)
class CurveSegments(Mapping):
    """Static partition of a curve order into ``n`` contiguous segments.

    Segment ``p`` is curve positions ``floor(N * p / n)`` to
    ``floor(N * (p + 1) / n)`` (``N = width * height``), so lengths differ by
    at most one pixel; it goes to process ``p`` and is rendered along the
    curve. ``name`` is the curve's
    name (``"hilbert"``, ``"morton"``, ``"serpentine"``, ``"scan"``).
    """

    curve: str = "hilbert"

    def __post_init__(self):
        if self.curve not in CURVES:
            raise InputError(f"CurveSegments.curve must be one of {sorted(CURVES)}, got {self.curve!r}")

    @property
    def name(self) -> str:
        return self.curve

    def _build(self, width, height, n):
        order = curve_order(self.curve, width, height)
        offsets = (order.size * np.arange(n + 1, dtype=np.int64)) // n
        return _static(self.name, width, height, n, offsets, order, np.arange(n, dtype=np.int64))


@dataclass(frozen=True)
class CurveTiles(Mapping):
    """``tile x tile`` tiles visited along the Hilbert curve of the tile grid.

    Pixels inside a tile follow the Morton order of the tile (``inner =
    "morton"``) or its row-major scan (``"scan"``); edge tiles are smaller
    and their Morton order skips the missing pixels. One task per tile, in
    Hilbert order of the tile grid (:func:`~coherence.curves.hilbert_order`
    of a ``ceil(width / tile) x ceil(height / tile)`` grid).

    Static (default): tile ``t`` in visiting order goes to process ``t mod n``.
    ``dynamic=True``: tiles are handed out on demand in visiting order, with
    ``dispatch_cycles`` and ``take_ahead`` as in :class:`DynamicBlock` (both
    ignored, and ``take_ahead`` must be 0, when static).

    ``name`` is ``"hilbert-tiles"`` with ``"-scan"`` appended for scan order
    inside and ``"-dynamic"`` for dynamic hand-out.
    """

    tile: int = 32
    inner: str = "morton"
    dynamic: bool = False
    dispatch_cycles: float = DEFAULT_DISPATCH_CYCLES
    take_ahead: int = 0

    def __post_init__(self):
        require_int("CurveTiles.tile", self.tile, 1)
        if self.inner not in ("morton", "scan"):
            raise InputError(f"CurveTiles.inner must be 'morton' or 'scan', got {self.inner!r}")
        object.__setattr__(self, "dynamic", require_bool("CurveTiles.dynamic", self.dynamic))
        _check_dynamic("CurveTiles", self.dispatch_cycles, self.take_ahead)
        if not self.dynamic and self.take_ahead != 0:
            raise InputError("CurveTiles.take_ahead applies to dynamic=True only; it must be 0 when static")

    @property
    def name(self) -> str:
        return "hilbert-tiles" + ("-scan" if self.inner == "scan" else "") + ("-dynamic" if self.dynamic else "")

    def _build(self, width, height, n):
        t = self.tile
        ntx = -(-width // t)
        nty = -(-height // t)
        rank = np.empty(ntx * nty, dtype=np.int64)
        rank[hilbert_order(ntx, nty)] = np.arange(ntx * nty, dtype=np.int64)
        ys, xs = np.divmod(np.arange(width * height, dtype=np.int64), width)
        tile_rank = rank[(ys // t) * ntx + xs // t]
        lx = xs % t
        ly = ys % t
        if self.inner == "morton":
            inner = morton_keys(lx, ly)
            span = 1 << (2 * (t - 1).bit_length())
        else:
            inner = ly * t + lx
            span = t * t
        pixels = np.argsort(tile_rank * span + inner, kind="stable").astype(np.int64, copy=False)
        offsets = np.zeros(ntx * nty + 1, dtype=np.int64)
        np.cumsum(np.bincount(tile_rank, minlength=ntx * nty), out=offsets[1:])
        if self.dynamic:
            return _dynamic(self, width, height, n, offsets, pixels)
        process = np.arange(ntx * nty, dtype=np.int64) % n
        return _static(self.name, width, height, n, offsets, pixels, process)
