"""Integrity of an access trace: the rules its arrays obey and the digests that cover its files.

Every byte a loaded trace depends on is under one digest. ``meta.json.xxh3``
holds the XXH3-64 of ``meta.json``; ``meta.json`` holds, under
``checksums``, the XXH3-64 of each array's data and of each ``.npy`` file's
header. A loader checks them all, and also that each header gives the
format's dtype and the shape ``meta.json``'s dimensions imply, and that each
file ends where its data end. A trace that lacks any of these digests (one
written before they existed, or one whose digest was deleted) is refused with
the command that writes a verified one: nothing is skipped.

The rules of the arrays hold for a trace built in memory as well (checked by
compiled passes, once per trace):

- ``pixel_offsets``: shape (P + 1,) int64, rising from 0 to the record count;
- ``records``: shape (R,) uint32, each of a known kind with an index below
  that kind's record count (``metadata["record_counts"]``, when given);
- ``counters``: shape (P, K) int64, none negative.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xxhash
from numba import njit

from rtcommon.files import read_npy_header
from rtcommon.resident import drop_pages, mapping_of
from rtcommon.validate import InputError, require_int
from tracer.trace.segments import SEGMENT_DTYPES
from tracer.trace.records import (COUNTER_NAMES, INDEX_MASK, READABLE_VERSIONS, KIND_SHIFT, N_KINDS, RecordKind,
                                  record_id, record_kind)

#: The hash recorded for each array and header in ``meta.json`` (xxHash's XXH3, 64 bits).
CHECKSUM_ALGORITHM = "xxh3_64"
#: The arrays of a trace, each in ``<name>.npy``, with the dtype the format stores.
DTYPES = {"pixel_offsets": np.dtype("<i8"), "records": np.dtype("<u4"), "counters": np.dtype("<i8")}
#: The files of a saved trace folder: its record (what was rendered, and the checksums) ...
META_FILE = "meta.json"
#: ... each array's file, by array name ...
ARRAY_FILES = {name: f"{name}.npy" for name in DTYPES}
#: ... every array a trace may hold, with the per-ray segments of a version-4 trace ...
ALL_DTYPES = {**DTYPES, **SEGMENT_DTYPES}
#: ... and the XXH3-64 of the record's bytes, beside it.
META_CHECKSUM = META_FILE + ".xxh3"
CHUNK = 1 << 22  # records per step of a streamed pass (16 MB)


class TraceIntegrityError(InputError):
    """A trace's files are damaged or unverifiable, or its arrays break the format's rules.

    ``detail`` is the message without the trace's name (what a cache's
    warning shows).
    """

    def __init__(self, message: str, detail: str | None = None):
        super().__init__(message)
        self.detail = message if detail is None else detail


def _refuse(where: str, detail: str, hint: str = "") -> TraceIntegrityError:
    return TraceIntegrityError(f"{where}: {detail}{hint}", detail)


def write_with_checksum(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path``, and its XXH3-64 (16 hex digits and a newline) to ``<path>.xxh3`` beside it.

    Beside the file rather than inside it, so that the file stays a plain,
    comparable record (a trace's ``meta.json``, a trace cache entry's
    ``render.json``).
    """
    path.write_bytes(data)
    path.with_name(path.name + ".xxh3").write_text(xxhash.xxh3_64_hexdigest(data) + "\n", encoding="ascii")


def matches_checksum(path: Path, data: bytes) -> bool | None:
    """Whether ``data``, the bytes read from ``path``, match the checksum in ``<path>.xxh3``.

    None when there is no such file (missing, or a folder in its place).
    """
    try:
        recorded = path.with_name(path.name + ".xxh3").read_text(encoding="ascii", errors="replace")
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None
    return recorded.strip() == xxhash.xxh3_64_hexdigest(data)


def array_checksum(array: np.ndarray) -> str:
    """XXH3-64 of an array's bytes in C order, as 16 hex digits (streamed in chunks; the pages of a
    memory-mapped array leave the resident set as they are hashed)."""
    hasher = xxhash.xxh3_64()
    flat = array.reshape(-1) if array.flags.c_contiguous else np.ascontiguousarray(array).reshape(-1)
    mapped = mapping_of(array)
    step = CHUNK * 4 // max(flat.itemsize, 1)
    for a in range(0, flat.size, step):
        if mapped is not None:
            drop_pages(mapped)
        hasher.update(np.ascontiguousarray(flat[a:a + step]))
    return hasher.hexdigest()


# ------------------------------------------------------------ the arrays' rules
def check_layout(arrays: dict, width, height, metadata) -> tuple[int, int]:
    """Types, dtypes and shapes of a trace's arrays; returns ``(width, height)`` as ints.

    Parameters
    ----------
    arrays : dict
        ``pixel_offsets``, ``records`` and ``counters`` (see :data:`DTYPES`).
    width, height : int
        Image size in samples, each >= 1.
    metadata : dict

    Raises
    ------
    ValueError
        Naming the ``AccessTrace`` field and what it must be.
    """
    width = require_int("AccessTrace.width", width, 1)
    height = require_int("AccessTrace.height", height, 1)
    if not isinstance(metadata, dict):
        raise InputError(f"AccessTrace.metadata must be a dict, got {type(metadata).__name__}")
    for name, dtype in DTYPES.items():
        array = arrays[name]
        if not isinstance(array, np.ndarray):
            raise InputError(f"AccessTrace.{name} must be a numpy array, got {type(array).__name__}")
        if array.dtype != dtype:
            raise InputError(f"AccessTrace.{name} must have dtype {dtype.name}, got {array.dtype}")
    p = width * height
    for name, shape in (("pixel_offsets", (p + 1,)), ("counters", (p, len(COUNTER_NAMES)))):
        if arrays[name].shape != shape:
            raise InputError(f"AccessTrace.{name} must have shape {shape}, got {arrays[name].shape}")
    if arrays["records"].ndim != 1:
        raise InputError(f"AccessTrace.records must have shape (R,), got {arrays['records'].shape}")
    return width, height


def check_values(trace, checksums: dict | None, where: str, files: bool = False) -> None:
    """The offsets', counters' and records' rules, with each array's hash when ``checksums`` is given.

    One streamed pass per array (the pages of memory-mapped ones leave the
    resident set as they are checked). With ``checksums``, a hash mismatch
    is reported before a broken rule of the same array: the file is damaged.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Its layout already checked (:func:`check_layout`).
    checksums : dict or None
        ``meta.json``'s ``checksums``: hex digests by array name.
    where : str
        How messages name the trace.
    files : bool
        Messages name the arrays' files (``records.npy``) rather than fields.

    Raises
    ------
    TraceIntegrityError
    """
    label = ARRAY_FILES.__getitem__ if files else (lambda name: name)
    wanted = (lambda name: None) if checksums is None else checksums.get
    offsets = np.asarray(trace.pixel_offsets)
    if wanted("pixel_offsets") is not None and array_checksum(offsets) != wanted("pixel_offsets"):
        raise _refuse(where, f"{label('pixel_offsets')} does not match its checksum (file damaged)")
    ends = int(offsets[0]), int(offsets[-1])
    if ends != (0, trace.n_records):
        raise _refuse(where, f"{label('pixel_offsets')} must run from 0 to the record count {trace.n_records}, "
                             f"got {ends[0]} to {ends[1]}")
    fall = _first_fall(offsets)
    if fall >= 0:
        raise _refuse(where, f"{label('pixel_offsets')} must rise from 0 to the record count; entry {fall + 1} "
                             f"({int(offsets[fall + 1])}) is below entry {fall} ({int(offsets[fall])})")
    _check_counters(trace.counters, wanted("counters"), where, label("counters"))
    _check_records(trace, wanted("records"), where, label("records"))


def _check_counters(counters: np.ndarray, checksum: str | None, where: str, label: str) -> None:
    mapped = mapping_of(counters)
    hasher = xxhash.xxh3_64()
    negative = -1
    step = max(1, CHUNK // max(counters.shape[1], 1))
    for a in range(0, counters.shape[0], step):
        piece = np.ascontiguousarray(counters[a:a + step])
        if mapped is not None:  # checked: out of the resident set until they are read again
            drop_pages(mapped)
        if checksum is not None:
            hasher.update(piece)
        if negative < 0:
            bad = _first_negative(piece.reshape(-1))
            if bad >= 0:
                negative = a * counters.shape[1] + bad
                if checksum is None:
                    break
    if checksum is not None and hasher.hexdigest() != checksum:
        raise _refuse(where, f"{label} does not match its checksum (file damaged)")
    if negative >= 0:
        pixel, column = divmod(negative, counters.shape[1])
        raise _refuse(where, f"{label} must not be negative; pixel {pixel}'s {COUNTER_NAMES[column]} is "
                             f"{int(counters[pixel, column])}")


def _check_records(trace, checksum: str | None, where: str, label: str) -> None:
    limits = index_limits(trace.metadata)
    hasher = xxhash.xxh3_64()
    records = trace.records
    mapped = mapping_of(records)
    first_bad = None
    for a in range(0, trace.n_records, CHUNK):
        piece = np.ascontiguousarray(records[a:a + CHUNK])
        if mapped is not None:  # checked pages leave the resident set: a long trace never sits in it whole
            drop_pages(mapped)
        if checksum is not None:
            hasher.update(piece)
        if first_bad is None:
            bad = first_record_out_of_range(piece, limits)
            if bad >= 0:
                first_bad = (a + bad, int(piece[bad]))
                if checksum is None:
                    break
    # a damaged file is reported as such, not as its first symptom
    if checksum is not None and hasher.hexdigest() != checksum:
        raise _refuse(where, f"{label} does not match its checksum (file damaged)")
    if first_bad is not None:
        position, record = first_bad
        kind, index = record >> KIND_SHIFT, record & INDEX_MASK
        what = RecordKind(kind).name.lower() if kind < N_KINDS else f"unknown kind {kind}"
        raise _refuse(where, f"{label}: record {position} reads {what} {index}, "
                             f"beyond the {int(limits[kind])} records the scene holds")


@njit(cache=True, nogil=True)
def _first_fall(offsets):
    """Position ``i`` of the first ``offsets[i + 1] < offsets[i]``, or -1.

    Parameters
    ----------
    offsets : ndarray of int64, shape (N,)
    """
    for i in range(offsets.shape[0] - 1):
        if offsets[i + 1] < offsets[i]:
            return i
    return -1


@njit(cache=True, nogil=True)
def _first_negative(values):
    """Position of the first negative entry of ``values`` (shape (N,) int64), or -1."""
    for i in range(values.shape[0]):
        if values[i] < 0:
            return i
    return -1


@njit(cache=True, nogil=True)
def first_record_out_of_range(records, index_limits):
    """Position of the first record whose index is not below its kind's limit, or -1.

    Parameters
    ----------
    records : ndarray of uint32, shape (N,)
    index_limits : ndarray of int64, shape (16,)
        One past the largest valid index of each kind (0: no such kind).
    """
    for position in range(records.shape[0]):
        record = records[position]
        if record_id(record) >= index_limits[record_kind(record)]:
            return position
    return -1


def index_limits(metadata: dict) -> np.ndarray:
    """Per kind (16 slots), one past the largest valid record index; 0 for kinds that do not exist."""
    limits = np.zeros(1 << (32 - KIND_SHIFT), dtype=np.int64)
    counts = metadata.get("record_counts") or {}
    for kind in RecordKind:
        count = counts.get(kind.name.lower())
        if count is not None:
            count = require_int(f"metadata['record_counts'][{kind.name.lower()!r}]", count, 0)
        limits[kind] = INDEX_MASK + 1 if count is None else min(count, INDEX_MASK + 1)
    return limits


# ------------------------------------------------------------------- the files
def rerender_hint(directory: Path, meta: dict | None) -> str:
    """``; re-render it with `coherence render SCENE --size N --trace DIR``, filled in from what ``meta``
    tells (scene, size, a workload other than the default, corner rays)."""
    metadata = meta.get("metadata") if isinstance(meta, dict) else None
    metadata = metadata if isinstance(metadata, dict) else {}
    scene = metadata.get("scene") if isinstance(metadata.get("scene"), str) else "SCENE"
    size = metadata.get("image_size")
    size = size[0] if isinstance(size, list) and len(size) == 2 and size[0] == size[1] else "N"
    options = ""
    workload = metadata.get("workload")
    if isinstance(workload, dict) and isinstance(workload.get("name"), str) and workload["name"] != "modern":
        options += f" --workload {workload['name']}"
    if metadata.get("corner_rays") is True:
        options += " --corner-rays"
    return f"; re-render it with `coherence render {scene} --size {size}{options} --trace {directory}`"


def read_meta(directory: Path) -> dict:
    """``meta.json``, verified against ``meta.json.xxh3``, with every checksum the loader needs.

    Raises
    ------
    TraceIntegrityError
        A digest or checksum missing (with the command that re-renders the
        trace), a mismatch, unreadable JSON or another format version.
    """
    where = f"trace {str(directory)!r}"
    data = (directory / META_FILE).read_bytes()
    try:
        meta = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        meta = error
    matches = matches_checksum(directory / META_FILE, data)
    if matches is None:
        raise _refuse(where, f"{META_CHECKSUM} (the checksum of meta.json) is missing, so the trace cannot be "
                             "verified", rerender_hint(directory, meta))
    if not matches:
        raise _refuse(where, "meta.json does not match its checksum (file damaged)")
    if isinstance(meta, Exception):
        raise _refuse(where, f"meta.json is damaged ({meta})")
    if not isinstance(meta, dict):
        raise _refuse(where, "meta.json is damaged (not an object)")
    if meta.get("format_version") not in READABLE_VERSIONS:
        raise _refuse(where, f"unsupported format_version {meta.get('format_version')!r} (this code reads "
                             f"{', '.join(map(str, READABLE_VERSIONS))})")
    checksums = meta.get("checksums") if isinstance(meta.get("checksums"), dict) else {}
    headers = checksums.get("headers") if isinstance(checksums.get("headers"), dict) else {}
    missing = [ARRAY_FILES[name] for name in DTYPES if not isinstance(checksums.get(name), str)]
    missing += [f"{ARRAY_FILES[name]}'s header" for name in DTYPES if not isinstance(headers.get(name), str)]
    if missing:
        what = "checksums" if len(missing) == 2 * len(DTYPES) else f"checksum of {', '.join(missing)}"
        raise _refuse(where, f"meta.json holds no {what}, so the trace cannot be verified",
                      rerender_hint(directory, meta))
    if checksums.get("algorithm") != CHECKSUM_ALGORITHM:
        raise _refuse(where, f"unknown checksum algorithm {checksums.get('algorithm')!r} in meta.json")
    return meta


def dimensions(meta: dict, where: str) -> dict:
    """The shape of each array that ``meta.json``'s dimensions imply, after cross-checking them.

    ``width`` and ``height`` must be positive integers; ``n_records`` a
    non-negative one; the counter names this version's; the render's own
    record of its size (``metadata`` ``width``, ``height`` and
    ``image_size``, one more per side with ``corner_rays``), where present,
    must agree.

    Returns
    -------
    dict
        Array name -> shape tuple.
    """
    values = {}
    for name, minimum in (("width", 1), ("height", 1), ("n_records", 0)):
        value = meta.get(name)
        if not isinstance(value, int) or isinstance(value, bool) or value < minimum:
            raise _refuse(where, f"meta.json: {name} must be an integer >= {minimum}, got {value!r}")
        values[name] = value
    width, height = values["width"], values["height"]
    if meta.get("counter_names") != list(COUNTER_NAMES):
        raise _refuse(where, "meta.json: counter_names are not this version's counters")
    metadata = meta.get("metadata", {})
    if not isinstance(metadata, dict):
        raise _refuse(where, "meta.json: metadata is not an object")
    recorded = (metadata.get("width", width), metadata.get("height", height))
    image_size = metadata.get("image_size")
    if image_size is not None:
        corner = int(bool(metadata.get("corner_rays")))
        if not (isinstance(image_size, list) and len(image_size) == 2 and all(isinstance(v, int) for v in image_size)):
            raise _refuse(where, f"meta.json: image_size must be [width, height], got {image_size!r}")
        recorded += (image_size[0] + corner, image_size[1] + corner)
    if any(value != dimension for value, dimension in zip(recorded, (width, height) * 2)):
        raise _refuse(where, f"meta.json: width x height = {width}x{height} disagrees with the render's record of "
                             f"its size (width {metadata.get('width')}, height {metadata.get('height')}, "
                             f"image_size {image_size})")
    p = width * height
    return {"pixel_offsets": (p + 1,), "records": (values["n_records"],), "counters": (p, len(COUNTER_NAMES))}


def header_checksums(folder: Path) -> dict:
    """XXH3-64 of each array file's ``.npy`` header in ``folder``, by array name."""
    return {name: xxhash.xxh3_64_hexdigest(read_npy_header(folder / ARRAY_FILES[name]).raw) for name in DTYPES}


def load_array(directory: Path, name: str, shape: tuple, checksums: dict, mmap: bool) -> np.ndarray:
    """``<name>.npy`` after its header is checked: its digest, the format's dtype, ``shape``, C order, and a
    file that ends where the data end. The data are checked later (:func:`check_values`).

    Raises
    ------
    TraceIntegrityError
        Naming the trace and the file.
    """
    where = f"trace {str(directory)!r}"
    path = directory / f"{name}.npy"
    try:
        header = read_npy_header(path)
    except (ValueError, OSError) as error:
        raise _refuse(where, f"{name}.npy is damaged ({error})") from None
    if xxhash.xxh3_64_hexdigest(header.raw) != checksums["headers"][name]:
        raise _refuse(where, f"{name}.npy's header does not match its checksum (file damaged)")
    dtype = ALL_DTYPES[name]
    if header.dtype != dtype or header.fortran_order or header.shape != shape:
        found = f"{header.dtype.str}{' Fortran-order' if header.fortran_order else ''} {header.shape}"
        raise _refuse(where, f"{name}.npy holds {found}, expected {dtype.str} {shape} from meta.json")
    size = len(header.raw) + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if path.stat().st_size != size:
        raise _refuse(where, f"{name}.npy has {path.stat().st_size} bytes, expected {size} (file damaged)")
    try:
        return np.load(path, mmap_mode="r" if mmap else None, allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise _refuse(where, f"{name}.npy is damaged ({error})") from None
