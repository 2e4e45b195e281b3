"""The trace format's compiled accessors against the numpy pack/unpack."""
import numpy as np
from numba import njit

from tracer.trace.records import (AUX_INDEX_MASK, AUXILIARY_KIND, COUNTER_NAMES, INDEX_MASK, N_AUX_KINDS, AuxKind,
                                  Counter, RecordKind, aux_index, aux_kind, make_aux_record, make_record, pack,
                                  pack_aux, record_id, record_kind, unpack, unpack_aux)


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


@njit
def _aux_roundtrip(subs, indices, writes, out_records, out_subs, out_ids, out_kinds):
    for i in range(subs.shape[0]):
        out_records[i] = make_aux_record(subs[i], indices[i], writes[i])
        out_subs[i] = aux_kind(out_records[i])
        out_ids[i] = aux_index(out_records[i])
        out_kinds[i] = record_kind(out_records[i])


def test_auxiliary_records_round_trip_against_plain_bit_arithmetic():
    """Compiled and numpy auxiliary pack/unpack agree with plain-Python shifts on seeded random values
    (bits 31-28 kind 15, bit 27 write, bits 26-24 sub-kind, bits 23-0 index). Fails if
    ``AUX_KIND_SHIFT`` becomes 23 (or make_aux_record drops the write flag)."""
    rng = np.random.default_rng(31)
    n = 500
    subs = rng.integers(0, N_AUX_KINDS, n)
    indices = rng.integers(0, AUX_INDEX_MASK + 1, n)
    indices[:2] = (0, AUX_INDEX_MASK)
    writes = rng.integers(0, 2, n).astype(np.bool_)
    expected = [(15 << 28) | (int(w) << 27) | (int(s) << 24) | int(i) for s, i, w in zip(subs, indices, writes)]
    records = np.empty(n, np.uint32)
    out_subs, out_ids, out_kinds = (np.empty(n, np.int64) for _ in range(3))
    _aux_roundtrip(subs, indices, writes, records, out_subs, out_ids, out_kinds)
    assert records.tolist() == expected
    assert pack_aux(subs, indices, writes).tolist() == expected
    np.testing.assert_array_equal(out_subs, subs)
    np.testing.assert_array_equal(out_ids, indices)
    assert set(out_kinds.tolist()) == {AUXILIARY_KIND}
    s, i = unpack_aux(records)
    assert s.tolist() == [int(r) >> 24 & 7 for r in expected]
    assert i.tolist() == [int(r) & 0xFFFFFF for r in expected]


def test_auxiliary_plan_and_bad_values():
    """The plan's names hold their values and bad input is refused. Fails if ``AuxKind.QUEUE_ENTRY``
    is renumbered or pack_aux stops checking its index."""
    import pytest

    assert AUXILIARY_KIND == 15 and AUXILIARY_KIND not in set(RecordKind)
    assert [int(k) for k in AuxKind] == [0, 1, 2] and N_AUX_KINDS == 8
    assert make_aux_record(AuxKind.QUEUE_ENTRY, 5, False) == 0xF000_0000 | (2 << 24) | 5
    with pytest.raises(ValueError, match="index"):
        pack_aux(0, AUX_INDEX_MASK + 1)
    with pytest.raises(ValueError, match="aux_kind"):
        pack_aux(8, 0)
    with pytest.raises(ValueError, match="auxiliary"):
        unpack_aux(pack(RecordKind.LIGHT, 1))


def test_version_3_trace_still_loads(tmp_path):
    """A trace written as version 3 (what a trace without segments still is) loads, and a version this
    code does not read is refused by name. Fails if READABLE_VERSIONS drops 3."""
    import json

    import pytest
    import xxhash

    from tests.trace_factory import random_trace
    from tracer.trace.access import AccessTrace

    trace = random_trace()
    path = trace.save(tmp_path / "t")
    assert json.loads((path / "meta.json").read_text())["format_version"] == 3
    back = AccessTrace.load(path)
    np.testing.assert_array_equal(back.records, trace.records)
    meta = json.loads((path / "meta.json").read_text())
    meta["format_version"] = 2
    data = json.dumps(meta).encode()
    (path / "meta.json").write_bytes(data)
    (path / "meta.json.xxh3").write_text(xxhash.xxh3_64_hexdigest(data) + "\n")
    with pytest.raises(ValueError, match="format_version 2"):
        AccessTrace.load(path)
