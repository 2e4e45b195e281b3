"""Textures: mip-map pyramids, filtered lookups that log every texel, and procedural images.

A scene's texture images (``Scene.texture_*``) become :class:`MipChains`:
each image and its box-filtered halvings down to 1 x 1, every level
row-major from its top row. A texel's *global number* counts the texels of
all textures, each level after level (the record index of
:attr:`tracer.trace.records.RecordKind.TEXEL`); where that texel lives in memory
is the memory layout's choice (:mod:`coherence.texture_layout`).

A lookup (:func:`filtered_lookup`) reads the texture's header record, then
the texels its filter needs, in this order:

* ``nearest``: the texel under (u, v) on the level nearest the level of
  detail;
* ``bilinear``: the 2 x 2 texels around (u, v) on that level, row by row;
* ``trilinear``: the bilinear texels of the two levels around the level of
  detail, finer first (only the finer when the detail falls on a level or
  outside the pyramid).

Coordinates wrap (the texture repeats); ``u`` runs right, ``v`` up, so
``v = 1`` is the image's top row. Texel values are RGBA8; colours are
``value / 255``.
"""
from __future__ import annotations

import enum
import math
from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.jit import NO_REFCOUNTS
from rtcommon.validate import InputError, require_int
from tracer.trace.records import Counter, RecordKind, make_record

#: the most texels a trace can name (27-bit record indices)
MAX_TEXELS = 1 << 27


class TextureFilter(enum.IntEnum):
    """How a lookup filters texels (see the module docstring)."""

    NEAREST = 0
    BILINEAR = 1
    TRILINEAR = 2


class MipChains(NamedTuple):
    """Every texture's mip pyramid, as the kernels read it.

    Attributes
    ----------
    texels : ndarray of uint8, shape (N, 4)
        RGBA of every texel, by global number.
    level_first : ndarray of int64, shape (K + 1,)
        Level ``k`` (all textures' levels, texture by texture, finest first)
        holds texels ``level_first[k]:level_first[k + 1]``.
    level_width, level_height : ndarray of int64, shape (K,)
    texture_level : ndarray of int64, shape (X + 1,)
        Texture ``x``'s levels are ``texture_level[x]:texture_level[x + 1]``.
    """

    texels: np.ndarray
    level_first: np.ndarray
    level_width: np.ndarray
    level_height: np.ndarray
    texture_level: np.ndarray

    def levels(self) -> list:
        """Each texture's levels as ``[[width, height], ...]``, finest first (plain ints)."""
        return [[[int(self.level_width[k]), int(self.level_height[k])]
                 for k in range(self.texture_level[x], self.texture_level[x + 1])]
                for x in range(self.texture_level.shape[0] - 1)]


def halve(image: np.ndarray) -> np.ndarray:
    """The next mip level of ``image`` (H, W, 4) uint8: each texel the rounded
    mean of a 2 x 2 box (a side of odd length repeats its last row or column),
    shape (max(1, H // 2), max(1, W // 2), 4)."""
    height, width = image.shape[:2]
    out_h, out_w = max(1, height // 2), max(1, width // 2)
    rows = np.minimum(np.arange(2 * out_h).reshape(out_h, 2), height - 1)
    cols = np.minimum(np.arange(2 * out_w).reshape(out_w, 2), width - 1)
    wide = image.astype(np.uint32)
    total = (wide[rows[:, 0]][:, cols[:, 0]] + wide[rows[:, 0]][:, cols[:, 1]]
             + wide[rows[:, 1]][:, cols[:, 0]] + wide[rows[:, 1]][:, cols[:, 1]])
    return ((total + 2) // 4).astype(np.uint8)


def mip_chains(scene) -> MipChains:
    """The mip pyramids of ``scene``'s textures (see :class:`MipChains`).

    Raises
    ------
    ValueError
        Texture arrays of the wrong shape, more than :data:`MAX_TEXELS`
        texels in all levels, or a scene read without its texels.
    """
    sizes = np.asarray(scene.texture_size, dtype=np.int64).reshape(-1, 2)
    offsets = np.asarray(scene.texture_offsets, dtype=np.int64)
    if not scene.texels_read:
        raise InputError(f"scene {scene.name!r} was read without its texels (texels=False, for a summary); "
                         "read it again with texels to render it")
    texels = np.asarray(scene.texture_texels)
    if offsets.shape != (sizes.shape[0] + 1,) or (sizes.size and sizes.min() < 1):
        raise InputError("Scene.texture_offsets must have one entry per texture plus one, "
                         "and every texture_size a width and height >= 1")
    if texels.dtype != np.uint8 or texels.ndim != 2 or texels.shape[1] != 4 \
            or offsets[-1] != texels.shape[0] or np.any(np.diff(offsets) != sizes[:, 0] * sizes[:, 1]):
        raise InputError("Scene.texture_texels must be uint8 (N, 4), width x height rows per texture")
    levels, widths, heights, texture_level = [], [], [], [0]
    for x, (width, height) in enumerate(sizes):
        image = texels[offsets[x]:offsets[x + 1]].reshape(height, width, 4)
        while True:
            levels.append(image.reshape(-1, 4))
            widths.append(image.shape[1])
            heights.append(image.shape[0])
            if image.shape[0] == 1 and image.shape[1] == 1:
                break
            image = halve(image)
        texture_level.append(len(levels))
    level_first = np.zeros(len(levels) + 1, dtype=np.int64)
    np.cumsum([len(level) for level in levels], out=level_first[1:])
    if level_first[-1] > MAX_TEXELS:
        raise InputError(f"the textures' mip levels hold {int(level_first[-1])} texels; "
                         f"a trace can name at most {MAX_TEXELS}")
    return MipChains(np.ascontiguousarray(np.concatenate(levels)) if levels else np.zeros((0, 4), np.uint8),
                     level_first, np.array(widths, dtype=np.int64), np.array(heights, dtype=np.int64),
                     np.array(texture_level, dtype=np.int64))


def procedural_texture(width: int, height: int | None = None, *, seed: int = 0, cells: int = 8) -> np.ndarray:
    """A seeded image of ``width x height`` texels, (height, width, 4) uint8 RGBA.

    A ``cells x cells`` board of random colours (each cell one colour) with
    independent per-texel noise of +-24, so neighbouring texels differ and
    coarser mip levels average to the cells' colours. The same arguments
    give the same image.
    """
    height = width if height is None else height
    for name, value in (("width", width), ("height", height), ("cells", cells)):
        require_int(f"procedural_texture: {name}", value, 1)
    rng = np.random.default_rng(seed)
    board = rng.integers(48, 232, size=(cells, cells, 3))
    rows = np.arange(height) * cells // height
    cols = np.arange(width) * cells // width
    image = board[rows][:, cols] + rng.integers(-24, 25, size=(height, width, 3))
    alpha = np.full((height, width, 1), 255)
    return np.concatenate([np.clip(image, 0, 255), alpha], axis=2).astype(np.uint8)


# --------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _read_texel(chains, level, x, y, log, pos, cnt):
    # texel (x, y) of global level ``level``: its colour and the next record
    # position (the read logged as a TEXEL record)
    number = chains.level_first[level] + y * chains.level_width[level] + x
    rec, limit = log
    if pos < limit:
        rec[pos] = make_record(RecordKind.TEXEL, number)
    cnt[Counter.TEXEL_READS] += 1
    texel = chains.texels[number]
    return np.float64(texel[0]) / 255.0, np.float64(texel[1]) / 255.0, np.float64(texel[2]) / 255.0, pos + 1


@njit(cache=True, inline="always")
def _wrap(value):
    return value - math.floor(value)


@njit(cache=True, **NO_REFCOUNTS)
def _nearest(chains, level, u, v, log, pos, cnt):
    width = chains.level_width[level]
    height = chains.level_height[level]
    x = min(np.int64(_wrap(u) * width), width - 1)
    y = min(np.int64((1.0 - _wrap(v)) * height), height - 1)
    return _read_texel(chains, level, x, y, log, pos, cnt)


@njit(cache=True, **NO_REFCOUNTS)
def _bilinear(chains, level, u, v, log, pos, cnt):
    # the 2 x 2 texels around (u, v), weighted by distance to their centres
    width = chains.level_width[level]
    height = chains.level_height[level]
    fx = _wrap(u) * width - 0.5
    fy = (1.0 - _wrap(v)) * height - 0.5
    x0 = math.floor(fx)
    y0 = math.floor(fy)
    ax = fx - x0
    ay = fy - y0
    xa = np.int64(x0) % width
    xb = (xa + 1) % width
    ya = np.int64(y0) % height
    yb = (ya + 1) % height
    r00, g00, b00, pos = _read_texel(chains, level, xa, ya, log, pos, cnt)
    r10, g10, b10, pos = _read_texel(chains, level, xb, ya, log, pos, cnt)
    r01, g01, b01, pos = _read_texel(chains, level, xa, yb, log, pos, cnt)
    r11, g11, b11, pos = _read_texel(chains, level, xb, yb, log, pos, cnt)
    w00 = (1.0 - ax) * (1.0 - ay)
    w10 = ax * (1.0 - ay)
    w01 = (1.0 - ax) * ay
    w11 = ax * ay
    return (w00 * r00 + w10 * r10 + w01 * r01 + w11 * r11, w00 * g00 + w10 * g10 + w01 * g01 + w11 * g11,
            w00 * b00 + w10 * b10 + w01 * b01 + w11 * b11, pos)


@njit(cache=True, **NO_REFCOUNTS)
def filtered_lookup(chains, texture, u, v, detail, filter_mode, log, pos, cnt):
    """Colour of ``texture`` at (u, v), filtered at level of detail ``detail``.

    Parameters
    ----------
    chains : MipChains
    texture : int
    u, v : float
        Texture coordinates (wrapped).
    detail : float
        log2 of the footprint's width in level-0 texels; level ``k`` is
        ``detail == k``, clamped to the pyramid.
    filter_mode : int
        A :class:`TextureFilter` value.
    log : tracer.kd.traverse.RecordLog
        Records go to ``log.records[pos:]`` while below ``log.limit``.
    pos : int
    cnt : ndarray of int64, shape (N_COUNTERS,)
        Counts the lookup and its texel reads.

    Returns
    -------
    r, g, b : float
    pos : int
        The position after the lookup's last record.
    """
    rec, limit = log
    if pos < limit:
        rec[pos] = make_record(RecordKind.TEXTURE, texture)
    pos += 1
    cnt[Counter.TEXTURE_LOOKUPS] += 1
    first = chains.texture_level[texture]
    coarsest = chains.texture_level[texture + 1] - 1 - first
    level = min(max(detail, 0.0), np.float64(coarsest))
    if filter_mode == TextureFilter.TRILINEAR:
        finer = np.int64(math.floor(level))
        blend = level - finer
        r, g, b, pos = _bilinear(chains, first + finer, u, v, log, pos, cnt)
        if blend > 0.0:
            r2, g2, b2, pos = _bilinear(chains, first + finer + 1, u, v, log, pos, cnt)
            r += blend * (r2 - r)
            g += blend * (g2 - g)
            b += blend * (b2 - b)
        return r, g, b, pos
    nearest = first + np.int64(math.floor(level + 0.5))
    if filter_mode == TextureFilter.BILINEAR:
        return _bilinear(chains, nearest, u, v, log, pos, cnt)
    return _nearest(chains, nearest, u, v, log, pos, cnt)
