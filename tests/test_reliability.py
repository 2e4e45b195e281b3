"""Reliability: damaged files, leftovers of dead runs, and bad input on the command line.

The first part checks the integrity of traces and of the trace cache
directly. The second is a table of command lines (input -> exit status and a
fragment of the message) run in subprocesses, so that a segfault (rc 139 or
-11) fails the test instead of killing the test run. Cases are grouped: one
subprocess runs a group through ``analyses.cli.main`` in turn, so the start-up
cost is paid once per group; a crash names the case that was running.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from analyses import traces
from rtcommon.files import remove_stale_temporaries, temp_prefix, write_files_atomic
from tracer.records import INDEX_MASK, KIND_SHIFT, RecordKind, pack
from tracer.trace import AccessTrace, TraceIntegrityError, _first_record_out_of_range, _index_limits
from trace_factory import random_trace

ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------- trace files
def _saved(tmp_path, metadata=None):
    trace = random_trace(8, 6, seed=3)
    trace.metadata = metadata or {}
    return trace, trace.save(tmp_path / "t")


def _flip(path: Path, position_from_end: int) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) - position_from_end] ^= 0x04
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("name", ["records", "pixel_offsets", "counters"])
def test_a_flipped_byte_in_any_array_is_caught(tmp_path, name):
    trace, folder = _saved(tmp_path)
    AccessTrace.load(folder)  # intact: loads
    _flip(folder / f"{name}.npy", 3)
    with pytest.raises(TraceIntegrityError, match=rf"{name}\.npy"):
        AccessTrace.load(folder)


def test_a_damaged_meta_json_is_caught(tmp_path):
    _, folder = _saved(tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["width"], meta["height"] = meta["height"], meta["width"]  # still valid JSON, still consistent shapes
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(TraceIntegrityError, match="meta.json does not match its checksum"):
        AccessTrace.load(folder)
    (folder / "meta.json").write_bytes(b"\xff{")
    with pytest.raises(TraceIntegrityError, match="meta.json is damaged"):
        AccessTrace.load(folder)


def test_records_beyond_the_scene_are_refused_without_checksums(tmp_path):
    counts = {kind.name.lower(): 60 for kind in RecordKind}
    trace, folder = _saved(tmp_path, {"record_counts": counts})
    meta = json.loads((folder / "meta.json").read_text())
    del meta["checksums"], meta["meta_checksum"]  # a trace written before checksums existed
    (folder / "meta.json").write_text(json.dumps(meta))
    AccessTrace.load(folder)
    records = np.load(folder / "records.npy")
    records[5] = pack(RecordKind.SPHERE, 60)
    np.save(folder / "records.npy", records)
    with pytest.raises(TraceIntegrityError, match="record 5 reads sphere 60, beyond the 60 records"):
        AccessTrace.load(folder)
    records[5] = np.uint32(15 << KIND_SHIFT)
    np.save(folder / "records.npy", records)
    with pytest.raises(TraceIntegrityError, match="record 5 reads unknown kind 15"):
        AccessTrace.load(folder)


def test_offsets_that_fall_are_refused(tmp_path):
    trace, folder = _saved(tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    del meta["checksums"], meta["meta_checksum"]
    (folder / "meta.json").write_text(json.dumps(meta))
    offsets = np.load(folder / "pixel_offsets.npy")
    offsets[3], offsets[4] = offsets[4] + 5, offsets[3]
    np.save(folder / "pixel_offsets.npy", offsets)
    with pytest.raises(TraceIntegrityError, match="pixel_offsets must rise"):
        AccessTrace.load(folder)


def _first_out_of_range_reference(records, limits):
    for position, record in enumerate(int(r) for r in records):
        if (record & INDEX_MASK) >= limits[record >> KIND_SHIFT]:
            return position
    return -1


@pytest.mark.parametrize("seed", range(6))
def test_range_kernel_matches_a_python_loop(seed):
    rng = np.random.default_rng(seed)
    limits = _index_limits({"record_counts": {kind.name.lower(): int(rng.integers(0, 50))
                                              for kind in RecordKind}})
    records = pack(rng.integers(0, len(RecordKind), 300), rng.integers(0, 40, 300))
    if seed % 2:
        records[rng.integers(0, 300)] = np.uint32(rng.integers(len(RecordKind), 16)) << np.uint32(KIND_SHIFT)
    assert _first_record_out_of_range(records, limits) == _first_out_of_range_reference(records, limits)
    assert _first_record_out_of_range(records[:0], limits) == -1


# ----------------------------------------------------------------- trace cache
def test_cache_entry_with_a_flipped_byte_is_evicted_and_rebuilt(tmp_path):
    _, trace, info = traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)
    fresh = np.array(trace.records)
    del trace
    entry = Path(info["path"])
    assert entry.parent == tmp_path / "traces"
    _flip(entry / "trace" / "records.npy", 7)
    with pytest.warns(UserWarning, match=r"damaged trace cache entry .*records\.npy.*rendering again"):
        _, again, info2 = traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)
    assert not info2["cached"] and np.array_equal(np.asarray(again.records), fresh)
    _flip(entry / "image.png", 40)
    with pytest.warns(UserWarning, match="image.png"):
        traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)[2]["cached"]


def test_cache_layout_is_the_same_from_argument_and_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(traces.CACHE_ENV, str(tmp_path / "env"))
    assert traces.cache_root() == tmp_path / "env"
    assert traces.cache_root(tmp_path / "arg") == tmp_path / "arg"
    assert traces.default_cache_dir() == tmp_path / "env" / "traces"
    _, _, by_env = traces.cached_trace("tetra", 8, progress=False)
    _, _, by_arg = traces.cached_trace("tetra", 8, cache_dir=tmp_path / "env", progress=False)
    assert by_arg["cached"] and by_arg["path"] == by_env["path"]
    assert Path(by_env["path"]).parent == tmp_path / "env" / "traces"


def test_cache_folder_that_is_a_file_is_refused_up_front(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for where in (blocker, blocker / "below"):
        with pytest.raises(NotADirectoryError, match="is a file, not a folder"):
            traces.check_cache_dir(where)


def test_read_only_cache_renders_without_caching_and_warns(tmp_path, monkeypatch):
    real = traces.make_temp_dir

    def refuse(target):
        if Path(target).is_relative_to(tmp_path):
            raise PermissionError(13, "Permission denied")
        return real(target)

    monkeypatch.setattr(traces, "make_temp_dir", refuse)
    monkeypatch.setattr(traces, "_PRIVATE_CACHES", {})
    with pytest.warns(UserWarning, match="not writable.*rendering without caching"):
        _, trace, info = traces.cached_trace("tetra", 8, cache_dir=tmp_path / "ro", progress=False)
    assert not Path(info["path"]).is_relative_to(tmp_path) and trace.n_records > 0


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_temporaries_of_dead_processes_are_removed_live_ones_kept(tmp_path):
    host_prefix = temp_prefix("entry").rsplit("~", 2)[0]  # ".entry~<host>"
    dead = tmp_path / f"{host_prefix}~{_dead_pid()}~abc.tmp"
    live = tmp_path / f"{host_prefix}~{os.getppid()}~abc.tmp"
    other_host = tmp_path / f".entry~elsewhere~{_dead_pid()}~abc.tmp"
    for folder in (dead, live, other_host):
        folder.mkdir()
        (folder / "records.npy").write_bytes(b"x" * 10)
    assert remove_stale_temporaries(tmp_path) == [dead]
    assert live.is_dir() and other_host.is_dir() and not dead.exists()


def test_write_files_atomic_writes_all_or_nothing(tmp_path):
    write_files_atomic({tmp_path / "a.csv": "old", tmp_path / "b.png": b"old"})

    class Unwritable:
        pass

    with pytest.raises(TypeError):
        write_files_atomic({tmp_path / "a.csv": "new", tmp_path / "b.png": Unwritable()})
    assert (tmp_path / "a.csv").read_text() == "old" and (tmp_path / "b.png").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.png"]
