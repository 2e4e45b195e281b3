"""Per-ray segments of a path-traced trace (format version 4).

Each ray a path tracer traces (camera ray, bounce, shadow ray) reads one
contiguous run of records, its *segment*; a pixel's records are its
segments one after another (samples in order, each sample's rays in the
order traced), so the segments tile the records and replaying a pixel
replays all of its segments. A bounce's or camera ray's segment holds its
traversal, then the shading reads of its hit (the material, then every
light); a shadow ray's segment holds its traversal only.

Two arrays, saved beside the trace's other arrays as ``segment_ints.npy``
and ``segment_rays.npy`` and covered by ``meta.json``'s checksums:

* ``ints``, shape (S, 6) int64, columns :class:`SegmentColumn`: pixel,
  sample, bounce (0 for the camera ray and its shadow rays), ray type
  (:class:`SegmentRayType`) and the record range ``first .. stop - 1``;
* ``rays``, shape (S, 9) float64, columns :class:`SegmentRayColumn`: origin,
  unit direction and hit point (NaN where the ray hit nothing; for a shadow
  ray, the blocker found).
"""
from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np

from rtcommon.validate import InputError


class SegmentRayType(enum.IntEnum):
    """What a segment's ray is."""

    CAMERA = 0
    BOUNCE = 1
    SHADOW = 2


class SegmentColumn(enum.IntEnum):
    """Columns of :attr:`RaySegments.ints`."""

    PIXEL = 0
    SAMPLE = 1
    BOUNCE = 2
    RAY_TYPE = 3
    FIRST = 4  #: first record of the segment
    STOP = 5   #: one past its last record


class SegmentRayColumn(enum.IntEnum):
    """Columns of :attr:`RaySegments.rays`."""

    ORIGIN = 0     #: x; y and z follow
    DIRECTION = 3  #: x, unit; y and z follow
    HIT = 6        #: x, NaN where nothing was hit; y and z follow


N_SEGMENT_COLUMNS = len(SegmentColumn)
N_SEGMENT_RAY_COLUMNS = 9
#: The arrays of :class:`RaySegments`, by the trace file's array name, with their dtypes.
SEGMENT_DTYPES = {"segment_ints": np.dtype("<i8"), "segment_rays": np.dtype("<f8")}


class RaySegments(NamedTuple):
    """The segments of a path-traced trace (module docstring)."""

    ints: np.ndarray  #: (S, N_SEGMENT_COLUMNS) int64, columns SegmentColumn
    rays: np.ndarray  #: (S, N_SEGMENT_RAY_COLUMNS) float64, columns SegmentRayColumn

    @property
    def n_segments(self) -> int:
        return int(self.ints.shape[0])

    def arrays(self) -> dict:
        """The arrays by file array name (:data:`SEGMENT_DTYPES`)."""
        return {"segment_ints": self.ints, "segment_rays": self.rays}


def check_segments(segments, pixel_offsets: np.ndarray, n_records: int) -> None:
    """Check that ``segments`` tile the records pixel by pixel.

    Raises
    ------
    ValueError
        Naming the first broken rule: dtypes and shapes, a ray type, segments
        that do not run from record 0 to ``n_records`` without gaps, or a
        segment outside its pixel's records.
    """
    if not isinstance(segments, RaySegments):
        raise InputError(f"AccessTrace.segments must be RaySegments or None, got {type(segments).__name__}")
    for name, array in segments.arrays().items():
        width = N_SEGMENT_COLUMNS if name == "segment_ints" else N_SEGMENT_RAY_COLUMNS
        if not isinstance(array, np.ndarray) or array.dtype != SEGMENT_DTYPES[name] or array.ndim != 2 \
                or array.shape[1] != width:
            raise InputError(f"AccessTrace.segments: {name} must be a (S, {width}) "
                             f"{SEGMENT_DTYPES[name].name} array")
    ints = np.asarray(segments.ints)
    if segments.rays.shape[0] != ints.shape[0]:
        raise InputError("AccessTrace.segments: segment_ints and segment_rays must have as many rows")
    first, stop = ints[:, SegmentColumn.FIRST], ints[:, SegmentColumn.STOP]
    starts = np.concatenate(([0], stop[:-1]))
    if len(ints) == 0:
        tiled = n_records == 0
    else:
        tiled = bool(np.array_equal(first, starts) and np.all(stop >= first)) and int(stop[-1]) == n_records
    if not tiled:
        raise InputError(f"AccessTrace.segments must tile the records 0..{n_records} in order, without gaps")
    bad_type = np.flatnonzero((ints[:, SegmentColumn.RAY_TYPE] < 0)
                              | (ints[:, SegmentColumn.RAY_TYPE] > max(SegmentRayType)))
    if len(bad_type):
        raise InputError(f"AccessTrace.segments: segment {int(bad_type[0])} has an unknown ray type "
                         f"{int(ints[bad_type[0], SegmentColumn.RAY_TYPE])}")
    pixel = ints[:, SegmentColumn.PIXEL]
    n_pixels = len(pixel_offsets) - 1
    inside = (pixel >= 0) & (pixel < n_pixels)
    if inside.all():
        inside = (pixel_offsets[pixel] <= first) & (stop <= pixel_offsets[pixel + 1])
    if not inside.all():
        s = int(np.flatnonzero(~inside)[0])
        raise InputError(f"AccessTrace.segments: segment {s} (pixel {int(pixel[s])}, records "
                         f"{int(first[s])}..{int(stop[s])}) lies outside its pixel's records")
