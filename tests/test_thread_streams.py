"""coherence.thread_streams: a static mapping's interleaved stream of hardware threads, and its false sharing."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy
from cachesim.multicore import simulate_threads
from cachesim.multicore_state import FALSE_SHARING_MISSES
from cachesim.sharing import SharedHierarchy
from coherence.layout import get_layout
from coherence.mappings import get_mapping
from coherence.studies import place_layout
from coherence.thread_streams import (COUNTER_BYTES, PRIVATE_KINDS, counter_address, private_span, record_pieces,
                                      record_places, split_records, thread_stream)
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack
from tracer.trace.records import AUXILIARY_KIND

SCENE_KINDS = [RecordKind.KD_NODE, RecordKind.INDEX_ENTRY, RecordKind.SPHERE, RecordKind.MATERIAL]


def synthetic_trace(width, height, seed=0, reads=6):
    """Each pixel reads ``reads`` random scene records, writes and reads its ray stack, hit record and
    shading temporaries (index 0), and writes its own frame-buffer pixel."""
    rng = np.random.default_rng(seed)
    records, lengths = [], []
    for pixel in range(width * height):
        kinds = list(rng.choice(SCENE_KINDS, reads)) + list(PRIVATE_KINDS) * 2 + [RecordKind.FRAME_BUFFER]
        indices = list(rng.integers(0, 50, reads)) + [0] * (2 * len(PRIVATE_KINDS)) + [pixel]
        flags = [False] * reads + [True] * len(PRIVATE_KINDS) + [False] * len(PRIVATE_KINDS) + [True]
        records.append(pack(np.array(kinds), np.array(indices), np.array(flags)))
        lengths.append(len(kinds))
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    counters = np.zeros((width * height, len(COUNTER_NAMES)), dtype=np.int64)
    return AccessTrace(offsets, np.concatenate(records), counters, width, height, {})


def slow_stream(trace, placed, mapping, n_threads, line_size, turn):
    """The stream built by hand: threads take turns of ``turn`` pixels; each record byte by byte."""
    distribution = get_mapping(mapping).build(trace.width, trace.height, n_threads)
    queues = [list(distribution.process_pixels(p)) for p in range(n_threads)]
    accesses = []
    while any(queues):
        for thread, queue in enumerate(queues):
            for pixel in queue[:turn]:
                accesses += slow_pixel(trace, placed, pixel, thread, line_size)
            del queue[:turn]
    return accesses


def slow_pixel(trace, placed, pixel, thread, line_size):
    """One pixel's accesses by ``thread``, each record byte by byte."""
    span = private_span(placed)
    accesses = []
    for record in trace.records[trace.pixel_offsets[pixel]:trace.pixel_offsets[pixel + 1]]:
        kind, index, write = int(record) >> 28, int(record) & ((1 << 27) - 1), bool(int(record) >> 27 & 1)
        row = placed.kind_first[kind] + index
        start = int(placed.record_start[row]) + (span * (thread + 1) if kind in PRIVATE_KINDS else 0)
        byte_lines = [(start + b) // line_size for b in range(int(placed.record_size[row]))]
        for line in sorted(set(byte_lines)):
            first = start + byte_lines.index(line)
            accesses.append((first, thread, write, byte_lines.count(line), kind))
    return accesses


@pytest.mark.parametrize("mapping, n_threads, turn, layout", [("P", 3, 1, "alpha1997"), ("S", 4, 2, "alpha1997"),
                                                               ("B", 2, 5, "compact")])
def test_stream_matches_a_slow_build(mapping, n_threads, turn, layout):
    """Every access (first byte, thread, write flag, size, kind) equals the hand-built stream's.
    Mutation: ``threads + 1`` -> ``threads`` in record_pieces' private offset."""
    trace = synthetic_trace(6, 5, seed=n_threads)
    placed = place_layout(get_layout(layout), trace)
    stream = thread_stream(trace, placed, mapping, n_threads, line_size=32, pixels_per_turn=turn)
    built = list(zip(stream.addresses.tolist(), stream.threads.tolist(), stream.writes.tolist(),
                     stream.sizes.tolist(), stream.kinds.tolist()))
    assert built == slow_stream(trace, placed, mapping, n_threads, 32, turn)


def test_a_record_across_lines_is_split_at_the_line():
    """A 104-byte alpha1997 sphere from byte 40 of a 64-byte line touches 24 + 64 + 16 bytes of three
    lines (hand-checked). Mutation: ``end = ends[record]`` (no clip at the line's end)."""
    trace = synthetic_trace(2, 1)
    placed = place_layout(get_layout("alpha1997"), trace)
    sphere = placed.kind_first[RecordKind.SPHERE]
    start = int(placed.record_start[sphere])
    pieces = record_pieces(pack(RecordKind.SPHERE, 0)[None], np.zeros(1, dtype=np.int64), placed, 64)
    first_line = start - start % 64
    expected_sizes = [first_line + 64 - start]
    rest = 104 - expected_sizes[0]
    while rest > 0:
        expected_sizes.append(min(64, rest))
        rest -= 64
    assert pieces.sizes.tolist() == expected_sizes
    assert pieces.addresses.tolist() == [start] + [first_line + 64 * k for k in range(1, len(expected_sizes))]


def test_a_bad_turn_is_refused():
    """Mutation: drop the require_int of pixels_per_turn in thread_stream."""
    trace = synthetic_trace(4, 4)
    placed = place_layout(get_layout("compact"), trace)
    with pytest.raises(ValueError, match="pixels_per_turn must be"):
        thread_stream(trace, placed, "P", 2, pixels_per_turn=0)


def test_threads_of_another_length_than_the_records_are_refused():
    """Fewer or more thread ids than records: a named error, not a short stream or a read past the end.
    Mutation: drop the shape check in thread_streams._pieces (5 ids for 6 records gave a silent short
    stream)."""
    trace = synthetic_trace(2, 1)
    placed = place_layout(get_layout("compact"), trace)
    records = trace.records[:6]
    for n_ids in (5, 7):
        with pytest.raises(ValueError, match="threads must have one entry per record"):
            record_pieces(records, np.zeros(n_ids, dtype=np.int64), placed, 64)


def test_group_offsets_must_cover_the_records():
    """Mutation: drop the group_offsets check in split_records (offsets ending short of the records)."""
    trace = synthetic_trace(2, 1)
    placed = place_layout(get_layout("compact"), trace)
    records = trace.records[:6]
    places = record_places(records, placed, 64)
    for offsets in ([0, 3, 5], [0, 4, 2, 6], [1, 6]):
        offsets = np.asarray(offsets, dtype=np.int64)
        with pytest.raises(ValueError, match="group_offsets must rise"):
            split_records(records, offsets, np.zeros(offsets.size - 1, dtype=np.int64), places)


def test_p_shares_3_byte_pixels_falsely_more_than_s_at_8_threads():
    """8 threads, 3-byte frame-buffer pixels (alpha1997), private L1 and L2 under a shared L3: P puts
    neighbouring pixels of one line on different threads, S only at the strips' borders, so P's
    false-sharing misses are > 0 and more than S's; per-ray data is private, so no coherence miss
    falls on it. Mutation: give every thread the same private copy (``(threads + 1) * 0``)."""
    trace = synthetic_trace(32, 16, reads=4)
    placed = place_layout(get_layout("alpha1997"), trace)
    hierarchy = Hierarchy((CacheLevel("L1", 4096, 64, 4), CacheLevel("L2", 16384, 64, 8),
                           CacheLevel("L3", 65536, 64, 8)))
    machine = SharedHierarchy(hierarchy, n_cores=8, shared_by=("thread", "thread", "machine"))
    false_sharing = {}
    for mapping in ("P", "S"):
        stream = thread_stream(trace, placed, mapping, 8)
        result = simulate_threads(stream.addresses, stream.threads, machine, writes=stream.writes,
                                  sizes=stream.sizes, kinds=stream.kinds)
        frame = result.to_frame()
        false_sharing[mapping] = int(frame.false_sharing_misses.sum())
        assert frame[frame.kind.isin([int(kind) for kind in PRIVATE_KINDS])].coherence_misses.sum() == 0
    assert false_sharing["P"] > 0 and false_sharing["P"] > false_sharing["S"]


def test_tetra_p_has_false_sharing_and_s_less(tmp_path):
    """Tetra at 16x16 by the study-era workload (alpha1997 layout: 3-byte pixels), 8 threads on the
    modern levels with L1 and L2 private and L3 shared: P's false-sharing misses are > 0 and more
    than S's. Mutation: ``if False:`` for the disjointness test in cachesim.multicore._replay."""
    from analyses.traces import cached_trace
    from cachesim import modern

    scene, trace, _ = cached_trace("tetra", 16, cache_dir=tmp_path, progress=False, workload="study1997")
    placed = place_layout(get_layout("alpha1997"), trace, scene)
    machine = SharedHierarchy(modern(), n_cores=8, shared_by=("thread", "thread", "machine"))
    false_sharing = {mapping: false_sharing_misses(trace, placed, machine, mapping, 8) for mapping in ("P", "S")}
    assert false_sharing["P"] > 0 and false_sharing["P"] > false_sharing["S"]


def false_sharing_misses(trace, placed, machine, mapping, n_threads):
    """False-sharing misses over every level of ``machine`` when ``n_threads`` threads render ``trace``."""
    stream = thread_stream(trace, placed, mapping, n_threads)
    result = simulate_threads(stream.addresses, stream.threads, machine, writes=stream.writes,
                              sizes=stream.sizes, kinds=stream.kinds)
    return int(result.level_counts()[:, FALSE_SHARING_MISSES].sum())


def slow_db_stream(trace, placed, n_threads, line_size, turn):
    """DB's stream built by hand: task k to thread k % n, each task a counter write (its own item) then its
    pixels; each pixel's records as in slow_stream."""
    distribution = get_mapping("DB").build(trace.width, trace.height, n_threads)
    queues = [[] for _ in range(n_threads)]
    for task in range(distribution.n_tasks):
        pixels = distribution.task_pixels[distribution.task_offsets[task]:distribution.task_offsets[task + 1]]
        queues[task % n_threads] += ["counter", *pixels.tolist()]
    accesses = []
    while any(queues):
        for thread, queue in enumerate(queues):
            for item in queue[:turn]:
                if item == "counter":
                    accesses.append((counter_address(placed), thread, True, COUNTER_BYTES, AUXILIARY_KIND))
                    continue
                accesses += slow_pixel(trace, placed, item, thread, line_size)
            del queue[:turn]
    return accesses


@pytest.mark.parametrize("n_threads, turn", [(3, 1), (2, 7)])
def test_db_stream_matches_a_slow_build(n_threads, turn):
    """DB on 96x64 (six 32x32 tasks): every access equals the hand-built stream's, counter writes included.
    Mutation: ``tasks = range(thread, offsets.size - 1, 1)`` in _handed_out (every thread takes every task)."""
    trace = synthetic_trace(96, 64, reads=1)
    placed = place_layout(get_layout("alpha1997"), trace)
    stream = thread_stream(trace, placed, "DB", n_threads, line_size=64, pixels_per_turn=turn)
    built = list(zip(stream.addresses.tolist(), stream.threads.tolist(), stream.writes.tolist(),
                     stream.sizes.tolist(), stream.kinds.tolist()))
    assert built == slow_db_stream(trace, placed, n_threads, 64, turn)


def test_db_counter_traffic_hand_checked():
    """Two threads, four tasks handed out 0, 1, 0, 1, L1 private and large enough to keep every line: the
    counter's line misses cold for each thread's first hand-out, then is lost to the other's write before
    each later one: 2 coherence misses and 3 invalidations at L1 on the auxiliary kind.
    Mutation: ``np.zeros(n, dtype=bool)`` for the counter's writes in thread_stream (reads invalidate nothing)."""
    from cachesim.multicore_state import COHERENCE_INVALIDATIONS, COHERENCE_MISSES

    trace = synthetic_trace(64, 64, reads=1)
    placed = place_layout(get_layout("compact"), trace)
    hierarchy = Hierarchy((CacheLevel("L1", 1 << 20, 64, 16), CacheLevel("L2", 1 << 22, 64, 16)))
    machine = SharedHierarchy(hierarchy, n_cores=2, shared_by=("thread", "machine"))
    stream = thread_stream(trace, placed, "DB", 2, pixels_per_turn=64)
    assert (stream.kinds == AUXILIARY_KIND).sum() == 4
    result = simulate_threads(stream.addresses, stream.threads, machine, writes=stream.writes, sizes=stream.sizes,
                              kinds=stream.kinds)
    counter_l1 = result.counts[0, :, AUXILIARY_KIND].sum(axis=0)
    assert counter_l1[COHERENCE_MISSES] == 2 and counter_l1[COHERENCE_INVALIDATIONS] == 3
