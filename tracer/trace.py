"""Per-pixel access logs: record packing, counters and :class:`AccessTrace`.

A *record* is one read of one scene record, packed into a uint32 as
described in :mod:`tracer.records` (4-bit kind, write flag, 27-bit index):

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
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rtcommon.jsonio import json_default
from tracer.records import (  # noqa: F401  (re-exported: the format's names)
    COUNTER_NAMES, COUNTER_OF_KIND, FORMAT_VERSION, INDEX_MASK, KIND_SHIFT, N_COUNTERS, N_KINDS,
    Counter, RecordKind, pack, unpack,
)


def package_versions() -> dict:
    """Versions of the packages that decide a trace's content."""
    import numba
    import sys
    versions = {"python": sys.version.split()[0], "numpy": np.__version__, "numba": numba.__version__}
    try:
        from importlib.metadata import version
        versions["raytrace-coherence"] = version("raytrace-coherence")
    except Exception:  # pragma: no cover - not installed as a distribution
        versions["raytrace-coherence"] = "unknown"
    return versions


@dataclass(eq=False)
class AccessTrace:
    """Ordered per-pixel access logs of one render, CSR style.

    Attributes
    ----------
    pixel_offsets : ndarray, shape (P + 1,) int64
        Records of pixel ``p`` (row-major, ``p = y * width + x``, top row
        first) are ``records[pixel_offsets[p]:pixel_offsets[p + 1]]``.
    records : ndarray, shape (R,) uint32
        Packed records (see module docstring); may be a read-only memmap.
    counters : ndarray, shape (P, K) int64
        Per-pixel counters, columns :data:`COUNTER_NAMES`.
    width, height : int
    metadata : dict
        JSON-serialisable: scene, resolution, tree config and stats, render
        options, package versions.
    """

    pixel_offsets: np.ndarray
    records: np.ndarray
    counters: np.ndarray
    width: int
    height: int
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        p = int(self.width) * int(self.height)
        if self.pixel_offsets.shape != (p + 1,):
            raise ValueError(f"AccessTrace.pixel_offsets must have shape ({p + 1},), got {self.pixel_offsets.shape}")
        if self.counters.shape != (p, len(COUNTER_NAMES)):
            raise ValueError(f"AccessTrace.counters must have shape ({p}, {len(COUNTER_NAMES)}), got {self.counters.shape}")
        if self.records.ndim != 1 or self.records.dtype != np.uint32:
            raise ValueError("AccessTrace.records must be a 1-D uint32 array")
        if int(self.pixel_offsets[-1]) != len(self.records):
            raise ValueError("AccessTrace.pixel_offsets[-1] must equal len(records)")

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
            raise ValueError(f"unknown counter {name!r}; one of {COUNTER_NAMES}") from None
        return self.counters[:, col].reshape(self.height, self.width)

    def totals(self) -> dict:
        """Sum of every counter over all pixels, plus ``records``."""
        sums = self.counters.sum(axis=0)
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

        Files: ``pixel_offsets.npy``, ``records.npy``, ``counters.npy`` and
        ``meta.json``. They are written to a temporary sibling directory that
        is renamed into place, so a reader never sees a half-written trace.
        Records are copied in chunks (a memmapped trace is not loaded).

        Returns
        -------
        pathlib.Path
        """
        directory = Path(directory)
        tmp = _temp_sibling(directory)
        try:
            np.save(tmp / "pixel_offsets.npy", np.asarray(self.pixel_offsets, dtype=np.int64))
            np.save(tmp / "counters.npy", np.asarray(self.counters, dtype=np.int64))
            out = np.lib.format.open_memmap(tmp / "records.npy", mode="w+", dtype=np.uint32,
                                            shape=(self.n_records,))
            step = 1 << 24
            for a in range(0, self.n_records, step):
                out[a:a + step] = self.records[a:a + step]
            out.flush()
            del out
            _write_meta(tmp, self.width, self.height, self.n_records, self.metadata)
            _publish(tmp, directory)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return directory

    @classmethod
    def load(cls, directory, *, mmap: bool = True) -> "AccessTrace":
        """Read a trace written by :meth:`save` (records memory-mapped by default).

        Raises
        ------
        FileNotFoundError
            If the directory or one of its files is missing.
        ValueError
            If the files are inconsistent.
        """
        directory = Path(directory)
        if not directory.is_dir():
            raise FileNotFoundError(f"no such trace directory: {str(directory)!r}")
        for name in ("meta.json", "pixel_offsets.npy", "records.npy", "counters.npy"):
            if not (directory / name).is_file():
                raise FileNotFoundError(f"trace {str(directory)!r} lacks {name}")
        meta = json.loads((directory / "meta.json").read_text())
        if meta.get("format_version") != FORMAT_VERSION:
            raise ValueError(f"trace {str(directory)!r}: unsupported format_version {meta.get('format_version')!r}")
        records = np.load(directory / "records.npy", mmap_mode="r" if mmap else None)
        return cls(pixel_offsets=np.load(directory / "pixel_offsets.npy"),
                   records=records,
                   counters=np.load(directory / "counters.npy"),
                   width=int(meta["width"]), height=int(meta["height"]),
                   metadata=meta.get("metadata", {}))


def _temp_sibling(directory: Path) -> Path:
    directory.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f".{directory.name}.", suffix=".tmp", dir=directory.parent))


def _write_meta(tmp: Path, width: int, height: int, n_records: int, metadata: dict) -> None:
    meta = {"format_version": FORMAT_VERSION, "width": int(width), "height": int(height),
            "n_records": int(n_records), "record_kinds": {k.name: int(k) for k in RecordKind},
            "counter_names": list(COUNTER_NAMES), "metadata": metadata}
    (tmp / "meta.json").write_text(json.dumps(meta, indent=1, default=json_default))


def _publish(tmp: Path, directory: Path) -> None:
    # Replace an existing trace: move it aside, rename the new one in, then
    # delete the old one, so the path holds a complete trace at every moment
    # except between the two renames.
    old = None
    if directory.exists():
        if not (directory / "meta.json").is_file() and any(directory.iterdir()):
            raise ValueError(f"{str(directory)!r} exists and is not a trace directory; not overwriting")
        old = directory.with_name(f".{directory.name}.old-{os.getpid()}")
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
        self.tmp = _temp_sibling(self.directory)
        self.n_records = 0
        self._file = open(self.tmp / "records.npy", "wb")
        self._file.write(_npy_header(0))  # rewritten with the final length

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
        self.n_records += len(records)

    def abort(self) -> None:
        if not self._file.closed:
            self._file.close()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def finish(self, pixel_offsets, counters, width, height, metadata, *, mmap: bool = True) -> AccessTrace:
        """Write the remaining files, publish, and return the trace (memory-mapped by default)."""
        n = self.n_records
        if int(pixel_offsets[-1]) != n:
            raise ValueError(f"pixel_offsets end at {int(pixel_offsets[-1])} but {n} records were written")
        self._file.seek(0)
        self._file.write(_npy_header(n))
        self._file.close()
        np.save(self.tmp / "pixel_offsets.npy", np.asarray(pixel_offsets, dtype=np.int64))
        np.save(self.tmp / "counters.npy", np.asarray(counters, dtype=np.int64))
        _write_meta(self.tmp, width, height, n, metadata)
        _publish(self.tmp, self.directory)
        return AccessTrace.load(self.directory, mmap=mmap)


def _npy_header(n_records: int) -> bytes:
    """A fixed-length (128-byte) ``.npy`` v1.0 header for ``n_records`` uint32."""
    text = "{'descr': '<u4', 'fortran_order': False, 'shape': (%d,), }" % n_records
    text = text.ljust(128 - 10 - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")
