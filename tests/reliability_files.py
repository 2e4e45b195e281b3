"""Files and paths the reliability tests (tests/test_reliability_*.py) share."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xxhash

from rtcommon.files import read_npy_header

ROOT = Path(__file__).resolve().parents[1]


def flip(path: Path, position_from_end: int) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) - position_from_end] ^= 0x04
    path.write_bytes(bytes(data))


def recorded_anew(folder: Path, meta_edit=None, **arrays) -> None:
    """Write ``arrays`` into the trace at ``folder`` and record every digest anew (``meta_edit`` changes
    meta.json first): a writer that hashes correctly what it wrongly wrote, so only the format's rules
    can catch it."""
    for name, array in arrays.items():
        np.save(folder / f"{name}.npy", array)
    meta = json.loads((folder / "meta.json").read_text())
    if meta_edit is not None:
        meta_edit(meta)
    for name in ("pixel_offsets", "records", "counters"):
        meta["checksums"][name] = xxhash.xxh3_64_hexdigest(np.load(folder / f"{name}.npy").tobytes())
        meta["checksums"]["headers"][name] = xxhash.xxh3_64_hexdigest(read_npy_header(folder / f"{name}.npy").raw)
    data = json.dumps(meta).encode()
    (folder / "meta.json").write_bytes(data)
    (folder / "meta.json.xxh3").write_text(xxhash.xxh3_64_hexdigest(data))


def png_header(width, height) -> bytes:
    """A PNG file's signature, header chunk and end: it opens and states its size, but holds no pixels."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) \
        + chunk(b"IEND", b"")
