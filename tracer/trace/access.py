"""Per-pixel access logs: record packing, counters and :class:`AccessTrace`.

A *record* is one read of one scene record, packed into a uint32 as
described in :mod:`tracer.trace.records` (4-bit kind, write flag, 27-bit index):

=============  ===============================================================
KD_NODE        kd-tree node ``index`` (row of ``KdTree.nodes``), each visit;
               a ray that misses the scene box still reads the root (0)
INDEX_ENTRY    entry ``index`` of ``KdTree.primitive_indices`` read in a leaf
SPHERE ...     primitive tested; ``index`` is the row in *that kind's* arrays
CONE           (``Scene.element_index``), not the element id
MATERIAL       material row read to shade a hit
LIGHT          light row read while shading (once per light per hit)
=============  ===============================================================

In a leaf, each entry read is followed by the test of the primitive it names;
a ray reads the nodes it visits in traversal order; shading reads the
material, then per light the light record, then that light's shadow ray
records. Rays of one pixel appear in depth-first (recursive Whitted) order.
"""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import xxhash

from rtcommon.files import make_temp_dir, read_npy_header, remove_stale_temporaries, temp_prefix
from rtcommon.resident import drop_pages, mapping_of
from rtcommon.jsonio import json_default
from tracer.trace.records import (  # noqa: F401  (re-exported: the format's names)
    COUNTER_NAMES, COUNTER_OF_KIND, FORMAT_VERSION, INDEX_MASK, PLAIN_FORMAT_VERSION, KIND_SHIFT, N_COUNTERS, N_KINDS,
    Counter, RecordKind, pack, record_id, record_kind, unpack,
)
from tracer.trace.check import (  # noqa: F401  (re-exported: TraceIntegrityError, array_checksum)
    ARRAY_FILES, CHECKSUM_ALGORITHM, CHUNK as _CHUNK, DTYPES, META_FILE,
    TraceIntegrityError, array_checksum, check_layout, check_values, dimensions, header_checksums, load_array, read_meta,
    write_with_checksum,
)
from tracer.trace.segments import SEGMENT_DTYPES, RaySegments, check_segments
from rtcommon.validate import InputError

_ARRAYS = tuple(DTYPES)
#: Arrays a loaded trace reads through a memory map (mmap=True): the two that grow with it. The records
#: grow with the trace's length, the counters with the image (200 bytes a pixel).
_MAPPED = ("records", "counters")


@dataclass(eq=False)
class AccessTrace:
    """Ordered per-pixel access logs of one render, CSR style.

    Constructed in memory, a trace is checked as :meth:`load` checks one
    (hashes aside): dtypes and shapes, offsets rising from 0 to the record
    count, counters not negative, every record of a known kind with an index
    below its kind's ``metadata["record_counts"]`` (where given); a
    ValueError names the first rule broken.

    Attributes
    ----------
    pixel_offsets : ndarray, shape (P + 1,) int64
        Records of pixel ``p`` (row-major, ``p = y * width + x``, top row
        first) are ``records[pixel_offsets[p]:pixel_offsets[p + 1]]``.
    records : ndarray, shape (R,) uint32
        Packed records (see module docstring); may be a read-only memmap.
        ``pixel_offsets`` and ``records`` are stored as read-only views.
    counters : ndarray, shape (P, K) int64
        Per-pixel counters, columns :data:`COUNTER_NAMES`; a read-only
        memmap when loaded with ``mmap=True``.
    width, height : int
        At least 1 each; P = width * height.
    metadata : dict
        JSON-serialisable: scene, resolution, tree config and stats, render
        options, package versions.
    segments : RaySegments or None
        The per-ray segments of a path-traced trace (:mod:`tracer.trace.segments`):
        they must tile the records pixel by pixel. A trace with segments is
        saved as format version 4, one without as version 3.
    """

    pixel_offsets: np.ndarray
    records: np.ndarray
    counters: np.ndarray
    width: int
    height: int
    metadata: dict = field(default_factory=dict)
    segments: RaySegments | None = None

    def __post_init__(self):
        self._check_layout()
        check_values(self, None, "AccessTrace")
        if self.segments is not None:
            check_segments(self.segments, np.asarray(self.pixel_offsets), self.n_records)

    @classmethod
    def _checked_by_caller(cls, arrays: dict, width: int, height: int, metadata: dict) -> "AccessTrace":
        """A trace whose values the caller checks itself (:meth:`load`, in the pass that hashes them)."""
        trace = cls.__new__(cls)
        trace.pixel_offsets, trace.records, trace.counters = (arrays[name] for name in _ARRAYS)
        trace.width, trace.height, trace.metadata = width, height, metadata
        trace.segments = None
        trace._check_layout()
        return trace

    def _check_layout(self) -> None:
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        self.width, self.height = check_layout(arrays, self.width, self.height, self.metadata)
        # Kept as read-only views, whether loaded (a read-only memmap) or just rendered: numba
        # compiles a kernel once per array type, and writeable and read-only arrays are two types.
        for name in ("pixel_offsets", "records"):
            view = getattr(self, name).view()
            view.flags.writeable = False
            setattr(self, name, view)

    @property
    def n_pixels(self) -> int:
        return int(self.width) * int(self.height)

    @property
    def n_records(self) -> int:
        return int(self.records.shape[0])

    def pixel(self, p: int) -> np.ndarray:
        """Records of pixel ``p``, shape (n,) uint32."""
        return self.records[self.pixel_offsets[p]:self.pixel_offsets[p + 1]]

    def counter(self, name: str) -> np.ndarray:
        """Column ``name`` of :attr:`counters` as an (H, W) image."""
        try:
            col = COUNTER_NAMES.index(name)
        except ValueError:
            raise InputError(f"unknown counter {name!r}; one of {COUNTER_NAMES}") from None
        return self.counters[:, col].reshape(self.height, self.width)

    def totals(self) -> dict:
        """Sum of every counter over all pixels, plus ``records``."""
        sums = column_sums(self.counters)
        out = {name: int(v) for name, v in zip(COUNTER_NAMES, sums)}
        out["records"] = self.n_records
        return out

    def kind_counts(self, chunk: int = 1 << 24) -> dict:
        """Number of records of each kind (read in chunks; works on memmaps)."""
        counts = np.zeros(16, dtype=np.int64)
        for a in range(0, self.n_records, chunk):
            counts += np.bincount(np.asarray(self.records[a:a + chunk]) >> KIND_SHIFT, minlength=16)
        return {k: int(counts[k]) for k in RecordKind}

    # ------------------------------------------------------------------ I/O
    def save(self, directory) -> Path:
        """Write the trace to ``directory`` atomically.

        Files: ``pixel_offsets.npy``, ``records.npy``, ``counters.npy``,
        ``meta.json`` (which holds a checksum of each array's data and of
        each ``.npy`` header) and ``meta.json.xxh3`` (the checksum of
        ``meta.json``). They are
        written to a temporary sibling directory that is renamed into place,
        so a reader never sees a half-written trace. Records are copied in
        chunks (a memmapped trace is not loaded).

        Returns
        -------
        pathlib.Path
        """
        directory = Path(directory)
        tmp = _temp_sibling(directory)
        try:
            checksums = {}
            for name, array in (("pixel_offsets", self.pixel_offsets), ("counters", self.counters)):
                array = np.ascontiguousarray(array, dtype=np.int64)
                np.save(tmp / ARRAY_FILES[name], array)
                checksums[name] = array_checksum(array)
            out = np.lib.format.open_memmap(tmp / ARRAY_FILES["records"], mode="w+", dtype=np.uint32,
                                            shape=(self.n_records,))
            hasher = xxhash.xxh3_64()
            for a in range(0, self.n_records, _CHUNK):
                piece = np.ascontiguousarray(self.records[a:a + _CHUNK], dtype=np.uint32)
                out[a:a + _CHUNK] = piece
                hasher.update(piece)
            out.flush()
            del out
            checksums["records"] = hasher.hexdigest()
            if self.segments is not None:
                _save_segments(tmp, self.segments, checksums)
            _write_meta(tmp, self.width, self.height, self.n_records, self.metadata, checksums)
            _publish(tmp, directory)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return directory

    @classmethod
    def load(cls, directory, *, mmap: bool = True) -> "AccessTrace":
        """Read a trace written by :meth:`save`, checking every byte (records and counters memory-mapped by
        default).

        ``meta.json`` must match ``meta.json.xxh3``; each ``.npy`` header
        must match its checksum in ``meta.json`` and give the format's dtype
        and the shape that ``meta.json``'s width, height and record count
        imply (which must agree with the render's own record of its image
        size); each array's data must match its checksum. Then the offsets
        must rise from 0 to the record count, no counter may be negative, and
        every record must name a known kind and an index below that kind's
        record count (``metadata["record_counts"]``, the scene's and tree's
        sizes), so no later kernel can index out of range. A trace without
        these checksums (written before they existed) is refused: the
        message gives the command that writes it again.

        Raises
        ------
        FileNotFoundError
            If the directory or one of its files is missing.
        TraceIntegrityError
            (a ValueError) If a file is damaged or the files are inconsistent;
            the message names the trace and the file.
        """
        directory = Path(directory)
        if not directory.is_dir():
            if directory.exists():
                raise NotADirectoryError(f"trace {str(directory)!r} is a file, not a trace folder")
            raise FileNotFoundError(f"no such trace directory: {str(directory)!r}")
        for name in (META_FILE, *ARRAY_FILES.values()):
            if not (directory / name).is_file():
                raise FileNotFoundError(f"trace {str(directory)!r} lacks {name}")
        meta = read_meta(directory)
        where = f"trace {str(directory)!r}"
        shapes = dimensions(meta, where)
        arrays = {name: load_array(directory, name, shapes[name], meta["checksums"], mmap and name in _MAPPED)
                  for name in _ARRAYS}
        try:
            trace = cls._checked_by_caller(arrays, meta["width"], meta["height"], meta.get("metadata", {}))
        except ValueError as error:
            raise TraceIntegrityError(f"{where}: inconsistent files ({error})", str(error)) from None
        check_values(trace, meta["checksums"], where, files=True)
        if "n_segments" in meta:
            trace.segments = _load_segments(directory, meta, where, mmap)
            try:
                check_segments(trace.segments, np.asarray(trace.pixel_offsets), trace.n_records)
            except ValueError as error:
                raise TraceIntegrityError(f"{where}: inconsistent files ({error})", str(error)) from None
        return trace


def _save_segments(folder: Path, segments: RaySegments, checksums: dict) -> None:
    """Write the segment arrays into ``folder``, adding their checksums (data and header) to ``checksums``."""
    headers = checksums.setdefault("segment_headers", {})
    for name, array in segments.arrays().items():
        array = np.ascontiguousarray(array, dtype=SEGMENT_DTYPES[name])
        np.save(folder / f"{name}.npy", array)
        checksums[name] = array_checksum(array)
        headers[name] = xxhash.xxh3_64_hexdigest(read_npy_header(folder / f"{name}.npy").raw)


def _load_segments(directory: Path, meta: dict, where: str, mmap: bool) -> RaySegments:
    """The segment arrays of a version-4 trace, each checked against its checksums in ``meta.json``."""
    n = meta["n_segments"]
    checksums = meta["checksums"]
    headers = checksums.get("segment_headers")
    if meta.get("format_version") != FORMAT_VERSION or not isinstance(n, int) or isinstance(n, bool) or n < 0 \
            or not isinstance(headers, dict) \
            or not all(isinstance(checksums.get(k), str) and isinstance(headers.get(k), str) for k in SEGMENT_DTYPES):
        raise TraceIntegrityError(f"{where}: meta.json's segments need format_version {FORMAT_VERSION}, an "
                                  "integer n_segments >= 0 and a checksum of each segment file and header")
    arrays = {}
    widths = {"segment_ints": 6, "segment_rays": 9}
    for name in SEGMENT_DTYPES:
        if not (directory / f"{name}.npy").is_file():
            raise FileNotFoundError(f"trace {str(directory)!r} lacks {name}.npy")
        array = load_array(directory, name, (n, widths[name]), {"headers": headers}, mmap=False)
        if array_checksum(array) != checksums[name]:
            raise TraceIntegrityError(f"{where}: {name}.npy does not match its checksum (file damaged)")
        arrays[name] = array
    return RaySegments(arrays["segment_ints"], arrays["segment_rays"])


def column_sums(counters: np.ndarray) -> np.ndarray:
    """Sum of each column of a (P, K) counter array, read in row chunks (the pages of a memory-mapped
    array leave the resident set as they are summed). Returns shape (K,) int64."""
    mapped = mapping_of(counters)
    sums = np.zeros(counters.shape[1], np.int64)
    step = max(1, _CHUNK // max(counters.shape[1], 1))
    for a in range(0, counters.shape[0], step):
        if mapped is not None:
            drop_pages(mapped)
        sums += counters[a:a + step].sum(axis=0, dtype=np.int64)
    return sums


def verify_trace(trace: AccessTrace, checksums: dict | None = None, *, where: str = "trace") -> None:
    """Check a trace's arrays against their checksums and the format's rules, in one pass over each array.

    Parameters
    ----------
    trace : AccessTrace
    checksums : dict, optional
        ``{"algorithm": "xxh3_64", "pixel_offsets": hex, "records": hex,
        "counters": hex, ...}`` as stored in ``meta.json``; None checks the
        rules only (what constructing the trace checked already).
    where : str
        How messages name the trace.

    Raises
    ------
    TraceIntegrityError
        Naming the first rule broken: a checksum, the offsets, a negative
        counter, a record's kind or index.
    """
    if checksums is not None and (not isinstance(checksums, dict) or
                                  checksums.get("algorithm") != CHECKSUM_ALGORITHM or
                                  not all(isinstance(checksums.get(name), str) for name in _ARRAYS)):
        raise TraceIntegrityError(f"{where}: checksums must give an {CHECKSUM_ALGORITHM} digest of each of "
                                  f"{', '.join(_ARRAYS)}")
    check_values(trace, checksums, where)


def _temp_sibling(directory: Path) -> Path:
    # Runs that died (SIGKILL, power cut) leave their temporaries: clear them first.
    if directory.parent.is_dir():
        remove_stale_temporaries(directory.parent)
    return make_temp_dir(directory)


def _write_meta(tmp: Path, width: int, height: int, n_records: int, metadata: dict, checksums: dict) -> None:
    # version 4 only where its additions are used: a trace without segments stays version 3, byte for byte
    segments = "segment_ints" in checksums
    meta = {"format_version": FORMAT_VERSION if segments else PLAIN_FORMAT_VERSION,
            "width": int(width), "height": int(height),
            "n_records": int(n_records), "record_kinds": {k.name: int(k) for k in RecordKind},
            "counter_names": list(COUNTER_NAMES), "metadata": metadata,
            "checksums": {"algorithm": CHECKSUM_ALGORITHM, **checksums, "headers": header_checksums(tmp)}}
    if segments:
        meta["n_segments"] = int(np.load(tmp / "segment_ints.npy", mmap_mode="r").shape[0])
    data = json.dumps(meta, indent=1, default=json_default).encode("utf-8")
    write_with_checksum(tmp / META_FILE, data)


def _publish(tmp: Path, directory: Path) -> None:
    # Replace an existing trace: move it aside, rename the new one in, then
    # delete the old one, so the path holds a complete trace at every moment
    # except between the two renames.
    old = None
    if directory.exists():
        if not directory.is_dir():
            raise NotADirectoryError(f"{str(directory)!r} exists and is a file, not a trace directory; not overwriting")
        if not (directory / META_FILE).is_file() and any(directory.iterdir()):
            raise InputError(f"{str(directory)!r} exists and is not a trace directory; not overwriting")
        old = directory.with_name(f"{temp_prefix(directory.name)}old.tmp")
        os.replace(directory, old)
    os.replace(tmp, directory)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


class TraceWriter:
    """Writes a trace's records straight to disk as they are produced.

    Records arrive in sample order through :meth:`append` (their total is
    not known in advance); :meth:`finish` completes the ``records.npy``
    header, adds the other files and publishes the directory atomically. Use
    as a context manager: on error the temporary directory is removed.
    """

    def __init__(self, directory):
        self.directory = Path(directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise NotADirectoryError(f"{str(self.directory)!r} exists and is a file, not a trace directory; "
                                     "not overwriting")
        self.tmp = _temp_sibling(self.directory)
        self.n_records = 0
        self._hasher = xxhash.xxh3_64()
        self._file = open(self.tmp / ARRAY_FILES["records"], "wb")
        self._file.write(_npy_header(0))  # rewritten with the final length
        self._counters = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self.abort()
        return False

    def append(self, records) -> None:
        """Append records (uint32, in sample order)."""
        records = np.ascontiguousarray(records, dtype=np.uint32)
        self._file.write(memoryview(records).cast("B"))
        self._hasher.update(records)
        self.n_records += len(records)

    def counters_array(self, n_pixels: int, n_counters: int) -> np.ndarray:
        """A zeroed (``n_pixels``, ``n_counters``) int64 array mapped from the trace's ``counters.npy``.

        The render fills it in place and :meth:`release_counter_pages` lets
        the filled pages go, so a large image's counters (0.8 GB at 2048²)
        never sit in memory whole; :meth:`finish` then takes ``counters``
        None.
        """
        self._counters = np.lib.format.open_memmap(self.tmp / ARRAY_FILES["counters"], mode="w+", dtype=np.int64,
                                                   shape=(n_pixels, n_counters))
        return self._counters

    def release_counter_pages(self) -> None:
        """Write the counters filled so far to the file and drop their pages from memory."""
        if self._counters is not None:
            self._counters.flush()
            drop_pages(mapping_of(self._counters))

    def abort(self) -> None:
        if not self._file.closed:
            self._file.close()
        self._counters = None
        shutil.rmtree(self.tmp, ignore_errors=True)

    def finish(self, pixel_offsets, counters, width, height, metadata, *, mmap: bool = True) -> AccessTrace:
        """Write the remaining files, publish, and return the trace (memory-mapped by default).

        ``counters`` None: the array of :meth:`counters_array`, filled in
        place (drop other references to it first).
        """
        n = self.n_records
        if int(pixel_offsets[-1]) != n:
            raise InputError(f"pixel_offsets end at {int(pixel_offsets[-1])} but {n} records were written")
        self._file.seek(0)
        self._file.write(_npy_header(n))
        self._file.close()
        pixel_offsets = np.ascontiguousarray(pixel_offsets, dtype=np.int64)
        np.save(self.tmp / ARRAY_FILES["pixel_offsets"], pixel_offsets)
        if counters is None:  # filled in place (counters_array): already in its file
            if self._counters is None:
                raise InputError("finish: counters is None, but counters_array was never called")
            counters = self._counters
            self.release_counter_pages()
        else:
            counters = np.ascontiguousarray(counters, dtype=np.int64)
            np.save(self.tmp / ARRAY_FILES["counters"], counters)
        checksums = {"pixel_offsets": array_checksum(pixel_offsets), "records": self._hasher.hexdigest(),
                     "counters": array_checksum(counters)}
        del counters
        self._counters = None  # the map closes before the folder is renamed
        _write_meta(self.tmp, width, height, n, metadata, checksums)
        _publish(self.tmp, self.directory)
        return AccessTrace.load(self.directory, mmap=mmap)


def _npy_header(n_records: int) -> bytes:
    """A fixed-length (128-byte) ``.npy`` v1.0 header for ``n_records`` uint32."""
    text = "{'descr': '<u4', 'fortran_order': False, 'shape': (%d,), }" % n_records
    text = text.ljust(128 - 10 - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")
