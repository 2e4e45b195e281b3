"""Pixel orders of a ``width x height`` image along space-filling curves.

Every function returns an int64 array of pixel indices ``y * width + x``, a
permutation of ``range(width * height)``: the order in which a renderer
following the curve visits the pixels.

- :func:`hilbert_order`: the generalised Hilbert ("gilbert") curve, defined for
  any width and height, equal to the classic Hilbert curve on ``2^k x 2^k``.
- :func:`morton_order`: Z-order (bit interleaving) restricted to the image.
- :func:`serpentine_order`: boustrophedon rows, left to right then back.
- :func:`scan_order`: plain row-major scan, for completeness.

The generalised Hilbert curve follows the published description of Jakub
Červený's "gilbert" algorithm (2019): a rectangle spanned by a major vector
``a`` and a minor vector ``b`` is either a single row or column (walked
straight), or, when much longer than wide (``2|a| > 3|b|``), split into two
halves along ``a``, or else split into three parts like the Hilbert
"U": a lower part of height ``|b|/2`` walked with the axes swapped, the whole
upper part walked along ``a``, and the remaining part walked back with the
axes swapped and reversed. Halves are rounded so their lengths are even when
the whole is longer than two, which keeps consecutive pixels 4-neighbours.

Parity decides the rest: a 4-connected path from ``(0, 0)`` to the far end of
its major axis exists only if that axis has even length or both sides are odd
(checkerboard colouring). The curve therefore runs along the longer side,
unless the longer side is odd and the shorter even, in which case it runs
along the shorter (even) side. With that choice consecutive pixels are
4-neighbours for every size tested (all sizes up to 48 x 48 exhaustively and
sampled larger ones, see ``tests/test_curves.py``); the classic orientation
(start at the top-left, first step down, end at the top-right) is kept on
``2^k x 2^k`` squares.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from rtcommon.validate import InputError, require_int

__all__ = [
    "CURVES",
    "curve_order",
    "hilbert_order",
    "morton_order",
    "morton_keys",
    "scan_order",
    "serpentine_order",
]

# Largest side the bit-interleaving keys support (two 31-bit coordinates
# interleave into 62 bits of an int64).
_MAX_SIDE = 1 << 31


def _check_size(width, height) -> tuple[int, int]:
    for name, value in (("width", width), ("height", height)):
        require_int(name, value, 1)
        if value >= _MAX_SIDE:
            raise InputError(f"{name} must be < 2**31, got {value}")
    return int(width), int(height)


# --------------------------------------------------------------------------
# generalised Hilbert


@njit(cache=True)
def _sign(v):
    # Not ``(v > 0) - (v < 0)``: numpy refuses to subtract booleans, which
    # breaks the kernel when it runs as plain Python (NUMBA_DISABLE_JIT=1).
    if v > 0:
        return 1
    if v < 0:
        return -1
    return 0


@njit(cache=True)
def _gilbert_kernel(width, height, major_x, out):
    """Write the generalised Hilbert order of a ``width x height`` image.

    The recursion of the published algorithm runs on an explicit stack of
    rectangles ``(x, y, ax, ay, bx, by)``: origin, major and minor vectors.
    Sub-rectangles are pushed in reverse so they pop in visiting order.
    """
    # Each split halves one side, so the depth is O(log width + log height);
    # a stack level holds at most three pending rectangles.
    stack = np.empty((512, 6), dtype=np.int64)
    top = 0
    if major_x:
        stack[0, 0] = 0; stack[0, 1] = 0; stack[0, 2] = width
        stack[0, 3] = 0; stack[0, 4] = 0; stack[0, 5] = height
    else:
        stack[0, 0] = 0; stack[0, 1] = 0; stack[0, 2] = 0
        stack[0, 3] = height; stack[0, 4] = width; stack[0, 5] = 0
    top = 1
    k = 0
    while top > 0:
        top -= 1
        x = stack[top, 0]; y = stack[top, 1]
        ax = stack[top, 2]; ay = stack[top, 3]
        bx = stack[top, 4]; by = stack[top, 5]
        w = abs(ax + ay)
        h = abs(bx + by)
        dax = _sign(ax); day = _sign(ay)
        dbx = _sign(bx); dby = _sign(by)
        if h == 1:
            for _ in range(w):
                out[k] = y * width + x
                k += 1
                x += dax
                y += day
            continue
        if w == 1:
            for _ in range(h):
                out[k] = y * width + x
                k += 1
                x += dbx
                y += dby
            continue
        # Floor division as in the description (rounds towards -inf for the
        # reversed vectors of the third part).
        ax2 = ax // 2; ay2 = ay // 2
        bx2 = bx // 2; by2 = by // 2
        w2 = abs(ax2 + ay2)
        h2 = abs(bx2 + by2)
        if 2 * w > 3 * h:
            if (w2 % 2) == 1 and w > 2:
                ax2 += dax
                ay2 += day
            # second half first: the stack is last in, first out
            stack[top, 0] = x + ax2; stack[top, 1] = y + ay2
            stack[top, 2] = ax - ax2; stack[top, 3] = ay - ay2
            stack[top, 4] = bx; stack[top, 5] = by
            top += 1
            stack[top, 0] = x; stack[top, 1] = y
            stack[top, 2] = ax2; stack[top, 3] = ay2
            stack[top, 4] = bx; stack[top, 5] = by
            top += 1
        else:
            if (h2 % 2) == 1 and h > 2:
                bx2 += dbx
                by2 += dby
            stack[top, 0] = x + (ax - dax) + (bx2 - dbx)
            stack[top, 1] = y + (ay - day) + (by2 - dby)
            stack[top, 2] = -bx2; stack[top, 3] = -by2
            stack[top, 4] = -(ax - ax2); stack[top, 5] = -(ay - ay2)
            top += 1
            stack[top, 0] = x + bx2; stack[top, 1] = y + by2
            stack[top, 2] = ax; stack[top, 3] = ay
            stack[top, 4] = bx - bx2; stack[top, 5] = by - by2
            top += 1
            stack[top, 0] = x; stack[top, 1] = y
            stack[top, 2] = bx2; stack[top, 3] = by2
            stack[top, 4] = ax2; stack[top, 5] = ay2
            top += 1
    return k


def _hilbert_major_x(width: int, height: int) -> bool:
    """Run along x unless parity forces a diagonal step there but not along y."""
    if width >= height:
        return not (width % 2 == 1 and height % 2 == 0)
    return height % 2 == 1 and width % 2 == 0


def hilbert_order(width: int, height: int) -> np.ndarray:
    """Pixels in generalised Hilbert ("gilbert") curve order.

    Parameters
    ----------
    width, height : int
        Image size in pixels, any values >= 1.

    Returns
    -------
    numpy.ndarray
        int64 ``(width * height,)``, pixel indices ``y * width + x``.

    Notes
    -----
    Equal to the classic Hilbert curve (``d2xy``) on ``2^k x 2^k`` images;
    consecutive pixels are 4-neighbours for every size (see the module notes
    for the parity argument and the orientation rule).
    """
    width, height = _check_size(width, height)
    out = np.empty(width * height, dtype=np.int64)
    written = _gilbert_kernel(width, height, _hilbert_major_x(width, height), out)
    if written != out.size:  # pragma: no cover - a bug, not a user error
        raise RuntimeError(f"gilbert wrote {written} of {out.size} pixels")
    return out


# --------------------------------------------------------------------------
# Morton, serpentine, scan


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Insert a zero bit above each of the low 32 bits of ``v`` (uint64)."""
    v = v.astype(np.uint64) & np.uint64(0xFFFFFFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x3333333333333333)
    v = (v | (v << np.uint64(1))) & np.uint64(0x5555555555555555)
    return v


def morton_keys(x, y) -> np.ndarray:
    """Z-order keys: bits of ``x`` at even positions, bits of ``y`` at odd ones.

    Parameters
    ----------
    x, y : array_like of int
        Non-negative coordinates below ``2**31``, broadcast together.

    Returns
    -------
    numpy.ndarray
        int64 keys; within a ``2^k`` square the order of the keys visits
        ``(0,0), (1,0), (0,1), (1,1)`` (a "Z") at every scale.
    """
    x = np.asarray(x)
    y = np.asarray(y)
    return (_spread_bits(x) | (_spread_bits(y) << np.uint64(1))).astype(np.int64)


def morton_order(width: int, height: int) -> np.ndarray:
    """Pixels in Z-order (Morton) restricted to the image.

    The order is that of the Z curve over the enclosing ``2^k`` square with
    the pixels outside the image skipped, so it may jump between
    non-neighbouring pixels (it does so even on full squares).

    Returns
    -------
    numpy.ndarray
        int64 ``(width * height,)`` pixel indices ``y * width + x``.
    """
    width, height = _check_size(width, height)
    ys, xs = np.divmod(np.arange(width * height, dtype=np.int64), width)
    # keys are unique, so any sort gives the same (stable) result
    return np.argsort(morton_keys(xs, ys), kind="stable").astype(np.int64, copy=False)


def serpentine_order(width: int, height: int) -> np.ndarray:
    """Boustrophedon rows: even rows left to right, odd rows right to left.

    Returns
    -------
    numpy.ndarray
        int64 ``(width * height,)`` pixel indices ``y * width + x``.
    """
    width, height = _check_size(width, height)
    grid = np.arange(width * height, dtype=np.int64).reshape(height, width)
    grid[1::2] = grid[1::2, ::-1]
    return grid.ravel()


def scan_order(width: int, height: int) -> np.ndarray:
    """Row-major scan order, ``arange(width * height)``."""
    width, height = _check_size(width, height)
    return np.arange(width * height, dtype=np.int64)


CURVES = {
    "hilbert": hilbert_order,
    "morton": morton_order,
    "serpentine": serpentine_order,
    "scan": scan_order,
}


def curve_order(curve: str, width: int, height: int) -> np.ndarray:
    """Pixel order of the named curve (one of :data:`CURVES`)."""
    try:
        fn = CURVES[curve]
    except (KeyError, TypeError):
        raise InputError(f"unknown curve {curve!r}; choose one of {sorted(CURVES)}") from None
    return fn(width, height)
