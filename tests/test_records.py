"""The trace format's compiled accessors against the numpy pack/unpack."""
import numpy as np
from numba import njit

from tracer.trace.records import COUNTER_NAMES, INDEX_MASK, Counter, RecordKind, make_record, pack, record_id, record_kind, unpack


@njit
def _roundtrip(kinds, indices, out_records, out_kinds, out_ids):
    for i in range(kinds.shape[0]):
        out_records[i] = make_record(kinds[i], indices[i])
        out_kinds[i] = record_kind(out_records[i])
        out_ids[i] = record_id(out_records[i])


def test_compiled_accessors_match_pack_and_unpack():
    rng = np.random.default_rng(7)
    kinds = rng.integers(0, len(RecordKind), 1000)
    indices = rng.integers(0, INDEX_MASK + 1, 1000)
    indices[:2] = (0, INDEX_MASK)
    records = np.empty(1000, np.uint32)
    out_kinds = np.empty(1000, np.int64)
    out_ids = np.empty(1000, np.int64)
    _roundtrip(kinds, indices, records, out_kinds, out_ids)
    np.testing.assert_array_equal(records, pack(kinds, indices))
    k, i = unpack(records)
    np.testing.assert_array_equal(out_kinds, k)
    np.testing.assert_array_equal(out_ids, i)


def test_hand_packed_records():
    assert make_record(RecordKind.LIGHT, 5) == (8 << 28) + 5
    assert record_kind(np.uint32(0x7000_0003)) == RecordKind.MATERIAL
    assert record_id(np.uint32(0x7000_0003)) == 3


def test_counter_names_name_what_their_columns_count():
    """Each name of the counter columns, looked up in a real render's totals, counts what it says:
    one primary ray per pixel, and the records of the kind it counts. Fails when two names of
    ``COUNTER_NAMES`` trade places (e.g. ``tuple(reversed(...))`` or a swapped pair)."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    trace = render(load("tetra"), options=RenderOptions(size=8)).trace
    totals = trace.totals()
    kinds, _ = unpack(trace.records)
    assert totals["primary_rays"] == 64
    for kind, name in (("KD_NODE", "node_visits"), ("INDEX_ENTRY", "index_reads"),
                       ("TRIANGLE", "tests_triangle"), ("MATERIAL", "shading"), ("LIGHT", "light_reads")):
        assert totals[name] == np.count_nonzero(kinds == RecordKind[kind]), name
    assert totals["tests_sphere"] == 0


def test_every_kind_has_its_counter():
    from tracer.trace.records import COUNTER_OF_KIND

    assert set(COUNTER_OF_KIND) == set(RecordKind)
    assert len(set(COUNTER_OF_KIND.values())) == len(RecordKind)
    assert all(name in COUNTER_NAMES for name in COUNTER_OF_KIND.values())


def test_write_flag_round_trips_and_leaves_kind_and_id_alone():
    from tracer.trace.records import WRITE_FLAG, make_write_record, record_is_write

    kinds = np.array([0, 3, 8, 8])
    ids = np.array([0, 5, INDEX_MASK, 12])
    writes = np.array([False, True, True, False])
    packed = pack(kinds, ids, writes)
    assert np.array_equal((packed & np.uint32(WRITE_FLAG)) != 0, writes)
    back_kinds, back_ids = unpack(packed)
    assert np.array_equal(back_kinds, kinds) and np.array_equal(back_ids, ids)
    for record, kind, index, write in zip(packed, kinds, ids, writes):
        assert record_kind(record) == kind and record_id(record) == index
        assert record_is_write(record) == write
    assert make_write_record(3, 5) == packed[1]
    assert make_record(3, 5) == pack(3, 5)
