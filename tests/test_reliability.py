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
import shutil
import subprocess
import sys
import textwrap
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
import xxhash

from analyses import traces
from rtcommon.files import read_npy_header, remove_stale_temporaries, temp_prefix, write_files_atomic
from tracer.trace.records import INDEX_MASK, KIND_SHIFT, RecordKind, pack
from tracer.trace.access import AccessTrace, TraceIntegrityError
from tracer.trace.check import _first_fall, _first_negative, first_record_out_of_range, index_limits
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


def _recorded_anew(folder: Path, meta_edit=None, **arrays) -> None:
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
    _recorded_anew(folder)
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
    _recorded_anew(folder, lambda meta: meta.update(width=-8, height=-4))
    with pytest.raises(TraceIntegrityError, match=rf"trace '{folder}': meta.json: width must be an integer >= 1, "
                                                  "got -8"):
        AccessTrace.load(folder)
    _recorded_anew(folder, lambda meta: meta.update(width=4, height=8))
    with pytest.raises(TraceIntegrityError, match=r"width x height = 4x8 disagrees with the render's record"):
        AccessTrace.load(folder)
    _recorded_anew(folder, lambda meta: meta.update(width=8, height=4))
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
    _recorded_anew(folder, records=parts[1])
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
    _recorded_anew(folder, pixel_offsets=parts[0])
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


def _rewrite_render_json(entry: Path, edit) -> None:
    info = json.loads((entry / "render.json").read_text())
    edit(info)
    data = json.dumps(info).encode()
    (entry / "render.json").write_bytes(data)
    (entry / "render.json.xxh3").write_text(xxhash.xxh3_64_hexdigest(data))


def _digit_flipped_in_render_json(entry, other):
    text = (entry / "render.json").read_text()
    tests = json.loads(text)["totals"]["tests_triangle"]
    (entry / "render.json").write_text(text.replace(f'"tests_triangle": {tests}', f'"tests_triangle": {tests - 1}'))


def _render_json_digest_gone(entry, other):
    (entry / "render.json.xxh3").unlink()


def _image_checksum_gone(entry, other):
    _rewrite_render_json(entry, lambda info: info.pop("image_checksum"))


def _counters_header_says_float(entry, other):
    counters = entry / "trace" / "counters.npy"
    counters.write_bytes(counters.read_bytes().replace(b"'<i8'", b"'<f8'", 1))


def _another_entrys_trace(entry, other):
    shutil.rmtree(entry / "trace")
    shutil.copytree(other / "trace", entry / "trace")


def _size_edited_with_digest(entry, other):
    _rewrite_render_json(entry, lambda info: info.update(size=4))


@pytest.mark.parametrize("damage, warning", [
    (_digit_flipped_in_render_json, r"render\.json does not match its checksum"),
    (_render_json_digest_gone, r"render\.json\.xxh3 is missing"),
    (_image_checksum_gone, r"image\.png does not match its checksum"),
    (_counters_header_says_float, r"counters\.npy's header does not match its checksum"),
    (_another_entrys_trace, "the trace is not the one render.json was written with"),
    (_size_edited_with_digest, r"render\.json \(key .*, size 4\) does not describe its 8x8 trace"),
])
def test_a_damaged_or_unverifiable_cache_entry_is_evicted_and_rebuilt(tmp_path, damage, warning):
    """Every byte of an entry is under render.json.xxh3 (a flipped digit of render.json went into results.csv;
    a counters header saying float64 failed every run, never evicted). Fails if the check the warning
    names is skipped."""
    _, _, info = traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    _, _, other = traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False, max_depth=3)
    entry = Path(info["path"])
    damage(entry, Path(other["path"]))
    with pytest.warns(UserWarning, match=rf"damaged trace cache entry {info['key']}: {warning}.*; evicting it"):
        _, _, again = traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    assert not again["cached"] and again["totals"] == info["totals"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)[2]["cached"]


def test_a_damaged_cached_scene_file_is_written_again(tmp_path):
    """What-if scene sizes are NFF files in the cache, and traces are keyed by their bytes: a damaged one
    would be rendered as another scene. Fails if an existing file is used without comparing its bytes, or
    if a killed run's temporary beside it is not removed."""
    from analyses.whatif import _sized_scene_file

    path = Path(_sized_scene_file("tetra", 2, tmp_path))
    fresh = path.read_bytes()
    path.write_bytes(fresh[:len(fresh) // 2])  # cut short: still a scene, with half its triangles
    left = path.parent / f"{temp_prefix(path.name).rsplit('~', 2)[0]}~{_dead_pid()}~abc.tmp"
    left.write_text("s 0 0 0 1\n")  # a killed run's temporary
    assert Path(_sized_scene_file("tetra", 2, tmp_path)).read_bytes() == fresh
    assert not left.exists()


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


def test_temporaries_of_a_killed_run_not_yet_reaped_are_removed(tmp_path):
    """A run killed by SIGKILL is a zombie until its parent reaps it; an immediate rerun must still take
    its temporaries for a dead run's. Fails if ``_process_alive`` ends in ``return True`` (no zombie test)."""
    import signal
    import time

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        child.send_signal(signal.SIGKILL)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:  # dead, and not reaped: no wait() yet
            if Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] == "Z":
                break
            time.sleep(0.01)
        left = tmp_path / f"{temp_prefix('entry').rsplit('~', 2)[0]}~{child.pid}~abc.tmp"
        left.mkdir()
        assert remove_stale_temporaries(tmp_path) == [left]
    finally:
        child.wait()


def test_a_cache_hit_removes_a_dead_runs_temporaries(tmp_path):
    """Fails if ``cached_trace`` clears stale temporaries only when it renders (its call before the entry
    is read is removed)."""
    traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    left = tmp_path / "traces" / f"{temp_prefix('tetra-8').rsplit('~', 2)[0]}~{_dead_pid()}~abc.tmp"
    left.mkdir()
    assert traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)[2]["cached"]
    assert not left.exists()


def test_a_cache_entry_that_is_a_file_is_replaced(tmp_path):
    """Fails if the file standing where the entry's folder goes is not removed first (the rename of the
    new entry then fails with 'Not a directory' on every run)."""
    _, _, info = traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    entry = Path(info["path"])
    shutil.rmtree(entry)
    entry.write_text("x")
    with pytest.warns(UserWarning, match="a file, not a folder"):
        _, trace, again = traces.cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    assert not again["cached"] and (entry / "render.json").is_file() and trace.n_records > 0


def test_write_files_atomic_writes_all_or_nothing(tmp_path):
    write_files_atomic({tmp_path / "a.csv": "old", tmp_path / "b.png": b"old"})

    class Unwritable:
        pass

    with pytest.raises(TypeError):
        write_files_atomic({tmp_path / "a.csv": "new", tmp_path / "b.png": Unwritable()})
    assert (tmp_path / "a.csv").read_text() == "old" and (tmp_path / "b.png").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.png"]


# ------------------------------------------------------------- command lines
# Each case: (argv, expected exit status, a fragment of stderr), optionally a dict of environment
# variables. Paths are relative to a scratch folder that holds: afile (a regular file), adir (a
# folder), pipe.nff and pipe.txt (FIFOs), trace8 (a tetra 8x8 trace), trace8-flipped (one byte of
# its records flipped), trace8-outside (a record beyond the scene, digests recorded anew), trace8-old
# (no meta.json.xxh3), trace8-f8 (counters' header says float64), trace8-magic (records.npy's magic
# string damaged), addresses.txt,
# bom.txt (addresses after a UTF-8 byte-order mark), binary.toml (not text), petabyte.toml (a
# hierarchy whose 4 PB level cannot be allocated),
# empty.nff, noview.nff and digits.nff (NFF files the strict reader refuses), huge.nff (a
# triangle at 1e300, which the renderer refuses), bom.nff (after a UTF-8 byte-order mark),
# depth0.nff ('# max_depth 0'), negative.nff (Kd -0.5), usemtl.obj (usemtl without mtllib), vn.obj
# (normal 2 of 1), badvt.obj ('f 1/a 2 3'), huge-texture.nff (a 16384 x 16384 PNG header) and
# bom-study.toml (a what-if study without a grid, after a byte-order mark).
CLI_CASES = [
    (["render", "balls", "--size", "20000"], 2, "needs about"),
    (["render", "tetra", "--size", "0"], 2, "--size must be >= 1"),
    (["render", "tetra", "--size", "8", "--png", "nodir/x.png"], 2, "'nodir' does not exist"),
    (["render", "tetra", "--size", "8", "--png", "adir"], 2, "is a folder"),
    (["render", "tetra", "--size", "8", "--trace", "afile"], 2, "is a file, not a trace folder"),
    (["render", "tetra", "--size", "8", "--trace", "adir/../afile/t"], 2, "is a file, not a folder"),
    (["render", "pipe.nff", "--size", "8"], 2, "not a regular file"),
    (["render", "empty.nff", "--size", "8"], 2, "empty.nff:2:1: expected at least one object"),
    (["scene", "noview.nff"], 2, "noview.nff:1:1: expected a view"),
    (["scene", "digits.nff"], 2, "digits.nff:8:3: expected a number"),
    (["render", "huge.nff", "--size", "8"], 2, "row 0 holds 1e+300; coordinates and sizes must be finite"),
    (["render", "tetra", "--size", "8", "--max-depth", "0"], 2, "--max-depth must be in [1, 64]"),
    (["render", "tetra", "--size", "8", "--memory-budget", "0"], 2, "--memory-budget must be > 0"),
    (["render", "tetra", "--size", "8", "--memory-budget", "nan"], 2, "--memory-budget must be > 0"),
    (["render", "tetra", "--size", "4", "--png", "ok.png", "--trace", "ok-trace"], 0, "wrote ok.png"),
    (["scene", "balls", "--max-depth", "0"], 2, "--max-depth must be in [1, 64]"),
    (["scene", "balls", "--nff-out", "nodir/x.nff"], 2, "'nodir' does not exist"),
    (["scene", "pipe.nff"], 2, "not a regular file"),
    (["scene", "adir"], 2, ""),
    (["scene", "missing.nff"], 2, "missing.nff"),
    (["simulate", "afile"], 2, "is a file"),
    (["simulate", "adir"], 2, "lacks meta.json"),
    (["simulate", "trace8", "--csv", "nodir/x.csv"], 2, "'nodir' does not exist"),
    (["simulate", "trace8", "--csv", "adir"], 2, "is a folder"),
    (["simulate", "trace8", "--processes", "0"], 2, "--processes must be >= 1"),
    (["simulate", "trace8", "--cpus", "0"], 2, "--cpus must be >= 1"),
    (["simulate", "trace8", "--background", "-1"], 2, "--background must be >= 0"),
    (["simulate", "trace8", "--quantum", "-1"], 2, "--quantum must be"),
    (["simulate", "trace8", "--background-footprint", "-1"], 2, "--background-footprint must be >= 0"),
    (["simulate", "trace8", "--page-seed", "-1"], 2, "--page-seed must be >= 0"),
    (["simulate", "trace8", "--page-placement", "buddy"], 2, "invalid choice: 'buddy'"),
    (["simulate", "trace8", "--page-placement", "random", "--hierarchy", "alpha21164-dtb", "--csv", "paged.csv"], 0,
     ""),
    (["simulate", "trace8-flipped"], 2, "damaged"),
    (["simulate", "trace8-outside"], 2, "beyond the"),
    (["simulate", "trace8-old"], 2, "re-render it with `coherence render tetra --size 8 --trace trace8-old`"),
    (["simulate", "trace8-f8"], 2, "counters.npy's header does not match its checksum"),
    (["simulate", "trace8-magic"], 2, "records.npy is damaged (not a .npy file"),
    (["simulate", "trace8", "--mapping", "S", "--processes", "2", "--csv", "runs.csv"], 0, ""),
    (["cachesim", "pipe.txt"], 2, "not a regular file"),
    (["cachesim", "adir"], 2, "is a folder"),
    (["cachesim", "missing.txt"], 2, "no such file"),
    (["cachesim", "addresses.txt", "--csv", "nodir/x.csv"], 2, "'nodir' does not exist"),
    (["cachesim", "addresses.txt", "--hierarchy", "pipe.txt.toml"], 2, ""),
    (["cachesim", "addresses.txt", "--hierarchy", "binary.toml"], 2, "binary.toml:1: not a text file"),
    (["cachesim", "addresses.txt", "--hierarchy", "petabyte.toml"], 2, "use smaller caches"),
    (["cachesim", "bom.txt"], 0, ""),
    (["whatif", "--grid", "L1.size=4KB", "--grid", "L1.size=8KB"], 2, "--grid L1.size is given more than once"),
    (["whatif", "latency", "--jobs", "0"], 2, "--jobs must be >= 1"),
    (["whatif", "latency", "--jobs", "-1"], 2, "--jobs must be >= 1"),
    (["whatif", "latency", "--processes", "0"], 2, "--processes must be >= 1"),
    (["whatif", "latency", "--size", "20000"], 2, "needs about"),
    (["whatif", "latency", "--out", "afile"], 2, "is not a folder"),
    (["whatif", "--file", "pipe.txt"], 2, "not a regular file"),
    (["whatif", "latency", "--cache", "afile"], 2, "is a file, not a folder"),
    (["whatif", "latency", "--dask", "tcp://127.0.0.1:9"], 2, "pip install 'raytrace-coherence[cluster]'",
     {"BLOCK_DISTRIBUTED": "1"}),
    (["report", "tetra", "--size", "8", "--cache", "afile"], 2, "cache folder 'afile'"),
    (["report", "tetra", "--size", "8"], 2, "$COHERENCE_CACHE 'afile'", {"COHERENCE_CACHE": "afile"}),
    (["report", "tetra", "--size", "20000"], 2, "needs about"),
    (["report", "tetra", "--size", "8", "--max-processes", "0"], 2, "--max-processes must be >= 1"),
    (["report", "tetra", "--size", "8", "--processes", "0"], 2, "--processes must be >= 1"),
    (["report", "pipe.nff", "--size", "8"], 2, "not a regular file"),
    (["report", "tetra", "--size", "32", "--mappings", "DB", "--max-processes", "2", "--out", "one-mapping"], 0, ""),
    (["paper", "--size", "8", "--cache", "afile"], 2, "is a file, not a folder"),
    (["paper", "--size", "8", "--page-seed", "-1"], 2, "--page-seed must be >= 0"),
    (["report", "tetra", "--size", "8", "--background-footprint", "-1"], 2, "--background-footprint must be >= 0"),
    (["report", "tetra", "--size", "8", "--page-placement", "buddy"], 2, "invalid choice: 'buddy'"),
    (["paper", "--size", "20000"], 2, "needs about"),
    (["scene", "bom.nff"], 0, ""),
    (["scene", "depth0.nff"], 2, "depth0.nff:9:13: expected a max_depth in 1..64, found '0'"),
    (["render", "depth0.nff", "--size", "4"], 2, "depth0.nff:9:13: expected a max_depth in 1..64"),
    (["scene", "negative.nff"], 2, "negative.nff:8:9: expected Kd >= 0"),
    (["scene", "usemtl.obj"], 0, "usemtl.obj:1: 'usemtl red' names a material, but no 'mtllib'"),
    (["scene", "vn.obj"], 2, "vn.obj:5: expected a normal index in 1..1 or negative, found '1//2'"),
    (["scene", "badvt.obj"], 2, "badvt.obj:4: expected a texture coordinate index, found '1/a'"),
    (["scene", "huge-texture.nff"], 2, "huge.png' is 16384 x 16384 (268,435,456 texels); a texture may hold at most"),
    (["render", "huge-texture.nff", "--size", "4"], 2, "huge.png' is 16384 x 16384"),
    (["render", "tetra", "--size", "8", "--png", "counted.png", "--memory-budget", "0.001"], 0, "wrote counted.png"),
    (["render", "tetra", "--size", "8", "--png", "x.jpg"], 2, "--png 'x.jpg' must end in .png"),
    (["report", "tetra", "--size", "8", "--out", ""], 2, "output folder '' is an empty name"),
    (["whatif", "latency", "--out", ""], 2, "output folder '' is an empty name"),
    (["paper", "--size", "8", "--out", ""], 2, "output folder '' is an empty name"),
    (["whatif", "--file", "binary.toml"], 2, "binary.toml:1: not a text file (byte 0 is not UTF-8)"),
    (["whatif", "--file", "bom-study.toml"], 2, "bom-study.toml: needs a [grid] table"),
]

_RUNNER = textwrap.dedent('''
    import contextlib, io, json, os, sys
    cases = json.load(sys.stdin)
    if os.environ.get("BLOCK_DISTRIBUTED_ALL"):
        sys.modules["distributed"] = None
    from analyses.cli import main
    for number, (argv, env) in enumerate(cases):
        with open("running.txt", "w") as status:
            status.write(" ".join(argv))
        saved = {key: os.environ.get(key) for key in env}
        os.environ.update(env)
        blocked = sys.modules.get("distributed", False)
        if env.get("BLOCK_DISTRIBUTED"):
            sys.modules["distributed"] = None
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(argv)
            except SystemExit as exit:
                status = exit.code
            except BaseException as error:
                status = "traceback"
                err.write(f"{type(error).__name__}: {error}")
        if env.get("BLOCK_DISTRIBUTED"):
            if blocked is False:
                del sys.modules["distributed"]
            else:
                sys.modules["distributed"] = blocked
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        print(json.dumps({"status": status, "stderr": err.getvalue()}), flush=True)
''')


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """The scratch folder the table's paths are relative to."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    folder = tmp_path_factory.mktemp("cli")
    (folder / "afile").write_text("x\n")
    (folder / "adir").mkdir()
    os.mkfifo(folder / "pipe.nff")
    os.mkfifo(folder / "pipe.txt")
    os.mkfifo(folder / "pipe.txt.toml")
    (folder / "addresses.txt").write_text("0\n64\n4096\n0\n")
    (folder / "binary.toml").write_bytes(b"\xff\xfe\x00n\x00a")
    (folder / "bom.txt").write_bytes(b"\xef\xbb\xbf0\n64\n")
    (folder / "petabyte.toml").write_text('[[levels]]\nname = "L1"\nsize = 4503599627370496\nline_size = 64\n')
    (folder / "empty.nff").write_text("# nothing but a comment\n")
    (folder / "noview.nff").write_text("s 0 0 0 1\n")
    view = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\n"
    (folder / "digits.nff").write_text(view + "s 1_0 0 0 1\n")
    (folder / "huge.nff").write_text(view + "p 3 0 0 0 1e300 0 0 0 1e300 0\n")
    (folder / "bom.nff").write_bytes(b"\xef\xbb\xbf" + (view + "s 0 0 0 1\n").encode())
    (folder / "depth0.nff").write_text(view + "s 0 0 0 1\n# max_depth 0\n")
    (folder / "negative.nff").write_text(view + "f 1 1 1 -0.5 0 0 0 1\ns 0 0 0 1\n")
    triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    (folder / "usemtl.obj").write_text("usemtl red\n" + triangle + "f 1 2 3\n")
    (folder / "vn.obj").write_text(triangle + "vn 0 0 1\nf 1//2 2//1 3//1\n")
    (folder / "badvt.obj").write_text(triangle + "f 1/a 2 3\n")
    (folder / "huge.png").write_bytes(_png_header(16384, 16384))
    (folder / "bom-study.toml").write_bytes(b"\xef\xbb\xbfjobs = 1\n")
    (folder / "huge-texture.nff").write_text(view + "texture big huge.png\nusetexture big\ns 0 0 0 1\n")
    render(load("tetra"), options=RenderOptions(size=8), trace_path=folder / "trace8")
    for name in ("trace8-flipped", "trace8-outside", "trace8-old", "trace8-f8", "trace8-magic"):
        shutil.copytree(folder / "trace8", folder / name)
    _flip(folder / "trace8-flipped" / "records.npy", 9)
    outside = folder / "trace8-outside"
    records = np.load(outside / "records.npy")
    triangles = json.loads((outside / "meta.json").read_text())["metadata"]["record_counts"]["triangle"]
    records[3] = pack(RecordKind.TRIANGLE, triangles)
    _recorded_anew(outside, records=records)
    (folder / "trace8-old" / "meta.json.xxh3").unlink()
    counters = folder / "trace8-f8" / "counters.npy"
    counters.write_bytes(counters.read_bytes().replace(b"'<i8'", b"'<f8'", 1))
    (folder / "trace8-magic" / "records.npy").write_bytes(b"\x93NUMPX" + (folder / "trace8" / "records.npy").read_bytes()[6:])
    return folder


def run_cli_cases(folder: Path, cases, timeout: float = 900):
    """Run ``cases`` ((argv, env) pairs) in one subprocess; a list of {status, stderr}.

    Fails the calling test when the subprocess dies (a segfault: rc 139 or
    -11), naming the case that was running.
    """
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "COHERENCE_CACHE": str(folder / "cache"), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", _RUNNER], input=json.dumps([list(case) for case in cases]),
                          capture_output=True, text=True, cwd=folder, env=env, timeout=timeout)
    results = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{\"status\"")]
    if done.returncode != 0:
        running = (folder / "running.txt").read_text()
        kind = "segfault" if done.returncode in (139, -11) else f"rc {done.returncode}"
        pytest.fail(f"the runner died ({kind}) during: coherence {running}\n{done.stderr[-2000:]}")
    return results


def test_command_line_table(scratch):
    cases = [(case[0], case[3] if len(case) > 3 else {}) for case in CLI_CASES]
    results = run_cli_cases(scratch, cases)
    failures = []
    for case, result in zip(CLI_CASES, results):
        argv, status, fragment = case[:3]
        lines = [line for line in result["stderr"].splitlines() if "error" in line or "Error" in line]
        if (result["status"] != status or fragment not in result["stderr"] or "Traceback" in result["stderr"]
                or len(lines) > 1):
            failures.append(f"coherence {' '.join(argv)}: want {status} with {fragment!r}, got "
                            f"{result['status']}: {result['stderr'][-400:]!r}")
    assert not failures, "\n".join(failures)
    assert (scratch / "one-mapping" / "index.html").is_file()
    assert not (scratch / "nodir").exists()


def _cli(*argv, **options):
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.Popen([sys.executable, "-m", "analyses", *argv], env=env, text=True, **options)


def test_ctrl_c_prints_one_line_and_dies_by_sigint(tmp_path):
    import signal
    import time

    process = _cli("render", "balls", "--size", "2048", "--no-log", stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                   cwd=tmp_path)
    deadline = time.monotonic() + 120
    seen = ""
    while "rendering" not in seen and time.monotonic() < deadline:  # interrupt in the middle of the work
        seen += process.stderr.readline()
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == -signal.SIGINT, err  # killed by SIGINT: a shell reports 130
    said = err.strip().splitlines()  # numba compiling (a cold cache) adds the line that says it holds Ctrl-C
    assert said[-1] == "coherence render: interrupted"
    assert all(line.startswith("coherence render: interrupt received;") for line in said[:-1]) and len(said) <= 2


def test_broken_pipe_exits_quietly(tmp_path):
    process = _cli("scene", "balls", "--json", stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    process.stdout.close()  # the reader goes away before the output comes (like '| head -0'), at start-up
    err = process.stderr.read()
    process.wait(timeout=120)
    assert process.returncode == 141 and err == ""


# A process without work once crashed the simulation kernel (issue 13 item 1); these cases run
# apart so that a segfault there would not hide the others.
NO_WORK_CASES = [
    (["report", "tetra", "--size", "15", "--mappings", "S", "--max-processes", "16", "--out", "small"], 0, ""),
    (["simulate", "trace8", "--mapping", "S", "--processes", "9"], 0, ""),
    (["simulate", "trace8", "--mapping", "P", "--processes", "65"], 0, ""),
]


def test_processes_without_work_do_not_crash(scratch):
    results = run_cli_cases(scratch, [(case[0], {}) for case in NO_WORK_CASES])
    assert [result["status"] for result in results] == [case[1] for case in NO_WORK_CASES]


def test_a_trace_that_will_not_fit_on_disk_is_refused_before_rendering(tmp_path, monkeypatch):
    import shutil

    from analyses import output

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=10_000))
    with pytest.raises(ValueError, match=r"the trace of tetra at 64x64 needs about [\d.]+ kB of disk space in .*, "
                                         r"9\.8 kB free"):
        traces.cached_trace("tetra", 64, cache_dir=tmp_path, progress=False)
    assert not list((tmp_path / "traces").iterdir())
    output.check_free_space("small", tmp_path, 5_000)  # what fits passes


# ------------------------------------------------------------- messages that fit the cause
def _scenes_help(capsys) -> str:
    from analyses.cli import main

    with pytest.raises(SystemExit):
        main(["paper", "--help"])
    text = capsys.readouterr().out
    return " ".join(text.split("--scenes SCENE [SCENE ...]")[-1].split("\n  --", 1)[0].split())


def test_paper_help_lists_only_the_scenes_paper_accepts(capsys):
    """Every scene ``paper --help`` names for --scenes is accepted, and all the study's are named.

    Fails if the --scenes help says ``%(scenes)s`` (every named scene, textured ones too) again.
    """
    import re

    from analyses.paper_study import check_scenes
    from tracer.scenes.catalog import NAMED_SCENES, PAPER_SCENES

    listed = [word for word in re.findall(r"[a-z][a-z-]*", _scenes_help(capsys)) if word in NAMED_SCENES]
    assert sorted(listed) == sorted(PAPER_SCENES)
    assert check_scenes(listed) == listed


# ------------------------------------------------------------- scene files
SCENE_VIEW = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\n"
QUAD_OBJ = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"


def test_a_byte_order_mark_is_skipped(tmp_path):
    """An OBJ, MTL or NFF file that starts with a UTF-8 BOM reads as it does without one. Fails if the
    readers decode with plain "utf-8" (the OBJ then loses its first vertex, the others fail)."""
    from tracer.scenes.nff import read_nff
    from tracer.scenes.obj import read_obj
    from tracer.scenes.model import scenes_equal

    material = "newmtl red\nKd 1 0 0\n"
    obj = "mtllib m.mtl\nusemtl red\n" + QUAD_OBJ
    nff = SCENE_VIEW + "f 1 0 0 1 0 0 0 1\ns 0 0 0 1\n"
    scenes = {}
    for folder, mark in (("plain", b""), ("marked", b"\xef\xbb\xbf")):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "m.mtl").write_bytes(mark + material.encode())
        (tmp_path / folder / "q.obj").write_bytes(mark + obj.encode())
        (tmp_path / folder / "s.nff").write_bytes(mark + nff.encode())
        scenes[folder] = read_obj(tmp_path / folder / "q.obj"), read_nff(tmp_path / folder / "s.nff")
    for plain, marked in zip(scenes["plain"], scenes["marked"]):
        assert scenes_equal(plain, marked)
    assert scenes["marked"][0].material_color.tolist() == [[1.0, 0.0, 0.0]]


@pytest.mark.parametrize("field", ["r", "g", "b", "Kd", "Ks", "T", "ior"])
def test_a_negative_nff_material_value_is_refused_where_it_stands(field):
    """Fails if either NFF reader lets a negative colour, Kd, Ks, T or ior through (drop the check in
    the positional reader: the fast reader falls back to it and the file reads)."""
    from tracer.scenes.nff import NFFError, parse_nff
    from tracer.scenes.nff_fast import MATERIAL_FIELDS

    at = MATERIAL_FIELDS.index(field)
    values = ["0.5", "0.5", "0.5", "0.8", "0.1", "30", "0", "1"]
    values[at] = "-0.25"
    text = SCENE_VIEW + "f " + " ".join(values) + "\ns 0 0 0 1\n"
    column = len("f ") + sum(len(v) + 1 for v in values[:at]) + 1
    with pytest.raises(NFFError, match=rf"scene.nff:8:{column}: expected {field} >= 0 .*found '-0.25'"):
        parse_nff(text, "scene.nff")
    values[at], values[5] = "0", "-3"  # a negative Phong exponent is allowed
    assert parse_nff(SCENE_VIEW + "f " + " ".join(values) + "\ns 0 0 0 1\n").material_shine.tolist() == [-3.0]


@pytest.mark.parametrize("field", ["color", "kd", "ks", "t", "ior"])
def test_a_negative_material_is_refused_by_its_config(field):
    """Fails if Material accepts a negative colour, kd, ks, t or ior (drop its check)."""
    from tracer.scenes.model import Material

    value = (0.5, -0.1, 0.5) if field == "color" else -0.1
    with pytest.raises(ValueError, match=f"Material.{field} must be >= 0"):
        Material(**{field: value})


def test_a_max_depth_line_outside_1_to_64_is_refused_naming_file_and_line():
    """Fails if the reader takes '# max_depth 0' (render then refused it without naming the file)."""
    from tracer.scenes.nff import NFFError, parse_nff
    from tracer.scenes.catalog import load

    text = SCENE_VIEW + "s 0 0 0 1\n# max_depth 0\n"
    with pytest.raises(NFFError, match=r"deep.nff:9:13: expected a max_depth in 1\.\.64, found '0'"):
        parse_nff(text, "deep.nff")
    assert parse_nff(text, "deep.nff", max_depth=3).max_depth == 3  # an explicit depth replaces the line
    with pytest.raises(ValueError, match=r"max_depth must be in \[1, 64\], got 0"):
        load("tetra", max_depth=0)


@pytest.mark.parametrize("before, face, expected", [
    ("", "f 1/a 2 3", "q.obj:5: expected a texture coordinate index, found '1/a'"),
    ("vn 0 0 1\n", "f 1//2 2//1 3//1", r"q.obj:5: expected a normal index in 1\.\.1 or negative, found '1//2'"),
    ("vn 0 0 1\n", "f 1/1/1 2/1/1 3/1/9", r"q.obj:5: expected a normal index in 1\.\.1 or negative, found '3/1/9'"),
    ("vt 0 0\n", "f 1//1 2 3", r"q.obj:5: expected a normal index \(none is defined before this line\), found '1//1'"),
])
def test_obj_face_indices_are_checked_even_where_unused(tmp_path, before, face, expected):
    """Fails if a face's normal index is not checked against the 'vn' lines before it, or a texture
    index is only checked once a 'vt' exists ('1/a' was reported as a missing 'vt')."""
    from tracer.scenes.obj import OBJError, read_obj

    (tmp_path / "q.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + (before or "g mesh\n") + face + "\n")
    with pytest.raises(OBJError, match=expected):
        read_obj(tmp_path / "q.obj")


def test_obj_usemtl_without_mtllib_warns_once(tmp_path):
    """Fails if a 'usemtl' that names nothing (no 'mtllib' before it) passes in silence."""
    from tracer.scenes.obj import read_obj

    (tmp_path / "q.obj").write_text("usemtl red\n" + QUAD_OBJ + "usemtl blue\n")
    with pytest.warns(UserWarning, match=r"q.obj:1: 'usemtl red' names a material, but no 'mtllib'") as seen:
        scene = read_obj(tmp_path / "q.obj")
    assert len(seen) == 1 and scene.material_color.tolist() == [[0.8, 0.8, 0.8]]


# ------------------------------------------------------------- Ctrl-C where Python drops exceptions
_DROPPED_INTERRUPT = textwrap.dedent('''
    import signal, sys, time, weakref
    from analyses.interrupts import InterruptsOutsideNumba

    def interrupt_here():
        signal.raise_signal(signal.SIGINT)
        for _ in range(1000):  # Python runs the handler here, inside the callback
            pass

    class Key:
        pass

    class Finalized:
        def __del__(self):
            interrupt_here()

    def in_weak_key_dictionary_callback():
        table = weakref.WeakKeyDictionary()
        key = Key()
        table[key] = 1
        watcher = weakref.ref(key, lambda ref: interrupt_here())  # runs beside the table's own clean-up
        del key
        return watcher

    def in_del():
        Finalized()

    def swallowed_by_a_library():
        try:
            interrupt_here()
        except KeyboardInterrupt:
            pass

    try:
        with InterruptsOutsideNumba():
            globals()[sys.argv[1]]()
            for _ in range(100):  # the run goes on for a second
                time.sleep(0.01)
            print("ran on")
        print("finished")
    except KeyboardInterrupt:
        print("interrupted")
''')


def _interruptible():
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)  # a test run in the background starts with SIGINT ignored


def _python(code: str, *argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, env=env,
                          timeout=120, preexec_fn=_interruptible)


@pytest.mark.parametrize("where, said", [("in_weak_key_dictionary_callback", "interrupted\n"),
                                         ("in_del", "interrupted\n"),
                                         ("swallowed_by_a_library", "ran on\ninterrupted\n")])
def test_an_interrupt_python_drops_still_ends_the_run(where, said):
    """Ctrl-C raised where Python prints "Exception ignored" and runs on (a weakref callback, ``__del__``)
    interrupts the command at once, without that message; one a library catches, at the latest when the
    command ends.

    Fails (prints "ran on", "finished" and "Exception ignored") if ``InterruptsOutsideNumba.__enter__`` no
    longer installs ``_unraisable`` as ``sys.unraisablehook`` (the callback cases) or if ``__exit__`` no
    longer raises for ``self.received`` (the library case).
    """
    done = _python(_DROPPED_INTERRUPT, where)
    assert (done.stdout, done.stderr) == (said, "")


_HELD_IN_NUMBA = textwrap.dedent('''
    import json, signal, sys, time
    from analyses.interrupts import InterruptsOutsideNumba

    class Clock:
        """stderr that notes when each line came."""
        def __init__(self):
            self.lines = []
        def write(self, text):
            self.lines.append((time.monotonic(), text))
        def flush(self):
            pass

    # A function of a numba module: sys.argv[1] is numba.core.compiler_machinery (compiling) or one that
    # loading a compiled function from numba's cache runs; Ctrl-C comes as it starts, and it runs on for 2 s.
    namespace = {"__name__": sys.argv[1]}
    exec("import signal, time\\n"
         "def work(seconds):\\n"
         "    sent = time.monotonic()\\n"
         "    signal.raise_signal(signal.SIGINT)\\n"
         "    while time.monotonic() < sent + seconds:\\n"
         "        time.sleep(0.01)\\n"
         "    return sent\\n", namespace)
    sys.stderr = clock = Clock()
    try:
        with InterruptsOutsideNumba("test"):
            sent = namespace["work"](2.0)
            returned = time.monotonic()
            time.sleep(1.0)
            print("ran on")
    except KeyboardInterrupt:
        stopped = time.monotonic()
    print(json.dumps({"said": [[at - sent, text] for at, text in clock.lines],
                      "returned": returned - sent, "stopped": stopped - sent}))
''')


def test_an_interrupt_held_by_a_compilation_is_announced_within_a_second():
    """Ctrl-C while numba compiles is held until the compilation ends, and one line says so within 1 s;
    while numba loads a compiled function it is held without a word.

    Fails if ``InterruptsOutsideNumba._hold`` no longer starts the announcer (no line), or if
    ``_announce`` no longer asks ``self.compiling``, or ``_numba_compiling`` takes any numba.core.compiler*
    module for a compilation again (a line while numba loads a function from its cache).
    """
    for module, lines in (("numba.core.compiler_machinery", 1), ("numba.core.caching", 0), ("numba.core.compiler", 0),
                          ("numba.core.compiler_lock", 0)):
        done = _python(_HELD_IN_NUMBA, module)
        result = json.loads(done.stdout)
        said = [text for _, text in result["said"] if text.strip()]
        assert len(said) == lines, result
        assert result["returned"] >= 2.0 and result["returned"] <= result["stopped"] <= result["returned"] + 0.5
        if lines:
            assert said[0].startswith("test: interrupt received; stopping when numba has compiled")
            assert result["said"][0][0] < 1.0


def _png_header(width, height) -> bytes:
    """A PNG file's signature, header chunk and end: it opens and states its size, but holds no pixels."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) \
        + chunk(b"IEND", b"")


def test_a_huge_texture_is_refused_from_its_header(tmp_path):
    """A 16384 x 16384 PNG gives one ValueError naming the file, its size and the limit, from its header.
    Fails if read_image lets Pillow judge the size (its DecompressionBombError escapes)."""
    from tracer.scenes.images import MAX_IMAGE_TEXELS, image_size, read_image

    (tmp_path / "huge.png").write_bytes(_png_header(16384, 16384))
    (tmp_path / "big.png").write_bytes(_png_header(12000, 12000))  # under Pillow's refusal, over ours
    (tmp_path / "fits.png").write_bytes(_png_header(4000, 3000))
    for name, side in (("huge.png", 16384), ("big.png", 12000)):
        for reader in (read_image, image_size):
            with pytest.raises(ValueError, match=rf"{name}' is {side} x {side} \({side * side:,} texels\); "
                                                 rf"a texture may hold at most {MAX_IMAGE_TEXELS:,} texels"):
                reader(tmp_path / name)
    assert image_size(tmp_path / "fits.png") == (4000, 3000)


def _textured_nff(folder, textures):
    lines = [f"texture t{k} {spec}" for k, spec in enumerate(textures)]
    uses = "".join(f"usetexture t{k}\ns {3 * k} 0 0 1\n" for k in range(len(textures)))
    (folder / "textured.nff").write_text(SCENE_VIEW + "\n".join(lines) + "\nf 1 1 1 1 0 0 0 1\n" + uses)
    return folder / "textured.nff"


def test_a_scene_summary_does_not_make_its_textures(tmp_path, capsys):
    """'coherence scene' on a file with two 1024^2 procedural textures allocates under 1 MB of texels,
    and prints their sizes; fails if the command loads the scene with its texels (25 MB and more)."""
    from analyses.cli import main
    from tracer.scenes.catalog import load

    path = _textured_nff(tmp_path, ["procedural 1024 1024 1", "procedural 1024 512 2"])
    full = load(path).summary()
    assert main(["scene", str(path), "--json"]) == 0  # the command's imports, outside the measurement
    capsys.readouterr()
    tracemalloc.start()
    try:
        assert main(["scene", str(path), "--json"]) == 0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert json.loads(capsys.readouterr().out) == full and full["textures"] == [[1024, 1024], [1024, 512]]
    assert peak < 1 << 20, peak


def test_a_scene_read_without_texels_is_not_rendered_or_written(tmp_path):
    """Fails if a summary-only scene (texels=False) renders or writes its stand-in texels as black."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load
    from tracer.scenes.nff import write_nff

    (tmp_path / "fits.png").write_bytes(_png_header(64, 32))
    scene = load(_textured_nff(tmp_path, ["fits.png", "procedural 16 16 3"]), texels=False)
    assert not scene.texels_read and scene.summary()["textures"] == [[64, 32], [16, 16]]
    with pytest.raises(ValueError, match="read without its texels"):
        render(scene, options=RenderOptions(size=4))
    with pytest.raises(ValueError, match="read without its texels"):
        write_nff(scene, tmp_path / "out.nff")
    assert not (tmp_path / "out.nff").exists()


@pytest.mark.parametrize("command, runs_at_once", [("report", 1), ("paper", 2)])  # the paper maps two scenes at once
def test_the_least_memory_budget_named_is_the_one_the_run_needs(command, runs_at_once):
    """The least --memory-budget the command line names passes both its own check and the run's
    (``memory_shares``), one MB less is refused by the command line, and a budget too big is not told
    to be "at least" anything.

    Fails if ``memory_budget_bytes`` checks against ``MIN_MEMORY_BUDGET`` alone again (it then passes
    704 MB, which the run refuses for any image).
    """
    import re

    from analyses.cli import build_parser
    from analyses.commands.options import memory_budget_bytes
    from analyses.memory_budget import memory_shares

    parser = build_parser()
    for size in (64, 700):
        args = parser.parse_args([command, "--size", str(size), "--memory-budget", "704"])
        with pytest.raises(ValueError, match="--memory-budget must be at least") as refused:
            memory_budget_bytes(args)
        least = int(re.search(r"at least (\d+) MB", str(refused.value)).group(1))
        args.memory_budget = float(least)
        memory_shares(memory_budget_bytes(args), size * size, runs_at_once)
        args.memory_budget = least - 1.0
        with pytest.raises(ValueError, match=f"at least {least} MB"):
            memory_budget_bytes(args)
    for value, said in ((2e12, "at most"), (float("nan"), "a number")):
        args.memory_budget = value
        with pytest.raises(ValueError, match=f"--memory-budget must be {said}"):
            memory_budget_bytes(args)


def test_small_sizes_are_not_told_as_zero_gigabytes(tmp_path, monkeypatch):
    """The disk check names sizes in a unit that shows them: 50,000 bytes needed, 10,000 free.

    Fails if ``check_free_space`` formats both sizes in GB again ("0.0 GB ... 0.0 GB free").
    """
    import re
    import shutil

    from analyses import output

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=10_000))
    with pytest.raises(ValueError) as refused:
        output.check_free_space("the file", tmp_path, 50_000)
    units = {"bytes": 1, "kB": 2**10, "MB": 2**20, "GB": 2**30}
    sizes = [float(number) * units[unit] for number, unit in re.findall(r"([\d.]+) (bytes|kB|MB|GB)", str(refused.value))]
    assert len(sizes) == 2 and abs(sizes[0] - 50_000) < 0.01 * 50_000 and abs(sizes[1] - 10_000) < 0.01 * 10_000


@pytest.mark.parametrize("argv, hint", [(["cachesim", "addresses.txt"], False),
                                        (["report", "tetra", "--size", "8"], True)])
def test_out_of_memory_names_size_only_where_there_is_one(monkeypatch, capsys, argv, hint):
    """A MemoryError suggests a smaller --size only in a command that has --size.

    Fails if the command line's MemoryError message names --size whatever the command again.
    """
    import importlib

    from analyses.cli import main

    def run(args):
        raise MemoryError

    monkeypatch.setattr(importlib.import_module(f"analyses.commands.{argv[0]}"), "run", run)
    assert main(argv) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "out of memory" in said[0] and ("--size" in said[0]) == hint


@pytest.mark.parametrize("error, status", [("input", 2), (ZeroDivisionError("division by zero"), 1),
                                           (TypeError("unsupported operand"), 1), (IndexError("out of range"), 1),
                                           (ValueError("setting an array element with a sequence"), 1)])
def test_user_errors_and_bugs_are_told_apart(monkeypatch, capsys, error, status):
    """An InputError (the toolkit's own check) exits 2 with one line; any other exception is a bug: exit 1,
    its traceback, and a last line that says "internal error" and names it.

    Fails if ``main`` no longer catches ``Exception`` as an internal error (the exception escapes it), or
    takes a bare ValueError (numpy's, a bug's) for the user's again.
    """
    from analyses.cli import main
    from analyses.commands import cachesim
    from rtcommon.validate import InputError

    raised = InputError("--thing must be >= 1, got 0") if error == "input" else error

    def run(args):
        raise raised

    monkeypatch.setattr(cachesim, "run", run)
    assert main(["cachesim", "addresses.txt"]) == status
    said = capsys.readouterr().err.strip().splitlines()
    if status == 2:
        assert said == ["coherence cachesim: error: --thing must be >= 1, got 0"]
    else:
        assert said[0].startswith("Traceback") and f"{type(raised).__name__}: {raised}" in said[-2]
        assert said[-1] == f"coherence cachesim: internal error (a bug in the toolkit, not in what it was given): " \
                           f"{type(raised).__name__}: {raised}"


_LATE_INTERRUPT = textwrap.dedent('''
    import os, signal, sys
    from analyses import cli
    from analyses.commands import cachesim

    class InterruptAtTeardown:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)

    def run(args):
        cachesim.left_over = InterruptAtTeardown()  # lives until Python tears the modules down
        return 0

    cachesim.run = run
    sys.argv = ["coherence", "cachesim", "addresses.txt"]
    sys.exit(cli.main())
''')


def test_a_finished_command_line_leaves_before_pythons_teardown():
    """Once a command has finished, the process ends after the exit handlers, without Python's teardown:
    a Ctrl-C there found no handler and killed the process without a word (a second after a report).

    Fails (the object's SIGINT at teardown kills the process: rc -2) if ``main`` no longer registers
    ``_leave_after_exit_handlers``.
    """
    done = _python(_LATE_INTERRUPT)
    assert (done.returncode, done.stderr) == (0, "")


_LOADING_INTERRUPT = textwrap.dedent('''
    import runpy, signal, sys

    class InterruptWhileLoading:
        """Ctrl-C as the command line imports its interrupt handling."""
        def find_spec(self, name, path=None, target=None):
            if name == "analyses.interrupts" and not hasattr(self, "done"):
                self.done = signal.raise_signal(signal.SIGINT)
            return None

    sys.meta_path.insert(0, InterruptWhileLoading())
    sys.argv = ["coherence", "--version"]
    runpy.run_module("analyses", run_name="__main__", alter_sys=True)
''')


def test_ctrl_c_while_python_m_analyses_loads_prints_one_line():
    """``python -m analyses`` interrupted while it imports the command line prints one line and dies by SIGINT.

    Fails (a KeyboardInterrupt traceback) if ``analyses/__main__.py`` no longer catches KeyboardInterrupt
    around its import of ``analyses.cli``.
    """
    import signal

    done = _python(_LOADING_INTERRUPT)
    assert (done.returncode, done.stderr) == (-signal.SIGINT, "coherence: interrupted\n")


def test_the_toolkit_raises_no_bare_value_error():
    """Every error the toolkit raises for bad input is an InputError, which the command line tells apart
    from a bug's ValueError (exit 2 with one line, not exit 1 with a traceback).

    Fails if any library module raises ``ValueError(...)`` itself, or defines an error class on
    ``ValueError`` rather than ``InputError``, as every check did before.
    """
    import re

    found = []
    for package in ("tracer", "cachesim", "coherence", "analyses", "rtcommon"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"raise ValueError\(|^class (?!InputError\()\w+\(ValueError\)", line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "raise InputError (rtcommon.validate) instead:\n" + "\n".join(found)
