"""Mappings: recipes for splitting an image among processes.

A :class:`Mapping` is a recipe (frozen, validated parameters); its
:meth:`Mapping.build` turns it into a concrete
:class:`~coherence.distribution.Distribution` of a ``width x height`` image
among ``n_processes`` (tasks of ordered pixels, assigned statically or handed
out dynamically; see :mod:`coherence.distribution`).

Built-in mappings (DESIGN.md §2): :class:`Strip` "S", :class:`Pixel` "P",
:class:`Row` "R", :class:`Block` "B", :class:`DynamicBlock` "DB", plus
space-filling-curve orders (:class:`CurveSegments`, :class:`CurveTiles`) and
users' own (:class:`CustomMapping`, :func:`from_owner_image`). :data:`MAPPINGS`
holds a default instance of each built-in by name; :func:`get_mapping` looks
one up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np
from numba import njit

from .curves import CURVES, curve_order, hilbert_order, morton_keys
from rtcommon.validate import require_int, require_number

from .distribution import Distribution, _check_coverage, _csr_from_labels, _int_array, _pixel_text

__all__ = [
    "DEFAULT_DISPATCH_CYCLES",
    "DEFAULT_MAPPINGS",
    "MAPPINGS",
    "Block",
    "CurveSegments",
    "CurveTiles",
    "CustomMapping",
    "Distribution",
    "DynamicBlock",
    "Mapping",
    "Pixel",
    "Row",
    "Strip",
    "from_owner_image",
    "get_mapping",
]

#: Cycles one dynamic hand-out costs by default. An assumption, not a figure
#: from the study: a request/reply round trip to the master through shared
#: memory of about 20 µs at 300 MHz (the Alpha 21164 of the AlphaServer 8400).
DEFAULT_DISPATCH_CYCLES = 6000.0


# --------------------------------------------------------------------------
# Mapping base


class Mapping:
    """Base of work-distribution recipes.

    Subclasses are frozen dataclasses that validate their parameters and have
    a ``name`` (class attribute or property). They implement
    ``_build(width, height, n_processes) -> Distribution`` on validated
    arguments; users call :meth:`build`.
    """

    name: str  # provided by each subclass

    def build(self, width: int, height: int, n_processes: int) -> Distribution:
        """Distribute a ``width x height`` image among ``n_processes``.

        Raises
        ------
        ValueError
            If a size is not an integer >= 1.
        """
        owner = type(self).__name__
        width = require_int(f"{owner}.width", width, 1)
        height = require_int(f"{owner}.height", height, 1)
        n_processes = require_int(f"{owner}.n_processes", n_processes, 1)
        return self._build(width, height, n_processes)

    def _build(self, width: int, height: int, n_processes: int) -> Distribution:  # pragma: no cover
        raise NotImplementedError

    def picture(self, n_processes: int, width: int = 512, height: int = 512, ax=None):
        """Draw which process renders which pixel.

        Static mappings are coloured by process, dynamic ones by task index
        (their owner is only known at run time; the title says "dynamic").
        Colours repeat after 20 processes or tasks.

        Returns
        -------
        matplotlib.axes.Axes
        """
        import matplotlib.pyplot as plt
        from matplotlib.colors import ListedColormap

        dist = self.build(width, height, n_processes)
        image = dist.owner_image()
        n_values = dist.n_tasks if dist.dynamic else n_processes
        if n_values <= 10:
            colours = list(plt.get_cmap("tab10").colors)
        else:
            # tab20 pairs dark and light shades of a hue; all dark first keeps
            # neighbouring ids apart
            tab20 = list(plt.get_cmap("tab20").colors)
            colours = tab20[0::2] + tab20[1::2]
        n_colours = len(colours)
        if ax is None:
            _, ax = plt.subplots(figsize=(4, 4 * height / width))
        ax.imshow(
            image % n_colours,
            cmap=ListedColormap(colours),
            vmin=-0.5,
            vmax=n_colours - 0.5,
            interpolation="nearest",
        )
        if dist.dynamic:
            title = f"{dist.name}: dynamic, {dist.n_tasks} tasks (colour = task)"
        else:
            title = f"{dist.name}: {n_processes} process{'es' if n_processes != 1 else ''}"
        ax.set_title(title)
        ax.set_xticks([])
        ax.set_yticks([])
        return ax


def _static(name, width, height, n, offsets, pixels, process) -> Distribution:
    return Distribution(name, width, height, n, offsets, pixels, process)


# --------------------------------------------------------------------------
# the study's mappings


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


def _check_dynamic(owner: str, dispatch_cycles, take_ahead) -> None:
    require_number(f"{owner}.dispatch_cycles", dispatch_cycles, 0, "cycles")
    require_int(f"{owner}.take_ahead", take_ahead, 0)


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
        return Distribution(
            self.name, width, height, n, offsets, pixels, None,
            dispatch_cycles=float(self.dispatch_cycles), take_ahead=int(self.take_ahead),
        )


# --------------------------------------------------------------------------
# space-filling curves


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
            raise ValueError(f"CurveSegments.curve must be one of {sorted(CURVES)}, got {self.curve!r}")

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
            raise ValueError(f"CurveTiles.inner must be 'morton' or 'scan', got {self.inner!r}")
        if not isinstance(self.dynamic, bool):
            raise ValueError(f"CurveTiles.dynamic must be True or False, got {self.dynamic!r}")
        _check_dynamic("CurveTiles", self.dispatch_cycles, self.take_ahead)
        if not self.dynamic and self.take_ahead != 0:
            raise ValueError("CurveTiles.take_ahead applies to dynamic=True only; it must be 0 when static")

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
            return Distribution(
                self.name, width, height, n, offsets, pixels, None,
                dispatch_cycles=float(self.dispatch_cycles), take_ahead=int(self.take_ahead),
            )
        process = np.arange(ntx * nty, dtype=np.int64) % n
        return _static(self.name, width, height, n, offsets, pixels, process)


# --------------------------------------------------------------------------
# users' own


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
            raise ValueError(f"CustomMapping.name must be a non-empty string, got {self.name!r}")
        if not callable(self.fn):
            raise ValueError(f"CustomMapping.fn must be callable as fn(width, height, n), got {self.fn!r}")

    def _build(self, width, height, n):
        owner = f"mapping {self.name!r}"
        result = self.fn(width, height, n)
        process = np.arange(n, dtype=np.int64)
        if isinstance(result, (list, tuple)):
            if len(result) != n:
                raise ValueError(
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
            raise ValueError(
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
        raise ValueError(
            f"{owner}: the owner image must have shape (height, width) = ({height}, {width}), got {image.shape}"
        )
    if image.dtype.kind not in "iu":
        raise ValueError(f"{owner}: the owner image must hold integer process ids, got dtype {image.dtype}")
    ids = image.astype(np.int64).ravel()
    bad = np.flatnonzero((ids < 0) | (ids >= n))
    if bad.size:
        raise ValueError(
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
            raise ValueError(
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
        raise ValueError(f"from_owner_image: owner must be a (height, width) array, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise ValueError(f"from_owner_image: owner must hold integer process ids, got dtype {arr.dtype}")
    arr.flags.writeable = False
    return CustomMapping(name, _FixedOwner(name, arr))


# --------------------------------------------------------------------------
# registry

MAPPINGS: dict[str, Mapping] = {
    m.name: m
    for m in (
        Strip(),
        Pixel(),
        Row(),
        Block(),
        DynamicBlock(),
        CurveSegments("hilbert"),
        CurveSegments("morton"),
        CurveSegments("serpentine"),
        CurveTiles(),
    )
}


#: The study's five mappings, in its order: the default of every comparison
#: (the command line, :func:`coherence.studies.study`, reports, the paper, what-ifs).
DEFAULT_MAPPINGS = ("S", "P", "R", "B", "DB")


def get_mapping(name_or_mapping) -> Mapping:
    """A :class:`Mapping` given itself or a name of :data:`MAPPINGS`.

    Names match exactly first, then ignoring case (``"db"`` is ``"DB"``).
    """
    if isinstance(name_or_mapping, Mapping):
        return name_or_mapping
    if isinstance(name_or_mapping, str):
        if name_or_mapping in MAPPINGS:
            return MAPPINGS[name_or_mapping]
        folded = {k.lower(): v for k, v in MAPPINGS.items()}
        if name_or_mapping.lower() in folded:
            return folded[name_or_mapping.lower()]
    raise ValueError(f"unknown mapping {name_or_mapping!r}; choose one of {', '.join(MAPPINGS)} or pass a Mapping")
