"""Resident pages of memory-mapped traces: dropped on demand, the data unchanged, and the report's budget."""
import time

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
    from tracer.trace import COUNTER_NAMES, AccessTrace, RecordKind, pack

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
    from analyses.memory_budget import DEFAULT_MEMORY_BUDGET, memory_shares
    from coherence.pixel_lines import SHARED_LINES_BUDGET

    assert memory_shares(DEFAULT_MEMORY_BUDGET) == {"render_records": 1 << 30, "shared_lines": SHARED_LINES_BUDGET,
                                                    "trace_pages": 512 * MB}
    assert memory_shares(256 * MB) == {"render_records": 128 * MB, "shared_lines": 128 * MB, "trace_pages": 64 * MB}
    with pytest.raises(ValueError, match="memory_budget"):
        memory_shares(MB)
