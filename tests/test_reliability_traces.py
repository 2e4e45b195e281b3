"""Reliability of saved traces: damaged or unverifiable files, and arrays that break the format's rules.

Checks the integrity of traces directly, and compares the checking kernels with
Python loops.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import xxhash

from tracer.trace.records import INDEX_MASK, KIND_SHIFT, RecordKind, pack
from tracer.trace.access import AccessTrace, TraceIntegrityError
from tracer.trace.check import _first_fall, _first_negative, first_record_out_of_range, index_limits
from trace_factory import random_trace
from reliability_files import flip, recorded_anew


# ----------------------------------------------------------------- trace files
def _saved(tmp_path, metadata=None):
    trace = random_trace(8, 6, seed=3)
    trace.metadata = metadata or {}
    return trace, trace.save(tmp_path / "t")


@pytest.mark.parametrize("name", ["records", "pixel_offsets", "counters"])
def test_a_flipped_byte_in_any_array_is_caught(tmp_path, name):
    trace, folder = _saved(tmp_path)
    AccessTrace.load(folder)  # intact: loads
    flip(folder / f"{name}.npy", 3)
    with pytest.raises(TraceIntegrityError, match=rf"{name}\.npy"):
        AccessTrace.load(folder)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A rendered tetra trace of 8x4 samples (its metadata records scene and image size)."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    folder = tmp_path_factory.mktemp("rendered") / "tetra"
    render(load("tetra"), options=RenderOptions(size=(8, 4)), trace_path=folder)
    return folder


def _copy(folder: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(folder, tmp_path / folder.name))


def test_a_changed_npy_header_is_caught(tmp_path):
    """Counters' dtype <i8 -> <f8 in the header alone (rays became 0, misses per ray NaN). Fails if the
    headers' checksums are not compared, and then (digests recorded anew) if the dtype is not checked
    against the format."""
    _, folder = _saved(tmp_path)
    data = (folder / "counters.npy").read_bytes()
    (folder / "counters.npy").write_bytes(data.replace(b"'<i8'", b"'<f8'", 1))
    with pytest.raises(TraceIntegrityError, match=r"counters\.npy's header does not match its checksum"):
        AccessTrace.load(folder)
    recorded_anew(folder)
    with pytest.raises(TraceIntegrityError, match=r"counters\.npy holds <f8 \(48, 25\), expected <i8 \(48, 25\)"):
        AccessTrace.load(folder)


def test_a_damaged_npy_magic_is_named_without_numpys_pickle_advice(tmp_path):
    """Fails if the loader lets np.load read the header (its message advises allow_pickle)."""
    _, folder = _saved(tmp_path)
    data = bytearray((folder / "records.npy").read_bytes())
    data[1] ^= 0x01
    (folder / "records.npy").write_bytes(bytes(data))
    with pytest.raises(TraceIntegrityError, match=r"t': records\.npy is damaged \(not a \.npy file") as caught:
        AccessTrace.load(folder)
    assert "pickle" not in str(caught.value)


def test_bytes_after_an_arrays_data_are_caught(tmp_path):
    """np.load ignores them. Fails if the file's size is not compared with its header's."""
    _, folder = _saved(tmp_path)
    with open(folder / "records.npy", "ab") as stream:
        stream.write(b"\0" * 4)
    with pytest.raises(TraceIntegrityError, match=r"records\.npy has \d+ bytes, expected \d+"):
        AccessTrace.load(folder)


def test_a_damaged_meta_json_is_caught(tmp_path):
    """Fails if meta.json is not compared with meta.json.xxh3, or if undecodable bytes pass."""
    _, folder = _saved(tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["width"], meta["height"] = meta["height"], meta["width"]  # still valid JSON, still consistent shapes
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(TraceIntegrityError, match="meta.json does not match its checksum"):
        AccessTrace.load(folder)
    (folder / "meta.json").write_bytes(b"\xff{")
    (folder / "meta.json.xxh3").write_text(xxhash.xxh3_64_hexdigest(b"\xff{"))
    with pytest.raises(TraceIntegrityError, match="meta.json is damaged"):
        AccessTrace.load(folder)


def _drop_checksums(meta):
    del meta["checksums"]


def _drop_a_header_checksum(meta):
    del meta["checksums"]["headers"]["counters"]


@pytest.mark.parametrize("damage", ["no meta.json.xxh3", "no checksums", "no header checksum"])
def test_a_trace_without_its_digests_is_refused_with_the_command_that_writes_it_again(rendered, tmp_path,
                                                                                       damage):
    """A trace written before checksums existed, or whose digest was deleted, is never taken unverified
    (64x64 was then simulated as 32x128, a flipped counter accepted). Fails if any missing digest skips
    its check."""
    folder = _copy(rendered, tmp_path)
    if damage == "no meta.json.xxh3":
        (folder / "meta.json.xxh3").unlink()
    else:
        meta = json.loads((folder / "meta.json").read_text())
        (_drop_checksums if damage == "no checksums" else _drop_a_header_checksum)(meta)
        data = json.dumps(meta).encode()
        (folder / "meta.json").write_bytes(data)
        (folder / "meta.json.xxh3").write_text(xxhash.xxh3_64_hexdigest(data))
    with pytest.raises(TraceIntegrityError, match="cannot be verified; re-render it with "
                                                  f"`coherence render tetra --size N --trace {folder}`"):
        AccessTrace.load(folder)


def test_dimensions_are_cross_checked(rendered, tmp_path):
    """Fails if a negative width and height whose product fits the arrays pass (they did, naming no trace),
    or if width and height swapped in meta.json, digests recorded anew, are not compared with the
    render's image size."""
    folder = _copy(rendered, tmp_path)
    recorded_anew(folder, lambda meta: meta.update(width=-8, height=-4))
    with pytest.raises(TraceIntegrityError, match=rf"trace '{folder}': meta.json: width must be an integer >= 1, "
                                                  "got -8"):
        AccessTrace.load(folder)
    recorded_anew(folder, lambda meta: meta.update(width=4, height=8))
    with pytest.raises(TraceIntegrityError, match=r"width x height = 4x8 disagrees with the render's record"):
        AccessTrace.load(folder)
    recorded_anew(folder, lambda meta: meta.update(width=8, height=4))
    assert AccessTrace.load(folder).counter("primary_rays").shape == (4, 8)


def _random_parts(seed=3):
    trace = random_trace(8, 6, seed=seed)
    return [np.array(trace.pixel_offsets), np.array(trace.records), np.array(trace.counters), 8, 6,
            {"record_counts": {kind.name.lower(): 60 for kind in RecordKind}}]


def test_records_beyond_the_scene_are_refused(tmp_path):
    """In memory and in a file whose digests were recorded anew. Fails if the constructor or the loader
    skips the records' kind and index check."""
    parts = _random_parts()
    AccessTrace(*parts)
    parts[1][5] = pack(RecordKind.SPHERE, 60)
    with pytest.raises(ValueError, match="AccessTrace: records: record 5 reads sphere 60, beyond the 60 records"):
        AccessTrace(*parts)
    parts[1][5] = np.uint32(15 << KIND_SHIFT)
    with pytest.raises(ValueError, match="record 5 reads unknown kind 15"):
        AccessTrace(*parts)
    _, folder = _saved(tmp_path, parts[5])
    recorded_anew(folder, records=parts[1])
    with pytest.raises(TraceIntegrityError, match=r"records\.npy: record 5 reads unknown kind 15"):
        AccessTrace.load(folder)


def test_offsets_that_fall_are_refused(tmp_path):
    """In memory and in a file whose digests were recorded anew. Fails if either skips the offsets'
    check."""
    parts = _random_parts()
    parts[0][3], parts[0][4] = parts[0][4] + 5, parts[0][3]
    with pytest.raises(ValueError, match=r"AccessTrace: pixel_offsets must rise from 0 to the record count; "
                                         r"entry 4 \(\d+\) is below entry 3"):
        AccessTrace(*parts)
    _, folder = _saved(tmp_path)
    recorded_anew(folder, pixel_offsets=parts[0])
    with pytest.raises(TraceIntegrityError, match=r"pixel_offsets\.npy must rise"):
        AccessTrace.load(folder)


def _negative_counter(parts):
    parts[2][7, 3] = -4


def _float_counters(parts):
    parts[2] = parts[2].astype(np.float64)


def _int32_offsets(parts):
    parts[0] = parts[0].astype(np.int32)


def _offsets_not_from_zero(parts):
    parts[0] = parts[0] + 1


def _no_pixels(parts):
    parts[3:5] = [0, 6]


def _list_records(parts):
    parts[1] = list(parts[1])


@pytest.mark.parametrize("damage, message", [
    (_negative_counter, r"counters must not be negative; pixel 7's \w+ is -4"),
    (_float_counters, "counters must have dtype int64, got float64"),
    (_int32_offsets, "pixel_offsets must have dtype int64, got int32"),
    (_offsets_not_from_zero, "pixel_offsets must run from 0 to the record count 894, got 1 to 895"),
    (_no_pixels, "AccessTrace.width must be >= 1, got 0"),
    (_list_records, "records must be a numpy array, got list"),
])
def test_an_access_trace_built_in_memory_is_checked_as_a_loaded_one(damage, message):
    """A negative counter gave speedup_user = -4.99e8. Fails if the constructor drops the matching check."""
    parts = _random_parts()
    damage(parts)
    with pytest.raises(ValueError, match=message):
        AccessTrace(*parts)


@pytest.mark.parametrize("seed", range(4))
def test_offset_and_counter_kernels_match_python_loops(seed):
    """Fails if a kernel's comparison is off by one (``<=`` for ``<``) or it returns the wrong position."""
    rng = np.random.default_rng(seed)
    offsets = np.cumsum(rng.integers(0, 3, 200)).astype(np.int64)
    values = rng.integers(0, 9, 300).astype(np.int64)
    if seed % 2:
        offsets[rng.integers(1, 200)] -= 1 + seed
        values[rng.integers(0, 300, 3)] = -1
    falls = [i for i in range(offsets.size - 1) if offsets[i + 1] < offsets[i]]
    negatives = [i for i in range(values.size) if values[i] < 0]
    assert _first_fall(offsets) == (falls[0] if falls else -1)
    assert _first_negative(values) == (negatives[0] if negatives else -1)
    assert _first_fall(np.array([0, 2, 2, 1, 0], np.int64)) == 2
    assert _first_fall(np.array([0], np.int64)) == -1
    assert _first_negative(np.array([0, 3, -1, -2], np.int64)) == 2


def _first_out_of_range_reference(records, limits):
    for position, record in enumerate(int(r) for r in records):
        if (record & INDEX_MASK) >= limits[record >> KIND_SHIFT]:
            return position
    return -1


@pytest.mark.parametrize("seed", range(6))
def test_range_kernel_matches_a_python_loop(seed):
    rng = np.random.default_rng(seed)
    limits = index_limits({"record_counts": {kind.name.lower(): int(rng.integers(0, 50))
                                              for kind in RecordKind}})
    records = pack(rng.integers(0, len(RecordKind), 300), rng.integers(0, 40, 300))
    if seed % 2:
        records[rng.integers(0, 300)] = np.uint32(rng.integers(len(RecordKind), 16)) << np.uint32(KIND_SHIFT)
    assert first_record_out_of_range(records, limits) == _first_out_of_range_reference(records, limits)
    assert first_record_out_of_range(records[:0], limits) == -1
