"""Reuse distances against the O(N^2) reference, and the miss-ratio property."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cachesim import CacheLevel, Hierarchy, ReuseCounter, ReuseProfile, reuse_distances, reuse_profile, simulate
from cachesim.reuse import _fresh_state, _reuse_pass
from reference_cache import reference_reuse_distances, stack_reuse_distances


def test_by_hand():
    # lines: a b c a a b d c  (line size 16)
    stream = [0, 16, 32, 0, 4, 16, 48, 32]
    assert reuse_distances(stream, 16).tolist() == [-1, -1, -1, 2, 0, 2, -1, 3]


@pytest.mark.parametrize("seed", range(4))
def test_matches_reference_on_random_streams(seed):
    rng = np.random.default_rng(seed)
    span = [1 << 8, 1 << 12, 1 << 40, 1 << 63][seed]
    stream = rng.integers(0, span, 3000, dtype=np.uint64)
    if seed == 1:
        stream = np.repeat(stream, rng.integers(1, 4, stream.size))  # runs of one line
    line_size = [1, 16, 64, 4096][seed]
    assert np.array_equal(reuse_distances(stream, line_size), reference_reuse_distances(stream, line_size))


def test_growing_hash_table_keeps_exact_distances():
    # more distinct lines than the initial table holds, then every line again
    lines = np.arange(10000, dtype=np.uint64)
    stream = np.concatenate([lines, lines[::-1]]) * 64
    distances = reuse_distances(stream, 64)
    assert (distances[:10000] == -1).all()
    assert distances[10000:].tolist() == list(range(10000))


@pytest.mark.parametrize("tree_capacity", [1, 2, 7, 64])
def test_renumbering_a_small_tree_keeps_exact_distances(tree_capacity):
    # a tree far smaller than the stream: the live times are renumbered many times
    rng = np.random.default_rng(tree_capacity)
    lines = rng.integers(0, 300, 20000) ** 2 % 997  # skewed reuse over about 300 lines
    stream = (np.repeat(lines, rng.integers(1, 3, lines.size)) * 32).astype(np.uint64)
    distances = np.empty(stream.size, dtype=np.int64)
    state = _reuse_pass(stream, 5, distances, _fresh_state(tree_capacity))
    expected = stack_reuse_distances(stream, 32)
    assert np.array_equal(distances, expected)
    assert state.tree.size <= max(8 * np.unique(lines).size + 4, tree_capacity + 1)  # O(distinct lines), not O(accesses)


@pytest.mark.parametrize("seed", range(3))
def test_a_stream_in_pieces_equals_the_stream_in_one(seed):
    rng = np.random.default_rng(seed)
    stream = (rng.integers(0, 700, 12000) ** 2 % 4099 * 16).astype(np.uint64)
    cuts = np.sort(rng.integers(0, stream.size, 7))
    counter = ReuseCounter(32)
    distances = np.empty(stream.size, dtype=np.int64)
    for first, stop in zip(np.r_[0, cuts], np.r_[cuts, stream.size]):  # some pieces empty
        counter.update(stream[first:stop], distances[first:stop])
    expected = stack_reuse_distances(stream, 32)
    assert np.array_equal(distances, expected)
    profile = counter.profile()
    assert profile.cold == int((expected < 0).sum())
    assert np.array_equal(profile.histogram, np.bincount(expected[expected >= 0]))
    with pytest.raises(ValueError, match="distances must be int64"):
        counter.update(stream[:3], np.empty(2, dtype=np.int64))


def test_long_stream_profile_equals_the_stack_reference():
    # longer than the default tree: the public path renumbers too
    rng = np.random.default_rng(11)
    stream = rng.integers(0, 1 << 15, 30000, dtype=np.uint64)
    expected = stack_reuse_distances(stream, 64)
    assert np.array_equal(reuse_distances(stream, 64), expected)
    profile = reuse_profile(stream, 64)
    assert profile.cold == int((expected < 0).sum())
    assert np.array_equal(profile.histogram, np.bincount(expected[expected >= 0]))
    by_distances = ReuseProfile.from_distances(expected, 64)
    assert np.array_equal(profile.misses(np.arange(600)), by_distances.misses(np.arange(600)))


@settings(max_examples=40, deadline=None)
@given(stream=st.lists(st.integers(0, 2047), max_size=300), capacity=st.integers(1, 40))
def test_fully_associative_lru_misses_equal_distance_tail(stream, capacity):
    profile = reuse_profile(stream, 32)
    hierarchy = Hierarchy((CacheLevel("FA", 32 * capacity, 32, "full", "lru"),))
    assert int(profile.misses(capacity)) == int(simulate(stream, hierarchy).misses[0])


def test_miss_ratio_curve_is_monotone_and_complete():
    rng = np.random.default_rng(5)
    stream = rng.integers(0, 1 << 16, 20000)
    curve = reuse_profile(stream, 64).miss_ratio_curve()
    assert list(curve.columns) == ["size", "capacity_lines", "misses", "miss_ratio"]
    assert (np.diff(curve["misses"]) <= 0).all()
    distinct = np.unique(stream // 64).size
    assert curve["misses"].iloc[-1] == distinct  # a cache holding every line misses only cold


def test_bad_input():
    with pytest.raises(ValueError, match="line_size"):
        reuse_distances([1, 2], 48)
    with pytest.raises(ValueError, match="non-negative"):
        reuse_distances([1, -2], 64)
    assert reuse_distances([], 64).size == 0
    assert reuse_profile([], 64).accesses == 0
