"""Keep the pages of memory-mapped files that a process holds under a limit.

A trace is read through a memory map, and every page a replay touches stays
in the process's resident set while the map is open: a replay that walks a
4 GB trace holds 4 GB. The pages are clean copies of the file, so dropping
them loses nothing; the next read of one faults it back in from the page
cache or the disk. :class:`ResidentLimit` runs a thread that, while compiled
code reads the maps, checks the process's file-backed resident memory
(``RssFile`` of ``/proc/self/status``) a few times a second and, above the
limit, tells the kernel the mapped pages are not needed
(``madvise(MADV_DONTNEED)``). Where either is missing (not Linux) it does
nothing and says so in :attr:`ResidentLimit.active`.
"""
from __future__ import annotations

import mmap
import threading
from pathlib import Path

from rtcommon.validate import InputError, require_int

_STATUS = Path("/proc/self/status")


def mapping_of(array) -> mmap.mmap | None:
    """The memory map an array (or a view of one) reads, or None if it reads ordinary memory."""
    seen = 0
    while array is not None and seen < 64:
        if isinstance(array, mmap.mmap):
            return array
        inner = getattr(array, "_mmap", None)  # numpy.memmap keeps its map here
        if isinstance(inner, mmap.mmap):
            return inner
        array = getattr(array, "base", None)
        seen += 1
    return None


def drop_pages(mapped: mmap.mmap) -> None:
    """Tell the kernel the pages of ``mapped`` are not needed now (a read faults them back in)."""
    if hasattr(mmap, "MADV_DONTNEED"):
        try:
            mapped.madvise(mmap.MADV_DONTNEED)
        except (OSError, ValueError):  # closed meanwhile, or not allowed here: nothing to drop
            pass


def resident_file_bytes() -> int | None:
    """Bytes of file-backed pages in this process's resident set (``RssFile``), or None where unknown."""
    try:
        text = _STATUS.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("RssFile:"):
            return int(line.split()[1]) * 1024
    return None


class ResidentLimit:
    """While open, drop the resident pages of the maps behind ``arrays`` whenever the process's
    file-backed resident memory exceeds ``max_bytes``.

    Parameters
    ----------
    arrays : sequence of ndarray
        Arrays read through memory maps (others are ignored).
    max_bytes : int
        Limit on ``RssFile`` (which also counts the process's shared
        libraries, about 100 MB for this toolkit).
    interval : float
        Seconds between checks.

    Attributes
    ----------
    active : bool
        Whether it can work here (a map to trim, ``RssFile`` readable and
        ``madvise`` available).
    trims : int
        How many times the pages were dropped.
    """

    def __init__(self, arrays, max_bytes: int, interval: float = 0.2):
        max_bytes = require_int("max_bytes", max_bytes, 0)
        if not interval > 0:
            raise InputError(f"interval must be > 0 seconds, got {interval!r}")
        maps = []
        for array in arrays:
            found = mapping_of(array)
            if found is not None and all(found is not m for m in maps):
                maps.append(found)
        self.max_bytes = max_bytes
        self.interval = float(interval)
        self._maps = maps
        self.active = bool(maps) and hasattr(mmap, "MADV_DONTNEED") and resident_file_bytes() is not None
        self.trims = 0
        self._stop = threading.Event()
        self._thread = None

    def trim(self) -> bool:
        """Drop the maps' pages now if ``RssFile`` is over the limit; returns whether it did."""
        if not self.active:
            return False
        resident = resident_file_bytes()
        if resident is None or resident <= self.max_bytes:
            return False
        for mapped in self._maps:
            drop_pages(mapped)
        self.trims += 1
        return True

    def _watch(self):
        while not self._stop.wait(self.interval):
            self.trim()

    def __enter__(self) -> "ResidentLimit":
        if self.active:
            self._thread = threading.Thread(target=self._watch, name="resident-limit", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
