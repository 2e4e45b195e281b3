"""cachesim.multicore's own path for first-level read hits (in its replay loop): against the reference."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy
from cachesim.multicore import simulate_threads
from cachesim.sets import HITS, MISSES
from cachesim.sharing import SharedHierarchy
from reference_multicore import assert_equals_reference


def read_mostly_machine(rng):
    """2-4 cores of 1-2 threads; an L1 of 8 ways (the unrolled probe) or 3 (the plain loop) in 4 sets or 3
    (not a power of two), LRU, FIFO or random, private to a thread or a core; a shared L2."""
    ways = int(rng.choice([8, 3]))
    sets = int(rng.choice([4, 3]))
    l1 = CacheLevel("L1", 16 * ways * sets, 16, ways, str(rng.choice(["lru", "fifo", "random"])),
                    seed=int(rng.integers(0, 9)), write_allocate=bool(rng.random() < 0.5))
    l2 = CacheLevel("L2", 16 * 4 * 16, 16, 4, "lru")
    return SharedHierarchy(Hierarchy((l1, l2), inclusion=str(rng.choice(["non-inclusive", "inclusive"]))),
                           n_cores=int(rng.integers(2, 5)), smt=int(rng.integers(1, 3)),
                           shared_by=(str(rng.choice(["thread", "core"])), "machine"))


def read_mostly_stream(rng, machine, n):
    """Runs of 1-40 accesses by one thread over a footprint about the L1's, a twentieth of them writes, random
    kinds and bytes: most reads hit the thread's first level, in other sets than the access before."""
    line = machine.hierarchy.levels[0].line_size
    footprint = machine.hierarchy.levels[0].size // line + 4
    run_ends = np.cumsum(rng.integers(1, 41, n))
    run_of = np.searchsorted(run_ends, np.arange(n), side="right")
    threads = rng.integers(0, machine.n_threads, run_of[-1] + 1)[run_of]
    addresses = rng.integers(0, footprint, n) * line + rng.integers(0, line, n)
    sizes = np.minimum(rng.integers(1, 9, n), line - addresses % line)
    return addresses, threads, rng.random(n) < 0.05, sizes, rng.integers(0, 16, n)


@pytest.mark.parametrize("seed", range(10))
def test_first_level_read_hits_match_the_reference(seed):
    """Streams whose reads mostly hit the first level, by threads in runs: every count of every instance and
    kind and each thread's served counts equal the reference's. Mutations (each checked to fail):
    ``if thread != previous_thread:`` -> ``if i == 0:`` in _replay (the first way of another thread's
    instance); drop ``state.stamps[slot] = clock`` in _replay."""
    rng = np.random.default_rng(300 + seed)
    machine = read_mostly_machine(rng)
    stream = read_mostly_stream(rng, machine, 3000)
    result = assert_equals_reference(machine, *stream)
    assert result.served[:, 0].sum() > 0.6 * stream[0].size  # the path is taken


def test_a_first_level_read_hit_renews_its_lru_stamp():
    """Thread 0 reads A, B, A, C, A, B in one 2-way LRU set of its own L1 (thread 1 reads D, E of its L1's same
    set between them): the hit on A makes B the least recently used, so C evicts B, A hits and B misses.
    L1 hits by kind (the kind is the access's position): thread 0 at 3 and 5, thread 1 none. Counted by hand.
    Mutation: drop ``state.stamps[slot] = clock`` in _replay (C then evicts A: a hit at 3 only)."""
    hierarchy = Hierarchy((CacheLevel("L1", 32, 16, 2), CacheLevel("L2", 1024, 16, 4)))
    machine = SharedHierarchy(hierarchy, n_cores=2, shared_by=("core", "machine"))
    a, b, c, d, e = 0x100, 0x200, 0x300, 0x400, 0x500
    addresses = [a, b, d, a, e, c, a, b]
    threads = [0, 0, 1, 0, 1, 0, 0, 0]
    kinds = [1, 2, 0, 3, 0, 4, 5, 6]
    result = simulate_threads(addresses, threads, machine, kinds=kinds)
    l1 = result.counts[0]
    assert np.flatnonzero(l1[0, :, HITS]).tolist() == [3, 5]
    assert l1[0, :, MISSES].sum() == 4 and l1[1, :, HITS].sum() == 0 and l1[1, :, MISSES].sum() == 2
    assert result.served[:, 0].tolist() == [2, 0]


@pytest.mark.parametrize("n_ways", [1, 3, 8, 12, 16, 63, 64, 65, 100])
def test_a_probe_finds_the_way_holding_the_line_in_sets_of_any_width(n_ways):
    """A set of ``n_ways`` distinct lines (empty ways, -1, among them) between two other sets: the probe of each
    line gives its own way, of a line the set lacks (one the next set holds, -1) -1. Hand-checked, every way.
    Mutations (each checked to fail): ``+ np.int64(_trailing_zeros(matches))`` -> ``+ 0`` in _probe_ways; ``if
    n_ways <= 64:`` -> ``if n_ways <= 65:`` in _probe (a shift by 64 bits)."""
    from cachesim.multicore_sets import _probe

    base = n_ways  # one set before it
    tags = np.full(3 * n_ways, 7, dtype=np.int64)
    tags[base:base + n_ways] = np.arange(100, 100 + n_ways)
    tags[base + 1:base + n_ways:4] = -1
    held = [way for way in range(n_ways) if tags[base + way] >= 0]
    assert [_probe(tags, base, n_ways, int(tags[base + way])) for way in held] == [base + way for way in held]
    assert _probe(tags, base, n_ways, 7) == -1 and _probe(tags, base, n_ways, 99) == -1


@pytest.mark.parametrize("seed", range(3))
def test_fully_associative_levels_beyond_64_ways_match_the_reference(seed):
    """An L1 of one set of 72 or 100 ways (the probe's plain loop) and one of 64 (a full bit mask) over a
    shared L2: counts and served equal the reference's on a stream of twice the L1's lines. Mutation:
    ``if n_ways <= 64:`` -> ``if n_ways <= 128:`` in _probe (checked to fail)."""
    rng = np.random.default_rng(400 + seed)
    ways = [72, 100, 64][seed]
    l1 = CacheLevel("L1", 16 * ways, 16, ways, str(rng.choice(["lru", "fifo"])))
    machine = SharedHierarchy(Hierarchy((l1, CacheLevel("L2", 16 * 4 * 64, 16, 4))), n_cores=2,
                              shared_by=("core", "machine"))
    n = 3000
    addresses = rng.integers(0, 2 * ways, n) * 16 + rng.integers(0, 16, n)
    stream = (addresses, rng.integers(0, 2, n), rng.random(n) < 0.1, np.minimum(rng.integers(1, 9, n),
              16 - addresses % 16), rng.integers(0, 16, n))
    result = assert_equals_reference(machine, *stream)
    assert result.served[:, 0].sum() > 0.3 * n
