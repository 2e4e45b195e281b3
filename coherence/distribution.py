"""A concrete work distribution: which process renders which pixel, in what order.

A :class:`Distribution` is what a :class:`~coherence.mappings.Mapping` builds
for a ``width x height`` image and ``n_processes``:

- *tasks*: ordered pixel-index arrays (pixel index ``y * width + x``), stored
  as CSR (``task_offsets`` into ``task_pixels``); every pixel is in exactly one
  task, and the order inside a task is the render order;
- *assignment*: static (``task_process[t]`` owns task ``t``; a process renders
  its tasks in task order) or dynamic (``task_process is None``: tasks are
  handed out in task order to the next free process, each hand-out costing
  ``dispatch_cycles``).

The validation helpers here are shared with :mod:`coherence.mappings`.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from rtcommon.validate import InputError, require_int, require_number

__all__ = ["Distribution"]

# Arrays a mapping has just built and holds nowhere else, by id: a
# Distribution takes them without a copy (see _hand_over).
_HANDED_OVER: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def _hand_over(*arrays):
    """Mark a mapping's freshly built arrays (held nowhere else) for a
    :class:`Distribution` to take without a copy; returns them. An array that
    is not a C-contiguous int64 array owning its memory is left to be copied."""
    for array in arrays:
        if (isinstance(array, np.ndarray) and array.dtype == np.int64 and array.flags.c_contiguous
                and array.flags.owndata):
            _HANDED_OVER[id(array)] = array
    return arrays

# --------------------------------------------------------------------------
# validation helpers


def _int_array(owner: str, name: str, value, ndim: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu":
        if arr.size == 0 and arr.dtype.kind == "f":
            arr = arr.astype(np.int64)  # np.array([]) is float64 by default
        else:
            raise InputError(f"{owner}: {name} must hold integers, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        raise InputError(f"{owner}: {name} must be {ndim}-dimensional, got shape {arr.shape}")
    # A private, read-only, contiguous int64 copy: a validated distribution
    # must not change under its users (several simulations share one). An
    # array a mapping has just built and handed over (_hand_over) is private
    # already and is taken as it is: a copy costs 8 bytes a pixel at the
    # height of a run's memory.
    if _HANDED_OVER.pop(id(arr), None) is arr:
        arr.flags.writeable = False
        return arr
    out = np.array(arr, dtype=np.int64, order="C", copy=True)
    out.flags.writeable = False
    return out


def _pixel_text(pixel: int, width: int) -> str:
    y, x = divmod(int(pixel), width)
    return f"pixel {pixel} (x={x}, y={y})"


@njit(cache=True)
def _coverage(pixels, n_pixels):
    """Missing and repeated pixels of ``pixels`` (all in ``[0, n_pixels)``):
    (number missing, first missing, number repeated, first repeated, its
    count), with -1 for an absent first. Counts saturate at 255 in one byte
    a pixel, not a bincount's eight."""
    seen = np.zeros(n_pixels, dtype=np.uint8)
    for pixel in pixels:
        if seen[pixel] < 255:
            seen[pixel] += 1
    n_missing = 0
    first_missing = -1
    n_repeated = 0
    first_repeated = -1
    for pixel in range(n_pixels):
        if seen[pixel] == 0:
            first_missing = pixel if n_missing == 0 else first_missing
            n_missing += 1
        elif seen[pixel] > 1:
            first_repeated = pixel if n_repeated == 0 else first_repeated
            n_repeated += 1
    repeats = np.int64(seen[first_repeated]) if first_repeated >= 0 else 0
    return n_missing, first_missing, n_repeated, first_repeated, repeats


def _check_coverage(owner: str, pixels: np.ndarray, width: int, height: int) -> None:
    """Raise ValueError unless ``pixels`` holds every pixel index exactly once."""
    n_pixels = width * height
    if pixels.size and (pixels.min() < 0 or pixels.max() >= n_pixels):
        bad = pixels[(pixels < 0) | (pixels >= n_pixels)]
        raise InputError(
            f"{owner}: {bad.size} pixel indices outside [0, {n_pixels}) for a "
            f"{width}x{height} image (first: {int(bad[0])})"
        )
    n_missing, first_missing, n_repeated, first_repeated, repeats = _coverage(pixels, n_pixels)
    if n_missing or n_repeated:
        parts = []
        if n_missing:
            parts.append(f"{n_missing} pixels missing (first: {_pixel_text(first_missing, width)})")
        if n_repeated:
            times = f"{repeats} times" if repeats < 255 else "255 times or more"
            parts.append(
                f"{n_repeated} pixels assigned more than once "
                f"(first: {_pixel_text(first_repeated, width)}, {times})"
            )
        raise InputError(
            f"{owner}: every pixel of the {width}x{height} image must be in exactly one task; "
            + "; ".join(parts)
        )


def _validate_distribution(d: "Distribution") -> None:
    if not isinstance(d.name, str) or not d.name:
        raise InputError(f"Distribution.name must be a non-empty string, got {d.name!r}")
    owner = f"Distribution {d.name!r}"
    width = require_int(f"{owner}.width", d.width, 1)
    height = require_int(f"{owner}.height", d.height, 1)
    n = require_int(f"{owner}.n_processes", d.n_processes, 1)
    offsets = _int_array(owner, "task_offsets", d.task_offsets, 1)
    pixels = _int_array(owner, "task_pixels", d.task_pixels, 1)
    n_pixels = width * height
    if offsets.size < 2:
        raise InputError(f"{owner}: task_offsets must have at least 2 entries (one task), got {offsets.size}")
    if offsets[0] != 0 or offsets[-1] != pixels.size:
        raise InputError(
            f"{owner}: task_offsets must start at 0 and end at len(task_pixels) = {pixels.size}, "
            f"got {int(offsets[0])} .. {int(offsets[-1])}"
        )
    if np.any(np.diff(offsets) < 0):
        t = int(np.flatnonzero(np.diff(offsets) < 0)[0])
        raise InputError(f"{owner}: task_offsets must be non-decreasing; task {t} has negative length")
    if pixels.size != n_pixels:
        raise InputError(
            f"{owner}: task_pixels must hold width*height = {n_pixels} pixels, got {pixels.size}"
        )
    _check_coverage(owner, pixels, width, height)
    n_tasks = offsets.size - 1
    if d.task_process is None:
        process = None
    else:
        process = _int_array(owner, "task_process", d.task_process, 1)
        if process.size != n_tasks:
            raise InputError(
                f"{owner}: task_process must have one entry per task ({n_tasks}), got {process.size}"
            )
        bad = np.flatnonzero((process < 0) | (process >= n))
        if bad.size:
            raise InputError(
                f"{owner}: task_process must be in [0, {n}); task {int(bad[0])} "
                f"has process {int(process[bad[0]])} ({bad.size} bad entries)"
            )
    dispatch = require_number(f"{owner}.dispatch_cycles", d.dispatch_cycles, 0, "cycles")
    take_ahead = require_int(f"{owner}.take_ahead", d.take_ahead, 0)
    if process is not None and (dispatch != 0.0 or take_ahead != 0):
        raise InputError(
            f"{owner}: dispatch_cycles and take_ahead apply to dynamic distributions only "
            f"(task_process=None); got {dispatch} and {take_ahead} for a static one"
        )
    for field, value in (
        ("width", width), ("height", height), ("n_processes", n),
        ("task_offsets", offsets), ("task_pixels", pixels), ("task_process", process),
        ("dispatch_cycles", dispatch), ("take_ahead", take_ahead),
    ):
        object.__setattr__(d, field, value)


# --------------------------------------------------------------------------
# Distribution


@dataclass(frozen=True, eq=False)
class Distribution:
    """Concrete work distribution of a ``width x height`` image among processes.

    Parameters
    ----------
    name : str
        Name of the mapping that built it (``"S"``, ``"DB"``, ...).
    width, height, n_processes : int
        Image size and number of processes, all >= 1.
    task_offsets : numpy.ndarray
        int64 ``(T + 1,)``: task ``t`` is ``task_pixels[task_offsets[t]:task_offsets[t + 1]]``.
        Tasks may be empty (e.g. a process with no rows when
        ``n_processes > height``).
    task_pixels : numpy.ndarray
        int64 ``(width * height,)``: pixel indices ``y * width + x``, every
        pixel exactly once, in render order inside each task.
    task_process : numpy.ndarray or None
        int64 ``(T,)``, static owner of each task in ``[0, n_processes)``; a
        process renders its tasks in increasing task index. ``None`` means
        dynamic: tasks are handed out in order (task 0 first) to the next
        free process.
    dispatch_cycles : float
        Cycles one hand-out costs (dynamic only; must be 0 for static).
    take_ahead : int
        Dynamic only: tasks a process may hold queued beyond the one it
        renders (0 = none, the study's DB).

    Notes
    -----
    The arrays are validated on construction and stored as private read-only
    contiguous int64 copies (a mapping's own fresh arrays are taken without
    a copy), so one distribution can be shared safely.
    """

    name: str
    width: int
    height: int
    n_processes: int
    task_offsets: np.ndarray
    task_pixels: np.ndarray
    task_process: np.ndarray | None
    dispatch_cycles: float = 0.0
    take_ahead: int = 0

    def __post_init__(self):
        _validate_distribution(self)

    def __repr__(self) -> str:
        kind = "dynamic" if self.dynamic else "static"
        return (
            f"Distribution({self.name!r}, {self.width}x{self.height}, "
            f"{self.n_processes} processes, {self.n_tasks} tasks, {kind})"
        )

    @property
    def n_tasks(self) -> int:
        """Number of tasks ``T``."""
        return self.task_offsets.size - 1

    @property
    def n_pixels(self) -> int:
        """``width * height``."""
        return self.width * self.height

    @property
    def dynamic(self) -> bool:
        """True when tasks are handed out on demand (``task_process is None``)."""
        return self.task_process is None

    @cached_property
    def task_lengths(self) -> np.ndarray:
        """int64 ``(T,)``: pixels per task."""
        out = np.diff(self.task_offsets)
        out.flags.writeable = False
        return out

    def task(self, t: int) -> np.ndarray:
        """Pixel indices of task ``t`` in render order (a read-only view)."""
        t = require_int(f"Distribution {self.name!r}.task", t, 0)
        if t >= self.n_tasks:
            raise InputError(f"task must be < n_tasks = {self.n_tasks}, got {t}")
        return self.task_pixels[self.task_offsets[t]:self.task_offsets[t + 1]]

    @cached_property
    def _position_task(self) -> np.ndarray:
        # task index of each entry of task_pixels
        return np.repeat(np.arange(self.n_tasks, dtype=np.int64), self.task_lengths)

    def _require_static(self, what: str) -> np.ndarray:
        if self.task_process is None:
            raise InputError(
                f"{what} is defined for static distributions only; {self.name!r} is dynamic "
                "(tasks are handed out at run time)"
            )
        return self.task_process

    def _require_process(self, p) -> int:
        p = require_int(f"Distribution {self.name!r}.process", p, 0)
        if p >= self.n_processes:
            raise InputError(f"process must be < n_processes = {self.n_processes}, got {p}")
        return p

    def process_tasks(self, p: int) -> np.ndarray:
        """Static only: task indices process ``p`` renders, in order."""
        process = self._require_static("process_tasks")
        return np.flatnonzero(process == self._require_process(p)).astype(np.int64)

    def process_pixels(self, p: int) -> np.ndarray:
        """Static only: pixels of process ``p`` in render order.

        Returns
        -------
        numpy.ndarray
            int64, the concatenation of ``p``'s tasks in task order.
        """
        process = self._require_static("process_pixels")
        p = self._require_process(p)
        return self.task_pixels[process[self._position_task] == p]

    def process_pixel_counts(self) -> np.ndarray:
        """Static only: int64 ``(n_processes,)`` pixels per process."""
        process = self._require_static("process_pixel_counts")
        return np.bincount(process, weights=self.task_lengths, minlength=self.n_processes).astype(np.int64)

    def owner_image(self) -> np.ndarray:
        """Who renders each pixel, as an image.

        Returns
        -------
        numpy.ndarray
            int64 ``(height, width)``: the process of each pixel (static) or
            the index of the task holding it (dynamic).
        """
        per_position = self._position_task
        if self.task_process is not None:
            per_position = self.task_process[per_position]
        out = np.empty(self.n_pixels, dtype=np.int64)
        out[self.task_pixels] = per_position
        return out.reshape(self.height, self.width)


def _csr_from_labels(labels: np.ndarray, n_tasks: int) -> tuple[np.ndarray, np.ndarray]:
    """Tasks from a task label per pixel; scan order inside each task.

    Parameters
    ----------
    labels : numpy.ndarray
        int64 ``(width * height,)``, task of each pixel index, in ``[0, n_tasks)``.

    Returns
    -------
    offsets, pixels : numpy.ndarray
        int64 ``(n_tasks + 1,)`` and ``(width * height,)``.
    """
    offsets = np.zeros(n_tasks + 1, dtype=np.int64)
    np.cumsum(np.bincount(labels, minlength=n_tasks), out=offsets[1:])
    # a stable sort keeps pixel (scan) order inside each task
    pixels = np.argsort(labels, kind="stable").astype(np.int64, copy=False)
    return offsets, pixels
