"""Skipping a run of fresh consecutive lines (cachesim.fresh) against walking it access by access."""
import numpy as np
import pytest

from cachesim import CacheLevel, CacheState, Hierarchy, get_hierarchy
from cachesim.fresh import skip_fresh_lines, skips_exactly
from cachesim.kernels import ACCESSES, HITS, MISSES, chunk_buffers, simulate_into


def _sets(state):
    """Per level and set: the (line, stamp) pairs held, as a sorted list (way order does not matter);
    stamps only where a level orders its ways."""
    geometry = state.geometry
    tags, stamps = state.arrays.tags, state.arrays.stamps
    out = []
    for level in range(len(geometry.ways)):
        ways = int(geometry.ways[level])
        for s in range(int(geometry.n_sets[level])):
            base = int(geometry.offset[level]) + s * ways
            held = [(int(tags[w]), int(stamps[w]) if ways > 1 else 0) for w in range(base, base + ways)
                    if tags[w] >= 0]
            out.append(sorted(held))
    return out


def _warm(hierarchy, seed):
    """A state after a random stream over a small region, and its clock."""
    rng = np.random.default_rng(seed)
    state = CacheState(hierarchy)
    addresses = (rng.integers(0, 1 << 17, 20_000) * 8).astype(np.uint64)
    clock = simulate_into(addresses, state.geometry, state.arrays, 0, np.zeros(0, np.uint8), False, chunk_buffers())
    return state, clock


def _both(hierarchy, first_line, n_lines, seed):
    walked, clock = _warm(hierarchy, seed)
    skipped = walked.copy()
    shift = walked.geometry.line_shift
    addresses = ((first_line + np.arange(n_lines, dtype=np.int64)) << shift).astype(np.uint64)
    before = walked.arrays.counts.copy()
    clock_walked = simulate_into(addresses, walked.geometry, walked.arrays, clock, np.zeros(0, np.uint8), False,
                                 chunk_buffers())
    clock_skipped = skip_fresh_lines(first_line, n_lines, skipped.geometry, skipped.arrays, clock)
    assert clock_walked == clock_skipped == clock + n_lines
    columns = [ACCESSES, HITS, MISSES]
    assert np.array_equal(walked.arrays.counts[:, columns] - before[:, columns],
                          skipped.arrays.counts[:, columns] - before[:, columns])
    return walked, skipped


HIERARCHIES = {
    "alpha21164": get_hierarchy("alpha21164"),
    "alpha21164-noninclusive": get_hierarchy("alpha21164-noninclusive"),
    "small-inclusive": Hierarchy((CacheLevel("L1", 512, 32, 2), CacheLevel("L2", 4096, 64, 4)), memory_latency=50,
                                 inclusion="inclusive"),
    "small-odd-sets": Hierarchy((CacheLevel("L1", 768, 32, 1), CacheLevel("L2", 6144, 64, 3)), memory_latency=50),
}


@pytest.mark.parametrize("name", list(HIERARCHIES))
@pytest.mark.parametrize("seed", range(3))
def test_skipping_fresh_lines_leaves_the_walked_state(name, seed):
    hierarchy = HIERARCHIES[name]
    rng = np.random.default_rng(100 + seed)
    n_lines = {"alpha21164": 1 << 15, "alpha21164-noninclusive": 1 << 15}.get(name, int(rng.integers(64, 600)))
    first_line = (1 << 30) + int(rng.integers(0, 1000))  # odd starts too: a coarser line half in the stream
    assert skips_exactly(CacheState(hierarchy).geometry, n_lines)
    walked, skipped = _both(hierarchy, first_line, n_lines, seed)
    assert _sets(walked) == _sets(skipped)


def test_what_the_shortcut_refuses():
    fifo = Hierarchy((CacheLevel("L1", 512, 32, 2, "fifo"),), memory_latency=50)
    assert not skips_exactly(CacheState(fifo).geometry, 1000)
    exclusive = Hierarchy((CacheLevel("L1", 512, 32, 1), CacheLevel("L2", 4096, 32, 4)), memory_latency=50,
                          inclusion="exclusive")
    assert not skips_exactly(CacheState(exclusive).geometry, 1000)
    inclusive = CacheState(get_hierarchy("alpha21164")).geometry
    assert skips_exactly(inclusive, 1 << 15)
    assert not skips_exactly(inclusive, 100)  # the L2 keeps earlier lines a back-invalidation may have removed
    assert skips_exactly(CacheState(get_hierarchy("alpha21164-noninclusive")).geometry, 100)


def test_a_short_stream_into_a_non_inclusive_hierarchy_by_hand():
    # L1: 2 sets x 2 ways of 32 B lines; lines 8, 9, 10 (fresh) after line 0 and 2 were read
    hierarchy = Hierarchy((CacheLevel("L1", 128, 32, 2),), memory_latency=10)
    state = CacheState(hierarchy)
    clock = simulate_into(np.array([0, 64], dtype=np.uint64), state.geometry, state.arrays, 0,
                          np.zeros(0, np.uint8), False, chunk_buffers())
    clock = skip_fresh_lines(8, 3, state.geometry, state.arrays, clock)
    assert clock == 5
    # set 0 held lines 0 (clock 1) and 2 (clock 2); 8 and 10 replace both; set 1 gets 9
    assert _sets(state) == [[(8, 3), (10, 5)], [(9, 4)]]
    assert state.arrays.counts[0, MISSES] == 5 and state.arrays.counts[0, HITS] == 0
