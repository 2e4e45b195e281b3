"""The compiled simulator against hand-checked cases and the slow reference."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cachesim import CacheLevel, CacheState, Hierarchy, alpha21164, modern, simulate, simulate_many
from reference_cache import reference_simulate


def one_level(size, line_size, assoc, policy="lru"):
    return Hierarchy((CacheLevel("L1", size, line_size, assoc, policy),))


def counts_of(result):
    return result.counts.tolist()


# --- hand-checked cases ------------------------------------------------------

def test_direct_mapped_conflict_by_hand():
    # 4 lines of 16 B, direct-mapped: addresses 0 and 64 share set 0.
    hierarchy = one_level(64, 16, 1)
    result = simulate([0, 4, 64, 0, 16, 80, 16], hierarchy, return_levels=True)
    # 0 miss, 4 hit (same line), 64 miss (evicts 0), 0 miss (evicts 64),
    # 16 miss, 80 miss (evicts 16), 16 miss.
    assert result.hits.tolist() == [1]
    assert result.misses.tolist() == [6]
    assert result.evictions.tolist() == [4]
    assert result.served_by.tolist() == [1, 0, 1, 1, 1, 1, 1]


def test_lru_and_fifo_differ_by_hand():
    # One set of two ways: A B A C A. LRU evicts B for C and hits A twice;
    # FIFO evicts A (first in) for C, so the last A misses.
    stream = [0, 32, 0, 64, 0]
    lru = simulate(stream, one_level(64, 32, 2, "lru"))
    fifo = simulate(stream, one_level(64, 32, 2, "fifo"))
    assert lru.hits.tolist() == [2]
    assert fifo.hits.tolist() == [1]


def test_two_levels_only_misses_go_down_by_hand():
    hierarchy = Hierarchy((CacheLevel("L1", 64, 32, 1), CacheLevel("L2", 256, 64, 1)))
    # 0 misses both; 32 misses L1 (other L1 line) but hits L2 (same 64 B line);
    # 0 hits L1 again? No: 0 and 32 are different L1 sets (2 sets), so 0 hits.
    result = simulate([0, 32, 0, 256], hierarchy, return_levels=True)
    assert result.accesses.tolist() == [4, 3]
    assert result.hits.tolist() == [1, 1]
    assert result.served_by.tolist() == [2, 1, 0, 2]


def test_non_power_of_two_sets_by_hand():
    # 3 sets of one way, 16 B lines: lines 0, 3, 6 all map to set 0.
    hierarchy = one_level(48, 16, 1)
    assert hierarchy.levels[0].n_sets == 3
    result = simulate([0, 48, 0, 16, 32, 16], hierarchy)
    assert result.hits.tolist() == [1]  # only the final 16


def test_inclusive_back_invalidation_by_hand():
    # L2 holds one 64 B line; L1 two 32 B lines. Filling L2 with a new line
    # must remove both halves of the old one from L1.
    hierarchy = Hierarchy(
        (CacheLevel("L1", 64, 32, "full"), CacheLevel("L2", 64, 64, 1)), inclusion="inclusive")
    result = simulate([0, 32, 64, 0], hierarchy, return_levels=True)
    # 0: miss/miss; 32: L1 miss, L2 hit; 64: miss/miss, L2 evicts line 0 ->
    # L1 lines 0 and 1 invalidated; 0: misses L1 and L2 again, and L2 evicting
    # line 1 (bytes 64..127) invalidates L1 line 2: three invalidations.
    assert result.served_by.tolist() == [2, 1, 2, 2]
    assert result.invalidations.tolist() == [3, 0]
    # 0, 32, 64, 32: after 64, a non-inclusive L1 still holds bytes 32..63
    # (LRU evicted line 0 only); an inclusive one lost both halves.
    stream = [0, 32, 64, 32]
    assert simulate(stream, hierarchy, return_levels=True).served_by.tolist() == [2, 1, 2, 2]
    non_inclusive = Hierarchy(hierarchy.levels)
    assert simulate(stream, non_inclusive, return_levels=True).served_by.tolist() == [2, 1, 2, 0]


def test_exclusive_moves_lines_by_hand():
    hierarchy = Hierarchy(
        (CacheLevel("L1", 32, 32, 1), CacheLevel("L2", 32, 32, 1)), inclusion="exclusive")
    # A (miss: L1=A), B (miss: L1=B, A -> L2), A (L2 hit: A up, B down), B (L2 hit)
    result = simulate([0, 32, 0, 32], hierarchy, return_levels=True)
    assert result.served_by.tolist() == [2, 2, 1, 1]
    state = result.state
    assert state.resident_lines("L1").tolist() == [1]
    assert state.resident_lines("L2").tolist() == [0]


# --- against the slow reference ---------------------------------------------

def adversarial_streams(rng, line_size, capacity_lines, n_sets):
    n = 3000
    yield "uniform", rng.integers(0, 8 * capacity_lines * line_size, n)
    yield "one line repeated", np.full(n, 12345)
    yield "same set stride", (np.arange(n) % (3 * capacity_lines)) * n_sets * line_size
    for factor in (0.9, 1.0, 1.1):
        lines = max(1, int(capacity_lines * factor))
        yield f"cyclic working set x{factor}", (np.arange(n) % lines) * line_size
    yield "above 2**32", (1 << 40) + rng.integers(0, 4 * capacity_lines * line_size, n)
    yield "near 2**64", np.uint64(2**64 - 2**20) + rng.integers(0, 2**19, n).astype(np.uint64)
    hot = rng.integers(0, capacity_lines * line_size // 2, n)
    cold = rng.integers(0, 64 * capacity_lines * line_size, n)
    yield "hot and cold mix", np.where(rng.random(n) < 0.8, hot, cold)


GEOMETRIES = [
    # (size, line_size, assoc)
    (1024, 32, 1),
    (96 * 32, 32, 3),       # 32 sets
    (3 * 5 * 16, 16, 5),    # 3 sets of 5 ways
    (512, 64, "full"),
    (6 * 64 * 2, 64, 2),    # 6 sets
]


@pytest.mark.parametrize("policy", ["lru", "fifo", "random"])
@pytest.mark.parametrize("geometry", GEOMETRIES, ids=str)
def test_single_level_matches_reference(policy, geometry):
    size, line_size, assoc = geometry
    hierarchy = Hierarchy((CacheLevel("L1", size, line_size, assoc, policy, seed=7),))
    level = hierarchy.levels[0]
    rng = np.random.default_rng(1)
    for name, stream in adversarial_streams(rng, line_size, level.n_lines, level.n_sets):
        stream = np.asarray(stream).astype(np.uint64)
        result = simulate(stream, hierarchy, return_levels=True)
        counts, served = reference_simulate(stream, hierarchy)
        assert counts_of(result) == counts.tolist(), name
        assert result.served_by.tolist() == served, name


def three_level(inclusion, policies=("lru", "lru", "lru")):
    line_sizes = (32, 64, 64) if inclusion != "exclusive" else (32, 32, 32)
    return Hierarchy((
        CacheLevel("L1", 256, line_sizes[0], 1, policies[0], seed=1),
        CacheLevel("L2", 3 * 4 * line_sizes[1], line_sizes[1], 3, policies[1], seed=2),
        CacheLevel("L3", 4096, line_sizes[2], 2, policies[2], seed=3),
    ), inclusion=inclusion, memory_latency=50)


@pytest.mark.parametrize("inclusion", ["non-inclusive", "inclusive", "exclusive"])
@pytest.mark.parametrize("policies", [("lru", "lru", "lru"), ("fifo", "random", "lru"),
                                      ("random", "fifo", "fifo")], ids=str)
def test_hierarchy_matches_reference(inclusion, policies):
    hierarchy = three_level(inclusion, policies)
    rng = np.random.default_rng(2)
    for name, stream in adversarial_streams(rng, 32, 8, 8):
        stream = np.asarray(stream).astype(np.uint64)
        result = simulate(stream, hierarchy, return_levels=True)
        counts, served = reference_simulate(stream, hierarchy)
        assert counts_of(result) == counts.tolist(), name
        assert result.served_by.tolist() == served, name


@settings(max_examples=60, deadline=None)
@given(
    stream=st.lists(st.integers(0, 4095), max_size=200),
    inclusion=st.sampled_from(["non-inclusive", "inclusive", "exclusive"]),
    policy=st.sampled_from(["lru", "fifo", "random"]),
)
def test_property_matches_reference(stream, inclusion, policy):
    hierarchy = three_level(inclusion, (policy, policy, policy))
    result = simulate(np.array(stream, dtype=np.uint64), hierarchy)
    counts, _ = reference_simulate(stream, hierarchy)
    assert counts_of(result) == counts.tolist()


def test_inclusive_lower_level_smaller_than_upper_matches_reference():
    # Allowed (what-if grids reach it): back-invalidation caps the upper level.
    hierarchy = Hierarchy((CacheLevel("L1", 512, 32, 2), CacheLevel("L2", 256, 64, 2)), inclusion="inclusive")
    stream = np.random.default_rng(23).integers(0, 4096, 3000).astype(np.uint64)
    result = simulate(stream, hierarchy)
    counts, _ = reference_simulate(stream, hierarchy)
    assert counts_of(result) == counts.tolist()
    assert result.invalidations[0] > 0
    assert len(result.state.resident_lines("L1")) <= 2 * len(result.state.resident_lines("L2"))


def test_alpha_preset_matches_reference_on_a_local_stream():
    rng = np.random.default_rng(3)
    stream = np.cumsum(rng.integers(-2048, 2100, 20000)) + 10**9
    stream = stream.astype(np.uint64)
    result = simulate(stream, alpha21164())
    counts, _ = reference_simulate(stream, alpha21164())
    assert counts_of(result) == counts.tolist()


# --- state: continue, clone, reset, many ------------------------------------

def random_stream(seed, n=5000, span=1 << 16):
    return np.random.default_rng(seed).integers(0, span, n).astype(np.uint64)


@pytest.mark.parametrize("inclusion", ["non-inclusive", "inclusive", "exclusive"])
def test_pieces_on_one_state_equal_one_run(inclusion):
    hierarchy = three_level(inclusion, ("lru", "random", "fifo"))
    stream = random_stream(4)
    whole = simulate(stream, hierarchy)
    state = CacheState(hierarchy)
    pieces = [simulate(piece, state) for piece in np.array_split(stream, [1, 700, 701, 3000])]
    assert sum(piece.counts for piece in pieces).tolist() == whole.counts.tolist()
    assert state.totals().counts.tolist() == whole.counts.tolist()
    assert np.array_equal(state.tags, whole.state.tags)


def test_copy_is_independent_and_reset_empties():
    hierarchy = alpha21164()
    state = simulate(random_stream(5), hierarchy).state
    clone = state.copy()
    follow = random_stream(6)
    a = simulate(follow, state)
    b = simulate(follow, clone)
    assert a.counts.tolist() == b.counts.tolist()
    simulate(random_stream(7), state)
    assert not np.array_equal(state.counts, clone.counts)
    state.reset()
    assert state.counts.sum() == 0 and (state.tags == -1).all()
    assert simulate(follow, state).counts.tolist() == simulate(follow, hierarchy).counts.tolist()


def test_simulate_many_equals_one_by_one():
    hierarchy = three_level("inclusive", ("lru", "random", "lru"))
    streams = [random_stream(seed, n=1000 * (seed + 1)) for seed in range(5)] + [np.zeros(0, np.uint64)]
    many = simulate_many(streams, hierarchy, return_levels=True)
    for stream, result in zip(streams, many):
        alone = simulate(stream, hierarchy, return_levels=True)
        assert result.counts.tolist() == alone.counts.tolist()
        assert np.array_equal(result.served_by, alone.served_by)
    # continuing the states equals continuing single runs
    again = simulate_many(streams, states=[result.state for result in many])
    for stream, result in zip(streams, again):
        state = simulate(stream, hierarchy).state
        assert result.counts.tolist() == simulate(stream, state).counts.tolist()


def test_served_by_agrees_with_counts():
    hierarchy = modern()
    result = simulate(random_stream(8, n=20000, span=1 << 26), hierarchy, return_levels=True)
    served = np.bincount(result.served_by, minlength=4)
    assert served[:3].tolist() == result.hits.tolist()
    assert served[3] == result.memory_accesses
    assert result.accesses[1:].tolist() == result.misses[:-1].tolist()


def test_frame_and_dict_carry_the_same_numbers():
    result = simulate(random_stream(9), alpha21164())
    frame = result.to_frame()
    assert list(frame.columns) == ["level", "size", "line_size", "ways", "accesses", "hits", "misses",
                                   "evictions", "invalidations", "hit_rate", "write_accesses",
                                   "write_hits", "write_misses"]
    assert frame["hits"].tolist() == result.hits.tolist()
    data = result.to_dict()
    assert [row["misses"] for row in data["levels"]] == result.misses.tolist()
    assert data["hierarchy"]["name"] == "alpha21164"


# --- bad input ---------------------------------------------------------------

def test_empty_stream_gives_zero_counts():
    result = simulate(np.zeros(0, dtype=np.uint64), alpha21164())
    assert result.counts.sum() == 0
    assert simulate([], alpha21164()).counts.sum() == 0


@pytest.mark.parametrize("bad, message", [
    ([1, -2, 3], "non-negative"),
    (np.array([1.0, 2.0]), "integers"),
    (np.array([True, False]), "integers"),
    (["a", "b"], "integers"),
    ([2**64], "below 2\\*\\*64"),
    (np.zeros((2, 2), dtype=np.int64), "one-dimensional"),
])
def test_bad_addresses_are_rejected(bad, message):
    with pytest.raises(ValueError, match=message):
        simulate(bad, alpha21164())


def test_unrolled_three_way_search_equals_the_loop():
    # The level-by-level path searches a three-way set with branch-free
    # masks; it must pick the same hit and victim as the loop (first empty
    # way, else the oldest stamp, ties to the lower way) on sets with empty
    # ways, tied stamps and the line absent or present.
    from cachesim.by_level import _search_three_ways, _search_ways

    rng = np.random.default_rng(8)
    for _ in range(3000):
        tags = rng.integers(-1, 4, 9).astype(np.int64)
        stamps = rng.integers(0, 3, 9).astype(np.int64)
        base = int(rng.integers(0, 3)) * 3
        line = np.int64(rng.integers(0, 4))
        held = list(tags[base:base + 3])
        if held.count(line) > 1:  # a set never holds a line twice
            continue
        expected_hit = base + held.index(line) if line in held else -1
        ages = [stamps[base + way] if held[way] >= 0 else -1 for way in range(3)]
        expected_victim = base + ages.index(min(ages))
        assert _search_ways(tags, stamps, base, 3, line) == (expected_hit, expected_victim)
        assert _search_three_ways(tags, stamps, base, line) == (expected_hit, expected_victim)


@pytest.mark.parametrize("policies", [("lru", "lru", "lru"), ("fifo", "random", "lru"), ("random", "fifo", "fifo")])
def test_level_by_level_path_equals_access_by_access_path(policies):
    # Non-inclusive hierarchies run level by level in chunks; the general path
    # walks each access down. Both must leave identical contents, counts and
    # served_by, across several chunks and with runs of one line.
    from cachesim import kernels as K

    hierarchy = Hierarchy((
        CacheLevel("L1", 256, 16, 2, policies[0]),
        CacheLevel("L2", 1536, 32, 3, policies[1]),
        CacheLevel("L3", 8192, 64, 1 if policies[2] == "lru" else 4, policies[2]),
    ))
    rng = np.random.default_rng(21)
    walk = np.cumsum(rng.integers(-200, 210, 3 * K.CHUNK + 123)) + (1 << 33)
    stream = np.repeat(walk, rng.integers(1, 4, walk.size)).astype(np.uint64)
    outputs = []
    from cachesim.by_access import _simulate_by_access
    from cachesim.by_level import _simulate_by_level

    no_writes = np.zeros(0, dtype=np.bool_)
    work = K.chunk_buffers()
    for buffer in work:
        buffer[:] = 12345  # left over from an earlier call: every kernel must start its counts afresh
    for kernel in (_simulate_by_level, _simulate_by_access):
        state = CacheState(hierarchy)
        served_by = np.zeros(stream.size, dtype=np.uint8)
        if kernel is _simulate_by_level:
            clock = kernel(stream, state.geometry, state.arrays, 5, served_by, True, work)
        else:
            clock = kernel(stream, no_writes, state.geometry, state.arrays, 5, served_by, True, work)
        outputs.append((clock, state.tags.copy(), state.stamps.copy(), state.counts.copy(), served_by))
    (clock_a, tags_a, stamps_a, counts_a, served_a), (clock_b, tags_b, stamps_b, counts_b, served_b) = outputs
    assert clock_a == clock_b == 5 + stream.size
    np.testing.assert_array_equal(tags_a, tags_b)
    # Without served_by, a direct-mapped last level only counts its misses.
    unrecorded = CacheState(hierarchy)
    _simulate_by_level(stream, unrecorded.geometry, unrecorded.arrays, 5, np.zeros(0, dtype=np.uint8), False, work)
    np.testing.assert_array_equal(unrecorded.tags, tags_b)
    np.testing.assert_array_equal(unrecorded.counts, counts_b)
    # Stamps order the ways of a set; a direct-mapped level has none to order
    # and the level-by-level path leaves its stamps alone.
    associative = np.concatenate([np.arange(start, start + ways * sets) for start, ways, sets, in zip(
        state.geometry.offset, state.geometry.ways, state.geometry.n_sets) if ways > 1])
    np.testing.assert_array_equal(stamps_a[associative], stamps_b[associative])
    np.testing.assert_array_equal(counts_a, counts_b)
    np.testing.assert_array_equal(served_a, served_b)
