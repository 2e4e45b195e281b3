"""Reliability of the trace cache: damaged or unverifiable entries, and leftovers of dead runs."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import xxhash

from analyses import traces
from rtcommon.files import remove_stale_temporaries, temp_prefix, write_files_atomic
from reliability_files import flip


# ----------------------------------------------------------------- trace cache
def test_cache_entry_with_a_flipped_byte_is_evicted_and_rebuilt(tmp_path):
    _, trace, info = traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)
    fresh = np.array(trace.records)
    del trace
    entry = Path(info["path"])
    assert entry.parent == tmp_path / "traces"
    flip(entry / "trace" / "records.npy", 7)
    with pytest.warns(UserWarning, match=r"damaged trace cache entry .*records\.npy.*rendering again"):
        _, again, info2 = traces.cached_trace("tetra", 12, cache_dir=tmp_path, progress=False)
    assert not info2["cached"] and np.array_equal(np.asarray(again.records), fresh)
    flip(entry / "image.png", 40)
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
