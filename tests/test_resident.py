"""Resident pages of memory-mapped traces: dropped on demand, the data unchanged, and the report's budget."""
import time
from pathlib import Path

import numpy as np
import pytest

from rtcommon.resident import ResidentLimit, drop_pages, mapping_of, resident_file_bytes

linux_only = pytest.mark.skipif(resident_file_bytes() is None, reason="RssFile is read from /proc/self/status")

MB = 1 << 20


@pytest.fixture
def mapped(tmp_path):
    """A 64 MB file of int64 0, 1, 2, ... read through a memory map, and its sum."""
    values = np.arange(8 * MB, dtype=np.int64)
    np.save(tmp_path / "big.npy", values)
    return np.load(tmp_path / "big.npy", mmap_mode="r"), int(values.sum())


def test_mapping_of_finds_the_map_behind_a_view_and_nothing_behind_memory(mapped):
    array, _ = mapped
    assert mapping_of(array) is not None
    assert mapping_of(array[100:5000]) is mapping_of(array)
    assert mapping_of(np.zeros(10)) is None
    assert ResidentLimit([np.zeros(10)], 0).active is False  # nothing to trim: never starts a thread


@linux_only
def test_dropped_pages_leave_the_resident_set_and_read_back_unchanged(mapped):
    array, total = mapped
    before = resident_file_bytes()
    assert int(array.sum()) == total
    touched = resident_file_bytes()
    assert touched - before > 48 * MB  # every page of the 64 MB was read
    drop_pages(mapping_of(array))
    assert touched - resident_file_bytes() > 48 * MB
    assert int(array.sum()) == total  # faulted back in from the file, the same bytes


@linux_only
def test_trim_acts_only_above_the_limit(mapped):
    array, total = mapped
    assert int(array.sum()) == total
    high = ResidentLimit([array], resident_file_bytes() + 256 * MB)
    assert high.trim() is False and high.trims == 0
    low = ResidentLimit([array], 0)
    assert low.trim() is True and low.trims == 1


@linux_only
def test_the_watcher_keeps_a_reader_under_its_limit(mapped):
    # 64 MB read 4 MB at a time against a limit 16 MB above the start: the
    # thread trims while the reader sleeps between pieces.
    array, total = mapped
    start = resident_file_bytes()
    step = MB // 2  # int64 values: 4 MB
    with ResidentLimit([array], start + 16 * MB, interval=0.005) as limit:
        seen = 0
        for first in range(0, array.size, step):
            seen += int(array[first:first + step].sum())
            deadline = time.monotonic() + 1.0
            while resident_file_bytes() - start > 24 * MB and time.monotonic() < deadline:
                time.sleep(0.005)
            assert resident_file_bytes() - start <= 24 * MB
    assert seen == total
    assert limit.trims >= 2
    assert limit._thread is None  # joined on exit


def test_bad_limits_are_refused(mapped):
    array, _ = mapped
    with pytest.raises(ValueError, match="max_bytes"):
        ResidentLimit([array], -1)
    with pytest.raises(ValueError, match="interval"):
        ResidentLimit([array], 0, interval=0)


@linux_only
def test_loading_a_trace_checks_it_without_keeping_it_resident(tmp_path):
    # AccessTrace.load hashes every record; the pages it checked must not stay resident.
    from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack

    rng = np.random.default_rng(3)
    n_pixels, per_pixel = 64 * 64, 3200  # 13.1 M records, 52 MB
    records = pack(np.full(n_pixels * per_pixel, RecordKind.SPHERE), rng.integers(0, 1000, n_pixels * per_pixel))
    offsets = np.arange(n_pixels + 1, dtype=np.int64) * per_pixel
    trace = AccessTrace(offsets, records, np.zeros((n_pixels, len(COUNTER_NAMES)), dtype=np.int64), 64, 64, {})
    trace.save(tmp_path / "trace")
    del AccessTrace.load(tmp_path / "trace", mmap=True).records  # the checking kernel's code is loaded now
    before = resident_file_bytes()
    loaded = AccessTrace.load(tmp_path / "trace", mmap=True)
    assert resident_file_bytes() - before < 24 * MB  # 52 MB read, one 16 MB piece held at a time
    np.testing.assert_array_equal(np.asarray(loaded.records), records)
    assert mapping_of(loaded.counters) is not None  # the per-pixel counters stream from the file too
    np.testing.assert_array_equal(np.asarray(loaded.counters), trace.counters)
    assert AccessTrace.load(tmp_path / "trace", mmap=False).counters.flags.writeable  # in memory when asked


def test_report_memory_shares():
    # The budget is the process's: 640 MB for the process and 96 bytes a
    # pixel for each run at once are set aside, and the rest is split.
    from analyses.memory_budget import DEFAULT_MEMORY_BUDGET, memory_shares

    # 1408 MB left: half for a render's records, then 3/4 for lines (at most 1 GiB) and 1/4 for pages
    assert memory_shares(DEFAULT_MEMORY_BUDGET) == {"render_records": 704 * MB, "shared_lines": 1024 * MB,
                                                    "trace_pages": 352 * MB}
    # 2 runs x 512^2 pixels x 96 bytes = 48 MB: 1360 MB are left
    assert memory_shares(DEFAULT_MEMORY_BUDGET, 512 * 512, 2) == {"render_records": 680 * MB,
                                                                  "shared_lines": 1020 * MB, "trace_pages": 340 * MB}
    assert memory_shares(704 * MB) == {"render_records": 32 * MB, "shared_lines": 48 * MB, "trace_pages": 16 * MB}
    with pytest.raises(ValueError, match="memory_budget"):
        memory_shares(MB)
    # 2048^2 pixels, 2 runs: 640 + 768 MB set aside, and 64 MB for the trace at least
    with pytest.raises(ValueError, match="give at least 1472 MB"):
        memory_shares(1300 * MB, 2048 * 2048, 2)
    assert memory_shares(1472 * MB, 2048 * 2048, 2)["trace_pages"] == 16 * MB


def test_runs_at_once_fit_the_budget():
    # One run per CPU while each leaves the trace its 64 MB: 2048 - 640 - 64 =
    # 1344 MB hold 56 runs of 512^2 pixels (24 MB each) and 2 of 2048^2 (384 MB).
    from analyses.memory_budget import runs_at_once

    assert runs_at_once(2048 * MB, 512 * 512, 64) == 56
    assert runs_at_once(2048 * MB, 512 * 512, 2) == 2
    assert runs_at_once(1536 * MB, 2048 * 2048, 8) == 2
    assert runs_at_once(1200 * MB, 2048 * 2048, 2) == 1
    assert runs_at_once(700 * MB, 2048 * 2048, 2) == 1  # memory_shares says it does not fit
    assert runs_at_once(700 * MB, 0, 3) == 3


def _synthetic_trace(folder, size):
    from tracer.trace.records import RecordKind, pack
    from tracer.trace.access import COUNTER_NAMES, AccessTrace

    rng = np.random.default_rng(size)
    kinds = np.array([RecordKind.KD_NODE, RecordKind.SPHERE, RecordKind.MATERIAL], dtype=np.int64)
    n_pixels = size * size
    records = pack(rng.choice(kinds, n_pixels), rng.integers(0, 40, n_pixels), np.zeros(n_pixels, dtype=bool))
    counters = rng.integers(0, 50, (n_pixels, len(COUNTER_NAMES))).astype(np.int64)
    trace = AccessTrace(np.arange(n_pixels + 1, dtype=np.int64), records, counters, size, size,
                        {"record_counts": {"kd_node": 40, "sphere": 40, "material": 40}})
    return AccessTrace.load(trace.save(Path(folder) / "trace"), mmap=True)


@pytest.mark.jit_only
def test_a_run_takes_at_most_its_bytes_per_pixel(tmp_path):
    # RUN_BYTES_PER_PIXEL is what memory_shares sets aside for each run at
    # once; measured here as the growth of a one-job study's traced peak
    # (numpy's arrays included) between two image sizes, so that fixed
    # costs (caches per CPU) cancel, over every default mapping.
    import tracemalloc

    from analyses.memory_budget import RUN_BYTES_PER_PIXEL
    from coherence.mappings import DEFAULT_MAPPINGS
    from coherence.studies import Execution, study

    peaks = {}
    for size in (128, 384):
        trace = _synthetic_trace(tmp_path / str(size), size)
        study(trace, ["S"], [2], progress=False, execution=Execution(n_jobs=1))  # compiled outside the measure
        for mapping in DEFAULT_MAPPINGS:
            tracemalloc.start()
            study(trace, [mapping], [8], progress=False, execution=Execution(n_jobs=1))
            peaks[mapping, size] = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        del trace
    for mapping in DEFAULT_MAPPINGS:
        per_pixel = (peaks[mapping, 384] - peaks[mapping, 128]) / (384 ** 2 - 128 ** 2)
        assert 8 < per_pixel <= RUN_BYTES_PER_PIXEL, (mapping, per_pixel)
