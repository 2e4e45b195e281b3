"""The direct-mapped-first path (cachesim.direct_first) against the general walk
(cachesim.by_access), state for state, and a case checked by hand."""
import numpy as np
import pytest

from cachesim import CacheLevel, CacheState, Hierarchy, alpha21164, alpha21164_noninclusive, simulate
from cachesim import kernels as K
from cachesim.by_access import _simulate_by_access
from cachesim.direct_first import _simulate_direct_first, serves_direct_first


def random_hierarchy(rng, third_ways=None, second_ways=None):
    """A hierarchy the direct path serves: a direct-mapped L1, an LRU L2 of 1-4
    ways, and 0-2 levels below of any policy, with random write allocation.
    With ``third_ways``: 1-2 levels below, the first of ``third_ways`` ways.
    With ``second_ways``: an L2 of that many ways (the same draws)."""
    while True:
        line = 1 << int(rng.integers(4, 7))
        levels = [CacheLevel("L1", line * (1 << int(rng.integers(1, 5))), line, 1, str(rng.choice(["lru", "fifo"])),
                             write_allocate=bool(rng.integers(2)))]
        line2 = line << int(rng.integers(0, 2))
        ways2 = int(rng.integers(1, 5))
        ways2 = ways2 if second_ways is None else second_ways
        levels.append(CacheLevel("L2", line2 * ways2 * (1 << int(rng.integers(1, 5))), line2, ways2, "lru",
                                 write_allocate=bool(rng.integers(2))))
        for depth in range(int(rng.integers(0, 3) if third_ways is None else rng.integers(1, 3))):
            line3 = line2 << int(rng.integers(0, 2))
            ways3 = third_ways if depth == 0 and third_ways is not None else int(rng.integers(1, 4))
            levels.append(CacheLevel(f"L{depth + 3}", line3 * ways3 * (1 << int(rng.integers(2, 6))), line3, ways3,
                                     str(rng.choice(["lru", "fifo", "random"])), seed=int(rng.integers(100)),
                                     write_allocate=bool(rng.integers(2))))
        try:
            return Hierarchy(tuple(levels), inclusion=str(rng.choice(["inclusive", "non-inclusive"])))
        except ValueError:  # an inclusive level above one that does not allocate writes, say
            continue


def random_stream(rng, n):
    kind = rng.integers(3)
    if kind == 0:
        stream = rng.integers(0, 1 << 13, n)
    elif kind == 1:
        stream = np.cumsum(rng.integers(-80, 90, n)) + (1 << 20)
    else:
        stream = np.repeat(rng.integers(0, 1 << 12, n // 3 + 1), 3)[:n]
    return stream.astype(np.uint64)


def run_kernel(kernel, stream, writes, hierarchy, pieces, record):
    """Both kernels on a fresh state, the stream cut into ``pieces`` calls
    sharing one work bundle whose buffers start dirty."""
    state = CacheState(hierarchy)
    work = K.chunk_buffers()
    for buffer in work:
        buffer[:] = 12345
    served = np.zeros(stream.size if record else 0, dtype=np.uint8)
    clock = 7
    bounds = np.linspace(0, stream.size, pieces + 1).astype(int)
    for start, stop in zip(bounds[:-1], bounds[1:]):
        piece = slice(start, stop)  # views: served_by is written through them
        flags = writes[piece] if writes is not None else np.zeros(0, dtype=np.bool_)
        out = served[piece] if record else served
        clock = kernel(stream[piece], flags, state.geometry, state.arrays, clock, out, record, work)
    return clock, state.tags.copy(), state.stamps.copy(), state.counts.copy(), served


def assert_direct_first_equals_the_walk(rng, hierarchy, lengths, with_writes, record, max_pieces):
    """The direct-first kernel and the general walk leave the same clock, tags, stamps, counts and served
    levels on a random stream of ``lengths`` (low, high) accesses, written at a random rate if
    ``with_writes``, replayed in 1 to ``max_pieces - 1`` calls."""
    assert serves_direct_first(CacheState(hierarchy).geometry)
    stream = random_stream(rng, int(rng.integers(*lengths)))
    writes = rng.random(stream.size) < rng.choice([0.0, 0.05, 0.5]) if with_writes else None
    pieces = int(rng.integers(1, max_pieces))
    walked = run_kernel(_simulate_by_access, stream, writes, hierarchy, pieces, record)
    direct = run_kernel(_simulate_direct_first, stream, writes, hierarchy, pieces, record)
    for name, a, b in zip(("clock", "tags", "stamps", "counts", "served_by"), walked, direct):
        np.testing.assert_array_equal(a, b, err_msg=f"{name} of {hierarchy}")


@pytest.mark.parametrize("seed", range(40))
def test_direct_first_equals_the_general_walk_on_seeded_random_hierarchies(seed):
    rng = np.random.default_rng(seed)
    hierarchy = random_hierarchy(rng)
    assert_direct_first_equals_the_walk(rng, hierarchy, (1, 3000), bool(seed % 4), bool(seed % 3), 5)


@pytest.mark.parametrize("seed", range(30))
def test_direct_mapped_third_level_equals_the_general_walk(seed):
    """A direct-mapped third level, which the kernel looks up and fills in its own scalars (one of 1-3
    ways, walked as the general walk does, for comparison), with a level of 1-3 ways below it or none,
    against the general walk state for state. Fails when a third-level eviction leaves the second
    level's lines inside it (``second_invalidations += 1`` and the ``tags[way] = -1`` before it dropped:
    checked), or when the third level's hit leaves its stamp (``stamps[base2] = clock`` dropped: checked)."""
    rng = np.random.default_rng(1000 + seed)
    hierarchy = random_hierarchy(rng, third_ways=1 if seed % 5 else int(rng.integers(2, 4)))
    assert_direct_first_equals_the_walk(rng, hierarchy, (500, 4000), bool(seed % 3), bool(seed % 2), 4)


@pytest.mark.parametrize("seed", range(16))
def test_three_way_second_level_equals_the_general_walk(seed):
    """A 3-way L2 (the 21164's S-cache), whose ways the kernel probes in a loop of fixed length, with a
    direct-mapped third level or any levels below, against the general walk state for state. Fails when
    the fixed-length probe looks at two ways (``_ways_holding(tags, base, 2, line)`` in ``_find_way``:
    checked)."""
    rng = np.random.default_rng(2000 + seed)
    hierarchy = random_hierarchy(rng, third_ways=1 if seed % 2 else None, second_ways=3)
    assert_direct_first_equals_the_walk(rng, hierarchy, (500, 4000), bool(seed % 3), bool(seed % 4), 4)


def test_three_way_second_level_by_hand():
    """The 21164 (8 KB direct-mapped L1, 96 KB 3-way LRU L2 of 512 sets, 4 MB direct-mapped L3, 64 B
    lines below the L1's 32 B), lines 32 KB apart: one L1 set, one L2 set, distinct L3 sets.
    Fails with the fixed-length probe looking at two ways (the last read's L2 hit is then a miss: checked).
    """
    a, b, c, d = (k * 32768 for k in range(4))
    # a b c: miss everywhere, L2 ways 0-2 = a b c
    # a:     L1 holds c: miss; L2 hit (way 0)
    # d:     misses L2 and L3; L2 evicts b, the least recently used: ways = a d c
    # b:     L2 miss, L3 hit; L2 evicts c (a and d were used since): ways = a d b
    # a:     L2 hit (way 0)
    # b:     L2 hit (way 2)
    stream = np.array([a, b, c, a, d, b, a, b], dtype=np.uint64)
    result = simulate(stream, alpha21164(), return_levels=True)
    assert result.served_by.tolist() == [3, 3, 3, 1, 3, 2, 1, 1]
    hits = result.counts[:, K.HITS].tolist()
    misses = result.counts[:, K.MISSES].tolist()
    assert (hits, misses) == ([0, 3, 1], [8, 5, 4])


def test_simulate_uses_the_direct_path_with_the_same_results_on_the_alpha_presets():
    rng = np.random.default_rng(5)
    stream = (np.cumsum(rng.integers(-4096, 4200, 30000)) + (1 << 30)).astype(np.uint64)
    writes = rng.random(stream.size) < 0.2
    for hierarchy in (alpha21164(), alpha21164_noninclusive()):
        assert serves_direct_first(CacheState(hierarchy).geometry)
        for flags in (writes, None):
            result = simulate(stream, hierarchy, writes=flags, return_levels=True)
            walked = run_kernel(_simulate_by_access, stream, flags, hierarchy, 1, True)
            np.testing.assert_array_equal(result.counts, walked[3])
            np.testing.assert_array_equal(result.served_by, walked[4])


def test_which_hierarchies_the_direct_path_serves():
    def hierarchy(l1_ways=1, l2_policy="lru", l2_size=512, inclusion="inclusive", l2_line=64):
        return Hierarchy((CacheLevel("L1", 128, 32, l1_ways), CacheLevel("L2", l2_size, l2_line, 2, l2_policy)),
                         inclusion=inclusion)

    assert serves_direct_first(CacheState(hierarchy()).geometry)
    assert not serves_direct_first(CacheState(hierarchy(l1_ways=2)).geometry)
    assert not serves_direct_first(CacheState(hierarchy(l2_policy="fifo")).geometry)
    assert not serves_direct_first(CacheState(hierarchy(l2_size=384)).geometry)  # 3 sets: not a power of two
    assert not serves_direct_first(CacheState(hierarchy(inclusion="exclusive", l2_line=32)).geometry)
    assert not serves_direct_first(CacheState(Hierarchy((CacheLevel("L1", 128, 32, 1),))).geometry)


def test_direct_first_by_hand():
    # L1: 2 sets of one 32 B line; L2: 1 set of two 64 B lines, LRU; inclusive;
    # the L1 does not allocate writes.
    hierarchy = Hierarchy((CacheLevel("L1", 64, 32, 1, write_allocate=False), CacheLevel("L2", 128, 64, 2)),
                          inclusion="inclusive")
    # 0    read:  misses both; L2 {0}, L1 set 0 = line 0            -> memory (2)
    # 32   read:  L1 set 1 misses, L2 line 0 hits; L1 set 1 = 1      -> L2 (1)
    # 0    write: L1 hit                                            -> L1 (0)
    # 64   write: misses both; L2 {0, 1}; L1 does not allocate      -> memory
    # 64   read:  L1 set 0 holds line 0: miss; L2 hit, L1 set 0 = 2  -> L2
    # 128  read:  misses both; L2 evicts line 0 (least recent), which
    #             back-invalidates L1 line 1 (set 1); L1 set 0 = 4   -> memory
    # 32   read:  L1 set 1 empty, L2 has no line 0: misses both      -> memory
    stream = np.array([0, 32, 0, 64, 64, 128, 32], dtype=np.uint64)
    writes = np.array([False, False, True, True, False, False, False])
    result = simulate(stream, hierarchy, writes=writes, return_levels=True)
    assert result.served_by.tolist() == [2, 1, 0, 2, 1, 2, 2]
    assert result.hits.tolist() == [1, 2]
    assert result.write_hits.tolist() == [1, 0]
    state = CacheState(hierarchy)
    simulate(stream, state, writes=writes)
    assert state.counts[0, K.INVALIDATIONS] == 1
    assert state.counts[1, K.EVICTIONS] == 2  # line 0 for 4, then line 1 for 0 (the last read)
