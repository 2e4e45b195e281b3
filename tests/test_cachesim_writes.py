"""Writes: hand-checked cases and the slow reference on seeded random streams."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cachesim import CacheLevel, CacheState, Hierarchy, alpha21164, alpha21164_noninclusive, simulate, simulate_many
from reference_cache import reference_simulate


def two_level(inclusion="non-inclusive", allocate_l1=False, policy="lru"):
    return Hierarchy((
        CacheLevel("L1", 64, 32, 1, policy, write_allocate=allocate_l1),
        CacheLevel("L2", 256, 64, 2, policy),
    ), inclusion=inclusion)


# --- hand-checked cases ------------------------------------------------------

def test_write_miss_does_not_allocate_in_a_write_through_level_by_hand():
    # L1: two 32 B lines, no write-allocate; L2: write-allocate.
    # write 0: misses L1 and L2; L2 takes line 0, L1 stays empty.
    # read 0: misses L1 (nothing was allocated), hits L2, fills L1.
    # write 0: hits L1.
    result = simulate([0, 0, 0], two_level(), writes=[True, False, True], return_levels=True)
    assert result.served_by.tolist() == [2, 1, 0]
    assert result.accesses.tolist() == [3, 2]
    assert result.hits.tolist() == [1, 1]
    assert result.write_accesses.tolist() == [2, 1]
    assert result.write_hits.tolist() == [1, 0]
    assert result.write_misses.tolist() == [1, 1]
    assert result.read_accesses.tolist() == [1, 1]
    assert result.read_hits.tolist() == [0, 1]
    assert result.state.resident_lines("L1").tolist() == [0]


def test_write_miss_allocates_in_a_write_allocate_level_by_hand():
    # Same stream with an L1 that allocates on writes: the read hits L1.
    result = simulate([0, 0, 0], two_level(allocate_l1=True), writes=[True, False, True], return_levels=True)
    assert result.served_by.tolist() == [2, 0, 0]
    assert result.write_hits.tolist() == [1, 0]


def test_repeated_writes_to_one_line_all_miss_a_no_allocate_level_by_hand():
    # The "repeat of the previous line" shortcut must not count these as hits.
    result = simulate([8, 8, 8, 16], two_level(), writes=[True, True, True, True], return_levels=True)
    assert result.served_by.tolist() == [2, 1, 1, 1]
    assert result.hits.tolist() == [0, 3]


def test_a_write_hit_updates_lru_recency_by_hand():
    # L2: 256 B, 2 ways of 64 B -> 2 sets; addresses 0, 128, 256 share L2 set 0
    # (and L1 set 0, so L1 keeps only the last line read). After read 0, read
    # 128, write 0, the write has made line 0 the more recent in L2, so read
    # 256 evicts 128; without the recency update it would evict 0.
    hierarchy = two_level()
    result = simulate([0, 128, 0, 256, 0, 128], hierarchy, writes=[False, False, True, False, False, False],
                      return_levels=True)
    # 0 read: mem; 128 read: mem (L1 evicts 0); 0 write: L1 miss, L2 hit (recency);
    # 256 read: mem, L2 evicts 128; 0 read: L2 hit; 128 read: memory again.
    assert result.served_by.tolist() == [2, 2, 1, 2, 1, 2]


def test_inclusive_write_keeps_upper_levels_a_subset_by_hand():
    # L2 holds one 64 B line; L1 two 32 B lines, no write-allocate.
    hierarchy = Hierarchy((CacheLevel("L1", 64, 32, "full", write_allocate=False),
                           CacheLevel("L2", 64, 64, 1)), inclusion="inclusive")
    # read 0 (L1 and L2 take it), write 64 (L2 takes line 1, evicting line 0:
    # L1's copy of bytes 0..31 is invalidated; L1 takes nothing), read 0: memory.
    result = simulate([0, 64, 0], hierarchy, writes=[False, True, False], return_levels=True)
    assert result.served_by.tolist() == [2, 2, 2]
    assert result.invalidations.tolist() == [1, 0]


def test_all_false_writes_equal_no_writes():
    rng = np.random.default_rng(5)
    stream = rng.integers(0, 1 << 16, 5000).astype(np.uint64)
    for hierarchy in (alpha21164(), alpha21164_noninclusive()):
        plain = simulate(stream, hierarchy, return_levels=True)
        flagged = simulate(stream, hierarchy, writes=np.zeros(stream.size, dtype=bool), return_levels=True)
        assert plain.counts.tolist() == flagged.counts.tolist()
        assert np.array_equal(plain.served_by, flagged.served_by)
        assert np.array_equal(plain.state.tags, flagged.state.tags)


# --- against the slow reference ---------------------------------------------

def three_level(inclusion, policies, allocate):
    line_sizes = (32, 64, 64) if inclusion != "exclusive" else (32, 32, 32)
    return Hierarchy((
        CacheLevel("L1", 256, line_sizes[0], 1, policies[0], seed=1, write_allocate=allocate[0]),
        CacheLevel("L2", 3 * 4 * line_sizes[1], line_sizes[1], 3, policies[1], seed=2, write_allocate=allocate[1]),
        CacheLevel("L3", 4096, line_sizes[2], 2, policies[2], seed=3, write_allocate=allocate[2]),
    ), inclusion=inclusion, memory_latency=50)


CASES = [
    ("non-inclusive", ("lru", "lru", "lru"), (False, True, True)),
    ("non-inclusive", ("fifo", "random", "lru"), (True, False, True)),
    ("non-inclusive", ("lru", "lru", "fifo"), (False, False, False)),
    ("inclusive", ("lru", "lru", "lru"), (False, True, True)),
    ("inclusive", ("random", "fifo", "lru"), (False, False, True)),
    ("inclusive", ("fifo", "lru", "random"), (True, True, True)),
    ("exclusive", ("lru", "random", "fifo"), (True, True, True)),
]


@pytest.mark.parametrize("inclusion, policies, allocate", CASES, ids=str)
@pytest.mark.parametrize("write_share", [0.1, 0.5, 0.9])
def test_writes_match_reference_on_seeded_streams(inclusion, policies, allocate, write_share):
    hierarchy = three_level(inclusion, policies, allocate)
    rng = np.random.default_rng(int(write_share * 10) + len(inclusion))
    n = 4000
    streams = {
        "uniform": rng.integers(0, 1 << 14, n),
        "local walk": np.cumsum(rng.integers(-96, 100, n)) + (1 << 20),
        "runs of one line": np.repeat(rng.integers(0, 1 << 13, n // 4), 4),
    }
    for name, stream in streams.items():
        stream = stream.astype(np.uint64)
        writes = rng.random(stream.size) < write_share
        result = simulate(stream, hierarchy, writes=writes, return_levels=True)
        counts, served = reference_simulate(stream, hierarchy, writes)
        assert result.counts.tolist() == counts.tolist(), name
        assert result.served_by.tolist() == served, name


@settings(max_examples=60, deadline=None)
@given(
    data=st.lists(st.tuples(st.integers(0, 4095), st.booleans()), max_size=200),
    case=st.sampled_from(CASES),
)
def test_property_writes_match_reference(data, case):
    hierarchy = three_level(*case)
    stream = np.array([address for address, _ in data], dtype=np.uint64)
    writes = np.array([flag for _, flag in data], dtype=bool)
    result = simulate(stream, hierarchy, writes=writes)
    counts, _ = reference_simulate(stream, hierarchy, writes)
    assert result.counts.tolist() == counts.tolist()


def test_alpha_presets_with_writes_match_reference():
    rng = np.random.default_rng(13)
    stream = (np.cumsum(rng.integers(-2048, 2100, 20000)) + 10**9).astype(np.uint64)
    writes = rng.random(stream.size) < 0.3
    for hierarchy in (alpha21164(), alpha21164_noninclusive()):
        result = simulate(stream, hierarchy, writes=writes)
        counts, _ = reference_simulate(stream, hierarchy, writes)
        assert result.counts.tolist() == counts.tolist(), hierarchy.name


def test_pieces_and_many_with_writes_equal_one_run():
    hierarchy = three_level(*CASES[3])
    rng = np.random.default_rng(17)
    stream = rng.integers(0, 1 << 15, 6000).astype(np.uint64)
    writes = rng.random(stream.size) < 0.4
    whole = simulate(stream, hierarchy, writes=writes)
    state = CacheState(hierarchy)
    for piece in np.array_split(np.arange(stream.size), [1, 900, 901, 4000]):
        simulate(stream[piece], state, writes=writes[piece])
    assert state.counts.tolist() == whole.counts.tolist()
    many = simulate_many([stream, stream[:100], stream[:0]], hierarchy, writes=[writes, None, writes[:0]])
    assert many[0].counts.tolist() == whole.counts.tolist()
    assert many[1].counts.tolist() == simulate(stream[:100], hierarchy).counts.tolist()
    assert many[2].counts.sum() == 0


# --- bad input ---------------------------------------------------------------

@pytest.mark.parametrize("writes, message", [
    ([True, False], "shape \\(3,\\)"),
    ([0, 2, 1], "booleans"),
    (np.array([0.5, 1.0, 0.0]), "booleans"),
    (np.ones((3, 1), dtype=bool), "shape \\(3,\\)"),
])
def test_bad_writes_are_rejected(writes, message):
    with pytest.raises(ValueError, match=message):
        simulate([0, 64, 128], alpha21164(), writes=writes)


def test_write_allocate_rules_of_hierarchies():
    with pytest.raises(ValueError, match="write_allocate"):
        CacheLevel("L1", 64, 32, write_allocate="no")
    with pytest.raises(ValueError, match="cannot sit above"):
        Hierarchy((CacheLevel("L1", 64, 32), CacheLevel("L2", 128, 32, write_allocate=False)), inclusion="inclusive")
    with pytest.raises(ValueError, match="exclusive levels must allocate"):
        Hierarchy((CacheLevel("L1", 64, 32, write_allocate=False), CacheLevel("L2", 128, 32)), inclusion="exclusive")
