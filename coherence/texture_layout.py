"""Where texels live: the order of a texture's texels in memory.

A trace names a texel by its *global number*: textures one after another,
each texture's mip levels from the finest, each level row-major from its top
row (``tracer.rendering.texture``). A :class:`TextureLayout` says where each of those
texels sits in the texel region, in texels from the region's start; the
:class:`~coherence.layout.MemoryLayout` multiplies by the texel size.

Orders within one level of ``w x h`` texels (texel ``(x, y)``, ``y`` the row):

``linear``
    row-major: ``y w + x``.
``tiled``
    ``tile x tile`` tiles, row-major inside a tile, tiles row-major across
    the level; the level is padded to whole tiles.
``morton``
    Z-order: the bits of ``x`` and ``y`` interleaved (``x`` in the lower of
    each pair) over the padded power-of-two size; when one side is longer,
    its extra high bits go above the interleaved ones.
``blocked``
    Hakura & Gupta's two-level blocking (ISCA 1997): ``tile x tile`` blocks
    (row-major inside), ``superblock x superblock`` blocks to a superblock
    (row-major inside), superblocks row-major across the level; padded to
    whole superblocks. With 4-byte texels, a 4 x 4 block is one 64-byte line.

Levels follow each other without gaps. ``chains="contiguous"`` keeps each
texture's whole mip chain together (texture 0's levels, then texture 1's);
``chains="by_level"`` puts every texture's level 0 first, then every level 1,
and so on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rtcommon.validate import InputError, require_power_of_two

ORDERS = ("linear", "tiled", "morton", "blocked")
CHAINS = ("contiguous", "by_level")


@dataclass(frozen=True)
class TextureLayout:
    """The order of texels in memory (see the module docstring).

    Parameters
    ----------
    order : {"linear", "tiled", "morton", "blocked"}
    tile : int
        Side of a tile (``tiled``) or of a block (``blocked``), in texels; a
        power of two.
    superblock : int
        Blocks per superblock side (``blocked``); a power of two.
    chains : {"contiguous", "by_level"}
        Each texture's mip chain together, or level by level across textures.
    """

    order: str = "linear"
    tile: int = 4
    superblock: int = 8
    chains: str = "contiguous"

    def __post_init__(self):
        if self.order not in ORDERS:
            raise InputError(f"TextureLayout.order must be one of {', '.join(ORDERS)}, got {self.order!r}")
        if self.chains not in CHAINS:
            raise InputError(f"TextureLayout.chains must be one of {', '.join(CHAINS)}, got {self.chains!r}")
        for name in ("tile", "superblock"):
            require_power_of_two(f"TextureLayout.{name}", getattr(self, name))

    @classmethod
    def from_label(cls, text: str) -> "TextureLayout":
        """The layout a :attr:`label` names: ``linear``, ``morton``, ``tiled<k>``
        (``tiled`` alone: 4), ``blocked<k>x<s>`` (``blocked`` alone: 4 x 8); a
        ``:by_level`` suffix chains level by level."""
        import re

        label, _, chains = str(text).partition(":")
        match = re.fullmatch(r"(linear|morton|tiled|blocked)(\d+)?(?:x(\d+))?", label)
        if match is None or (match[1] in ("linear", "morton") and match[2]) or (match[1] != "blocked" and match[3]):
            raise InputError(f"unknown texture layout {text!r}: use linear, morton, tiled<k> or blocked<k>x<s>, "
                             "optionally with :by_level")
        tile = int(match[2]) if match[2] else 4
        superblock = int(match[3]) if match[3] else 8
        return cls(match[1], tile=tile, superblock=superblock, chains=chains or "contiguous")

    @property
    def label(self) -> str:
        """Short name for tables: ``linear``, ``tiled4``, ``morton``, ``blocked4x8``
        (with ``:by_level`` when chained level by level)."""
        name = {"tiled": f"tiled{self.tile}", "blocked": f"blocked{self.tile}x{self.superblock}"}.get(
            self.order, self.order)
        return name if self.chains == "contiguous" else f"{name}:{self.chains}"

    def level_texels(self, width: int, height: int) -> int:
        """Texels a ``width x height`` level takes in memory, padding included."""
        if self.order == "linear":
            return width * height
        if self.order == "tiled":
            return _round_up(width, self.tile) * _round_up(height, self.tile)
        if self.order == "morton":
            return _power_of_two(width) * _power_of_two(height)
        side = self.tile * self.superblock
        return _round_up(width, side) * _round_up(height, side)

    def level_order(self, width: int, height: int) -> np.ndarray:
        """Position in memory of every texel of a level, in texels from the
        level's start, as int64 of shape (height * width,), row-major
        (``[y * width + x]``)."""
        y, x = np.divmod(np.arange(width * height, dtype=np.int64), width)
        if self.order == "linear":
            return y * width + x
        if self.order == "tiled":
            tiles_across = _round_up(width, self.tile) // self.tile
            return _blocked(x, y, self.tile, tiles_across)
        if self.order == "morton":
            return _morton(x, y, _power_of_two(width), _power_of_two(height))
        side = self.tile * self.superblock
        superblocks_across = _round_up(width, side) // side
        superblock = (y // side) * superblocks_across + x // side
        inside = _blocked(x % side, y % side, self.tile, self.superblock)
        return superblock * side * side + inside

    def texel_offsets(self, textures) -> np.ndarray:
        """Position of every texel in the texel region, in texels.

        Parameters
        ----------
        textures : sequence of sequence of (int, int)
            For each texture, the ``(width, height)`` of each mip level, finest
            first (a trace's ``textures`` metadata).

        Returns
        -------
        ndarray of int64, shape (N,)
            Entry ``g`` is where the texel of global number ``g`` lives.
        """
        levels = [[(int(w), int(h)) for w, h in texture] for texture in textures]
        for t, texture in enumerate(levels):
            if any(w < 1 or h < 1 for w, h in texture):
                raise InputError(f"texture {t}: every level needs a width and height >= 1, got {texture}")
        if self.chains == "contiguous":
            placing = [(t, k) for t, texture in enumerate(levels) for k in range(len(texture))]
        else:
            depth = max((len(texture) for texture in levels), default=0)
            placing = [(t, k) for k in range(depth) for t, texture in enumerate(levels) if k < len(texture)]
        start = {}
        position = 0
        for t, k in placing:
            start[t, k] = position
            position += self.level_texels(*levels[t][k])
        parts = [start[t, k] + self.level_order(w, h)
                 for t, texture in enumerate(levels) for k, (w, h) in enumerate(texture)]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _round_up(value: int, step: int) -> int:
    return (value + step - 1) // step * step


def _power_of_two(value: int) -> int:
    return 1 << max(0, int(value - 1).bit_length())


def _blocked(x, y, tile, tiles_across):
    """Offsets of ``tile x tile`` tiles laid row-major, ``tiles_across`` to a row."""
    tile_number = (y // tile) * tiles_across + x // tile
    return tile_number * tile * tile + (y % tile) * tile + x % tile


def _morton(x, y, width, height):
    """Z-order offsets over a ``width x height`` (powers of two) area."""
    shared = min(width, height).bit_length() - 1  # bits both coordinates have
    out = np.zeros_like(x)
    for bit in range(shared):
        out |= ((x >> bit) & 1) << (2 * bit)
        out |= ((y >> bit) & 1) << (2 * bit + 1)
    longer = x if width > height else y
    return out | ((longer >> shared) << (2 * shared))
