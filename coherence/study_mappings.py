"""The study's five mappings (docs/design.md, "The study's experiment"): strips, pixels, rows, blocks and dynamic blocks."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numba import njit

from rtcommon.validate import require_int

from .distribution import _csr_from_labels
from .mapping_base import DEFAULT_DISPATCH_CYCLES, Mapping, _check_dynamic, _dynamic, _static

__all__ = ["Strip", "Pixel", "Row", "Block", "DynamicBlock"]


@dataclass(frozen=True)
class Strip(Mapping):
    """"S": ``n`` contiguous bands of whole rows, row counts differing by at most one.

    The first ``height % n`` processes get one row more. One task per process,
    row-major scan inside.
    """

    name: ClassVar[str] = "S"

    def _build(self, width, height, n):
        rows = np.full(n, height // n, dtype=np.int64)
        rows[: height % n] += 1
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(rows * width, out=offsets[1:])
        pixels = np.arange(width * height, dtype=np.int64)
        return _static(self.name, width, height, n, offsets, pixels, np.arange(n, dtype=np.int64))


@dataclass(frozen=True)
class Pixel(Mapping):
    """"P": pixel ``k = y * width + x`` goes to process ``k mod n``.

    One task per process holding its pixels in scan order.
    """

    name: ClassVar[str] = "P"

    def _build(self, width, height, n):
        labels = np.arange(width * height, dtype=np.int64) % n
        offsets, pixels = _csr_from_labels(labels, n)
        return _static(self.name, width, height, n, offsets, pixels, np.arange(n, dtype=np.int64))


@dataclass(frozen=True)
class Row(Mapping):
    """"R": row ``r`` goes to process ``r mod n``.

    One task per process holding its rows in order, scan order inside.
    """

    name: ClassVar[str] = "R"

    def _build(self, width, height, n):
        labels = (np.arange(width * height, dtype=np.int64) // width) % n
        offsets, pixels = _csr_from_labels(labels, n)
        return _static(self.name, width, height, n, offsets, pixels, np.arange(n, dtype=np.int64))


def _block_columns(fw: int, fh: int, n: int) -> int:
    """Columns of blocks for an ``fw x fh`` field cut into ``n`` blocks.

    Candidates are the floor and ceiling of ``sqrt(n * fw / fh)`` (square
    blocks need ``fw / c == fh * c / n``); the one whose worst block aspect
    ratio is smaller wins, ties going to fewer columns.
    """
    ideal = math.sqrt(n * fw / fh)
    limit = max(1, min(n, fw))
    best, best_score = 1, math.inf
    for c in sorted({min(limit, max(1, math.floor(ideal))), min(limit, max(1, math.ceil(ideal)))}):
        score = 0.0
        for k in {n // c, n // c + (1 if n % c else 0)}:
            if k == 0:
                continue
            w = fw * k / n
            h = fh / k
            score = max(score, w / h, h / w)
        if score < best_score:
            best, best_score = c, score
    return best


@njit(cache=True)
def _block_labels_kernel(width, height, field, n, columns, labels):
    """Task of every pixel for :class:`Block` (see its docstring).

    ``columns[f]`` is the number of block columns of field ``f``; task
    ``f * n + j`` is block ``j`` of field ``f``.
    """
    nfx = (width + field - 1) // field
    nfy = (height + field - 1) // field
    target = np.empty(n, dtype=np.int64)
    offset = 0  # where the round-robin of extra pixels continues
    for fy in range(nfy):
        for fx in range(nfx):
            f = fy * nfx + fx
            x0 = fx * field
            y0 = fy * field
            fw = min(field, width - x0)
            fh = min(field, height - y0)
            area = fw * fh
            q = area // n
            rem = area % n
            for j in range(n):
                target[j] = q + (1 if (j - offset) % n < rem else 0)
            offset = (offset + rem) % n
            c = columns[f]
            base = n // c
            extra = n % c
            j0 = 0
            start = 0  # column-major position where this block column starts
            for i in range(c):
                k = base + (1 if i < extra else 0)
                budget = 0
                for j in range(j0, j0 + k):
                    budget += target[j]
                end = start + budget
                if budget > 0:
                    cx0 = start // fh
                    cx1 = (end - 1) // fh
                    j = j0
                    left = target[j]
                    # row-major walk of the column's pixels, cutting it into
                    # its blocks by pixel count
                    for y in range(fh):
                        for x in range(cx0, cx1 + 1):
                            pos = x * fh + y
                            if pos < start or pos >= end:
                                continue
                            while left == 0:
                                j += 1
                                left = target[j]
                            labels[(y0 + y) * width + x0 + x] = f * n + j
                            left -= 1
                j0 += k
                start = end


@dataclass(frozen=True)
class Block(Mapping):
    """"B": ``field x field`` fields, each cut into ``n`` blocks; block ``j`` -> process ``j``.

    Fields tile the image in row-major order (edge fields are smaller when
    the image size is not a multiple of ``field``). Tasks are one per (field,
    block): task ``f * n + j`` is block ``j`` of field ``f``, pixels in scan
    order. A block may be empty only when a field has fewer than ``n`` pixels.

    Cutting an ``fw x fh`` field into ``n`` blocks:

    1. Pixel counts first: every block gets ``q = fw * fh // n`` pixels and
       ``fw * fh % n`` of them one more. Which blocks get the extra pixel
       continues round-robin from field to field, so over the whole image the
       pixel counts of any two processes differ by at most one (and within a
       field any two blocks differ by at most one pixel, well inside the
       study's "almost equal").
    2. Shape: ``c`` block columns, ``c`` the floor or ceiling of
       ``sqrt(n * fw / fh)``, whichever gives the smaller worst aspect ratio
       (:func:`_block_columns`). Columns hold ``n // c`` or ``n // c + 1``
       blocks (the fuller ones on the left), numbered top to bottom, columns
       left to right.
    3. Column ``i`` is the run of the field's column-major pixel order whose
       length is the sum of its blocks' counts: whole pixel columns plus
       possibly a partial column at either side. Each column is then cut in
       its row-major order into its blocks' counts: whole rows plus possibly
       a partial first and last row.

    So blocks are rectangles up to one partial row and one partial column,
    near square (on 64 x 64 fields the bounding boxes of all blocks for
    n <= 64 have aspect ratios <= 2.91, the worst being n = 3), and exact
    rectangles whenever the counts divide evenly (on 64 x 64: n = 1, 2, 4,
    8, 16, 64; n = 2 cuts a field into top and bottom halves, n = 8 into
    2 x 4 blocks of 32 x 16).
    """

    field: int = 64
    name: ClassVar[str] = "B"

    def __post_init__(self):
        require_int("Block.field", self.field, 1)

    def _build(self, width, height, n):
        field = self.field
        nfx = -(-width // field)
        nfy = -(-height // field)
        sizes_x = np.minimum(field, width - field * np.arange(nfx))
        sizes_y = np.minimum(field, height - field * np.arange(nfy))
        # at most four distinct field sizes: choose columns once per size
        choice = {}
        columns = np.empty(nfx * nfy, dtype=np.int64)
        for fy in range(nfy):
            for fx in range(nfx):
                key = (int(sizes_x[fx]), int(sizes_y[fy]))
                if key not in choice:
                    choice[key] = _block_columns(key[0], key[1], n)
                columns[fy * nfx + fx] = choice[key]
        labels = np.empty(width * height, dtype=np.int64)
        _block_labels_kernel(width, height, field, n, columns, labels)
        n_tasks = nfx * nfy * n
        offsets, pixels = _csr_from_labels(labels, n_tasks)
        process = np.tile(np.arange(n, dtype=np.int64), nfx * nfy)
        return _static(self.name, width, height, n, offsets, pixels, process)


@dataclass(frozen=True)
class DynamicBlock(Mapping):
    """"DB": ``block x block`` blocks handed out on demand in row-major block order.

    Edge blocks are smaller when the image size is not a multiple of
    ``block``; scan order inside a block.

    Parameters
    ----------
    block : int
        Block side in pixels (the study: 32).
    dispatch_cycles : float
        Cost of one hand-out; the default :data:`DEFAULT_DISPATCH_CYCLES`
        (6000 = a ~20 µs master round trip at 300 MHz) is an assumption.
    take_ahead : int
        Tasks a process may hold queued beyond the one it renders (the
        study: 0).
    """

    block: int = 32
    dispatch_cycles: float = DEFAULT_DISPATCH_CYCLES
    take_ahead: int = 0
    name: ClassVar[str] = "DB"

    def __post_init__(self):
        require_int("DynamicBlock.block", self.block, 1)
        _check_dynamic("DynamicBlock", self.dispatch_cycles, self.take_ahead)

    def _build(self, width, height, n):
        b = self.block
        nbx = -(-width // b)
        nby = -(-height // b)
        ys, xs = np.divmod(np.arange(width * height, dtype=np.int64), width)
        labels = (ys // b) * nbx + xs // b
        offsets, pixels = _csr_from_labels(labels, nbx * nby)
        return _dynamic(self, width, height, n, offsets, pixels)
