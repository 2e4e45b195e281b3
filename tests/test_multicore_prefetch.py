"""Prefetchers on shared levels (cachesim.multicore_prefetch) against an interleaved reference."""
from dataclasses import replace

import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy, Prefetcher, simulate
from cachesim.multicore import simulate_threads
from cachesim.multicore_state import COHERENCE_INVALIDATIONS, COHERENCE_MISSES, SharedState
from cachesim.sharing import SharedHierarchy, private
from reference_multicore_prefetch import reference_threads_prefetching
from test_multicore import random_machine, random_stream

PREFETCHERS = [
    Prefetcher("next-line"),
    Prefetcher("next-line", degree=2, distance=2, trigger="access"),
    Prefetcher("next-line", trigger="miss"),
    Prefetcher("stride", degree=2, table_size=4),
    Prefetcher("stride", distance=2, trigger="miss", table_size=16),
]


def with_prefetchers(machine, rng):
    """``machine`` with a random prefetcher (or none) on each level, at least one next-line in all
    (a stride prefetcher may never reach its steady state on a random stream)."""
    chosen = [PREFETCHERS[int(rng.integers(0, len(PREFETCHERS)))] if rng.random() < 0.6 else None
              for _ in machine.hierarchy.levels]
    if not any(prefetcher is not None and prefetcher.kind == "next-line" for prefetcher in chosen):
        chosen[int(rng.integers(0, len(chosen)))] = PREFETCHERS[0]
    levels = tuple(replace(level, prefetcher=prefetcher) for level, prefetcher in zip(machine.hierarchy.levels, chosen))
    return replace(machine, hierarchy=replace(machine.hierarchy, levels=levels))


def strided_stream(rng, machine, n):
    """Each thread walks its own region by its own stride (1-3 lines; kind = its thread), and one
    access in eight writes a line of a small shared region."""
    line = machine.hierarchy.levels[0].line_size
    threads = rng.integers(0, machine.n_threads, n)
    strides = rng.integers(1, 4, machine.n_threads) * line
    steps = np.zeros(n, dtype=np.int64)
    for thread in range(machine.n_threads):
        mine = threads == thread
        steps[mine] = np.arange(int(mine.sum()))
    addresses = 4096 * (threads + 1) + steps * strides[threads]
    shared = rng.random(n) < 0.125
    addresses[shared] = rng.integers(0, 8 * line, int(shared.sum()))
    sizes = np.minimum(rng.integers(1, 9, n), line - addresses % line)
    return addresses, threads, shared, sizes, threads % 16


@pytest.mark.parametrize("seed", range(12))
def test_random_machines_with_prefetchers_match_the_reference(seed):
    """Demand counts of every instance and kind, served counts, prefetches issued, useful, useless
    and pending per instance equal the reference's, in one call and in two calls on one state.
    Fails if a prefetch goes to thread 0's instances whoever triggered it
    (``machine.instance_of[level, access[0]]`` -> ``[level, 0]`` in ``_issue``), or if the
    instances of a level share one stride table (``rows = prefetch.table``)."""
    rng = np.random.default_rng(100 + seed)
    machine = with_prefetchers(random_machine(rng), rng)
    make = random_stream if seed % 2 else strided_stream
    addresses, threads, writes, sizes, kinds = make(rng, machine, 1200)
    reference = reference_threads_prefetching(addresses, threads, machine, writes, sizes, kinds)
    result = simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds)
    np.testing.assert_array_equal(result.counts, reference.counts)
    np.testing.assert_array_equal(result.served, reference.served)
    np.testing.assert_array_equal(result.prefetch_counts, reference.prefetch)
    np.testing.assert_array_equal(result.prefetch_pending, reference.pending())
    assert result.state.clock == reference.clock
    assert result.prefetch_counts[..., 0].sum() > 0
    state = SharedState(machine)
    parts = [simulate_threads(addresses[a:b], threads[a:b], state, writes=writes[a:b], sizes=sizes[a:b],
                              kinds=kinds[a:b]) for a, b in [(0, 500), (500, 1200)]]
    np.testing.assert_array_equal(parts[0].counts + parts[1].counts, reference.counts)
    np.testing.assert_array_equal(parts[0].prefetch_counts + parts[1].prefetch_counts, reference.prefetch)


def test_a_coherence_invalidation_makes_a_prefetch_useless_by_hand():
    """Thread 0 reads line 0, its L1 prefetches line 1; thread 1 writes line 1, which removes it
    from thread 0's L1 unused: issued 1, useful 0, useless 1 there; thread 0's read of line 1
    then misses its L1 as a coherence miss, and prefetches line 2 (pending). Fails if every
    resident line counts as pending (drop ``(prefetch.marks == tags) &`` in ``pending_by_instance``)."""
    hierarchy = Hierarchy((CacheLevel("L1", 512, 64, 2, prefetcher=Prefetcher("next-line")),
                           CacheLevel("L2", 4096, 64, 4)))
    machine = SharedHierarchy(hierarchy, n_cores=2, shared_by=("thread", "machine"))
    result = simulate_threads([0, 64, 64], [0, 1, 0], machine, writes=[False, True, False])
    assert result.prefetch_counts[0, 0].tolist() == [2, 0, 1]  # line 1, then line 2 on the miss on line 1
    assert result.prefetch_pending[0, 0] == 1
    assert result.counts[0, 0, 0, COHERENCE_MISSES] == 1  # coherence miss of thread 0 on line 1


def test_one_thread_of_private_levels_equals_simulate_with_prefetchers():
    """With one thread, private levels and the record kind as the PC-like id, the shared
    simulator gives cachesim.simulate's counts and prefetch counts. Fails if the kind is not
    the stride tables' id (``kind`` -> ``0`` in the ``_candidates`` call)."""
    rng = np.random.default_rng(4)
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 2, prefetcher=Prefetcher("stride", degree=2)),
                           CacheLevel("L2", 4096, 64, 4, "fifo", prefetcher=Prefetcher("stride", table_size=8))),
                          inclusion="inclusive")
    machine = private(hierarchy)
    starts = rng.integers(0, 1 << 14, 300)
    addresses = np.ravel(starts[:, None] + np.arange(6) * 96)
    kinds = np.repeat(np.arange(300) % 5, 6)
    alone = simulate(addresses, hierarchy, pcs=kinds)
    shared = simulate_threads(addresses, np.zeros(addresses.size, dtype=np.int64), machine, kinds=kinds)
    np.testing.assert_array_equal(shared.level_counts()[:, :COHERENCE_INVALIDATIONS], alone.counts)
    np.testing.assert_array_equal(shared.prefetch_counts[:, 0], alone.prefetch_counts)
