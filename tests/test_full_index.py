"""The indexed walk of large fully associative levels (cachesim.full) against today's scans.

Each case runs one seeded stream through two copies of a fresh state, one with
:func:`cachesim.by_access._simulate_indexed` and one with the scanning walk
(:func:`cachesim.by_access._simulate_by_access`; and, for reads through a
non-inclusive hierarchy, the level-by-level path too), in two pieces so that the second call
builds its index from a used state, and compares tags, stamps, counters, the
clock and ``served_by``.
"""
import numpy as np
import pytest

from cachesim import CacheLevel, CacheState, Hierarchy, simulate
from cachesim.by_access import _simulate_by_access, _simulate_indexed
from cachesim.by_level import _simulate_by_level
from cachesim.full import INDEXED_MIN_WAYS, uses_index
from cachesim.sets import chunk_buffers
from jit_mode import shrink
from reference_cache import reference_simulate


def random_hierarchy(rng):
    """One to three levels, one of them fully associative with at least INDEXED_MIN_WAYS ways."""
    n_levels = int(rng.integers(1, 4))
    inclusion = str(rng.choice(["non-inclusive", "inclusive", "exclusive"]))
    full_at = int(rng.integers(0, n_levels))
    line_size = int(rng.choice([16, 32]))
    allocate = sorted(bool(rng.random() < 0.7) for _ in range(n_levels))  # no allocating level above one that does not
    levels = []
    for level in range(n_levels):
        if inclusion != "exclusive" and level > 0 and rng.random() < 0.4:
            line_size *= 2
        if level == full_at:
            assoc, size = "full", int(rng.integers(INDEXED_MIN_WAYS, INDEXED_MIN_WAYS + 80)) * line_size
        else:
            assoc = int(rng.choice([1, 2, 3, 4]))
            size = assoc * int(rng.choice([2, 3, 8, 16])) * line_size
        levels.append(CacheLevel(f"L{level + 1}", size, line_size, assoc, str(rng.choice(["lru", "fifo", "random"])),
                                 seed=int(rng.integers(0, 1000)),
                                 write_allocate=True if inclusion == "exclusive" else allocate[level]))
    return Hierarchy(tuple(levels), inclusion=inclusion)


def random_stream(rng, hierarchy, n):
    """Bursts of nearby addresses over about three times the largest level, with repeats."""
    span = 3 * max(level.size for level in hierarchy.levels)
    starts = rng.integers(0, span, n // 4 + 1)
    burst = np.repeat(starts, 4)[:n] + rng.integers(0, 96, n)
    return burst.astype(np.uint64)


def run(kernel, addresses, writes, state, record):
    served_by = np.zeros(addresses.size if record else 0, dtype=np.uint8)
    state.clock = int(kernel(addresses, writes, state.geometry, state.arrays, state.clock, served_by, record,
                             chunk_buffers()))
    return served_by


def by_level(addresses, writes, geometry, arrays, clock, served_by, record, work):
    return _simulate_by_level(addresses, geometry, arrays, clock, served_by, record, work)


def assert_same(one: CacheState, other: CacheState):
    assert np.array_equal(one.tags, other.tags)
    assert np.array_equal(one.stamps, other.stamps)
    assert np.array_equal(one.counts, other.counts)
    assert one.clock == other.clock


@pytest.mark.parametrize("seed", range(shrink(60, 6)))
def test_indexed_walk_matches_the_scans_state_for_state(seed):
    """Fails if ``_hash_remove`` in cachesim/full.py moves an entry whose home lies between the hole
    and it (``>=`` made ``>``: lines then go missing from the table), if ``_place`` evicts the tail
    (the newest) instead of the head, or if ``_heap_pop`` returns its last empty way instead of the lowest."""
    rng = np.random.default_rng(seed)
    hierarchy = random_hierarchy(rng)
    n = shrink(4000, 4)
    addresses = random_stream(rng, hierarchy, n)
    writes = rng.random(n) < 0.3 if seed % 3 else np.zeros(0, dtype=np.bool_)
    record = seed % 4 != 1
    kernels = [_simulate_by_access]
    if hierarchy.inclusion == "non-inclusive" and writes.size == 0:
        kernels.append(by_level)
    cut = int(rng.integers(1, n))
    for kernel in kernels:
        indexed, scanned = CacheState(hierarchy), CacheState(hierarchy)
        for piece in (slice(0, cut), slice(cut, n)):
            flags = writes[piece] if writes.size else writes
            ours = run(_simulate_indexed, addresses[piece], flags, indexed, record)
            theirs = run(kernel, addresses[piece], flags, scanned, record)
            assert np.array_equal(ours, theirs)
            assert_same(indexed, scanned)


def test_simulate_indexes_a_large_fully_associative_level_and_matches_the_reference():
    """Fails if ``_place`` in cachesim/full.py leaves a filled way off the recency list (drop its
    ``_append``): the head would then not be the least recent line. Through ``simulate`` (the
    dispatch of cachesim/kernels.py), against the slow dict-based reference, with a fully
    associative LRU level between two others."""
    hierarchy = Hierarchy((CacheLevel("L1", 512, 32, 2), CacheLevel("L2", 256 * 64, 64, "full"),
                           CacheLevel("L3", 1024 * 64, 64, 4, "fifo")), inclusion="inclusive")
    rng = np.random.default_rng(11)
    addresses = random_stream(rng, hierarchy, 3000)
    result = simulate(addresses, hierarchy, return_levels=True)
    assert uses_index(result.state.geometry, addresses.size) and result.evictions[1] > 100
    counts, served_by = reference_simulate(addresses, hierarchy)
    assert np.array_equal(result.counts, counts)
    assert result.served_by.tolist() == served_by


def test_uses_index_weighs_the_ways_against_the_stream():
    """Fails if ``uses_index`` ignores the stream's length: a pixel's few accesses would build a
    65,536-way index each time."""
    geometry = CacheState(Hierarchy((CacheLevel("FA", 4 << 20, 64, "full"),))).geometry
    assert uses_index(geometry, 4096) and not uses_index(geometry, 4095)
    small = CacheState(Hierarchy((CacheLevel("FA", 64 * 64, 64, "full"),))).geometry
    assert not uses_index(small, 10**6)


def test_only_the_whole_stream_kernels_take_the_indexed_walk(monkeypatch):
    """Fails if ``simulate_into`` or ``simulate_writes_into`` in cachesim/kernels.py dispatch to
    ``_simulate_indexed`` (put back their ``uses_index`` branch): every caller compiled around them,
    the schedule's event loop among them, would compile the indexed walk too. ``simulate_writes``
    (one whole stream) must still take it. The kernels' Python bodies run with the indexed walk
    replaced by a spy; the callees they reach stay compiled."""
    from cachesim import kernels as K

    calls = []

    def spy(*args):
        calls.append(args[0].size)
        return _simulate_indexed(*args)

    monkeypatch.setattr(K, "_simulate_indexed", spy)
    hierarchy = Hierarchy((CacheLevel("L1", 256, 32, 1), CacheLevel("FA", INDEXED_MIN_WAYS * 64, 64, "full")),
                          inclusion="inclusive")
    addresses = (np.arange(64, dtype=np.uint64) * 96) % 8192
    flags = np.arange(64) % 5 == 0
    served = np.zeros(0, dtype=np.uint8)
    results = []
    for kernel, extra in ((K.simulate_into, ()), (K.simulate_writes_into, (flags,)), (K.simulate_writes, (flags,))):
        state = CacheState(hierarchy)
        assert uses_index(state.geometry, addresses.size)
        work = (chunk_buffers(),) if kernel is not K.simulate_writes else ()
        body = getattr(kernel, "py_func", kernel)
        if extra:
            body(addresses, *extra, state.geometry, state.arrays, 0, served, False, *work)
        else:
            body(addresses, state.geometry, state.arrays, 0, served, False, *work)
        results.append(state.counts)
    assert calls == [addresses.size]
    assert np.array_equal(results[1], results[2])


INDEX_HELPERS = {"_hash_find", "_hash_add", "_hash_remove", "_unlink", "_append", "_heap_push", "_heap_pop"}


def inlined_callees(operations, index):
    """Names of the functions numba copies (``inline="always"``) into a fresh kernel that walks one
    access's levels with ``operations`` (cachesim.full.SCANNING or INDEXED) and ``index``."""
    from numba import njit
    from numba.core import inline_closurecall

    names = []
    original = inline_closurecall.InlineWorker.inline_function

    def spy(self, caller_ir, block, i, function, *args, **kwargs):
        names.append(function.__name__)
        return original(self, caller_ir, block, i, function, *args, **kwargs)

    serving_level, fill_levels = operations.serving_level, operations.fill_levels

    @njit
    def one_access(line, geometry, state, index, work):
        served = serving_level(line, 0, geometry, state, index, 1, False, work)
        fill_levels(served, 0, geometry, state, index, 1, False, work)
        return served

    state = CacheState(Hierarchy((CacheLevel("L1", 256, 32, 2), CacheLevel("FA", INDEXED_MIN_WAYS * 64, 64, "full")),
                                 inclusion="inclusive"))
    inline_closurecall.InlineWorker.inline_function = spy
    try:
        one_access(7, state.geometry, state.arrays, index(state), chunk_buffers())
    finally:
        inline_closurecall.InlineWorker.inline_function = original
    return set(names)


@pytest.mark.jit_only
def test_the_scanning_operations_compile_none_of_the_index():
    """Fails if a scanning operation of cachesim/full.py tests the index against None instead of its
    form's constant (``indexed and index.indexed[level]`` in ``lookup`` made ``index is not None
    and ...``): numba would then copy the index's helpers into every kernel without an index (the
    direct-mapped path, the scanning walk, the schedule's event loop) before dropping them, which
    took several times as long to compile. The indexed form must copy them in."""
    from cachesim.full import INDEXED, SCANNING, build_index

    scanning = inlined_callees(SCANNING, lambda state: None)
    indexed = inlined_callees(INDEXED, lambda state: build_index(state.geometry, state.arrays, 0)[0])
    assert "_find" in scanning and not scanning & INDEX_HELPERS
    assert INDEX_HELPERS <= indexed
