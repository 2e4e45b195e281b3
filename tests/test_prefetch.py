"""Prefetchers: hand-checked streams, the slow reference on seeded random streams, configuration."""
import json

import numpy as np
import pytest

from cachesim import CacheLevel, CacheState, Hierarchy, Prefetcher, simulate, simulate_many
from reference_prefetch import reference_prefetching

LINE = 64


def one_level(prefetcher, size=1024, assoc=2, policy="lru"):
    return Hierarchy((CacheLevel("L1", size, LINE, assoc, policy, prefetcher=prefetcher),
                      CacheLevel("L2", 8 * size, LINE, 4)))


def sequential(n_lines):
    return np.arange(n_lines, dtype=np.uint64) * LINE


# --- hand-checked streams -----------------------------------------------------

@pytest.mark.parametrize("trigger", ["tagged", "access"])
def test_next_line_turns_a_sequential_stream_into_useful_hits_by_hand(trigger):
    """Lines 0..39 read once each: line k + 1 is fetched while line k is used, so only line 0
    misses; 40 prefetches, 39 used, the last (line 40) still pending, none useless.
    Fails if the tagged trigger ignores the first use of a prefetched line (``missed or
    first_use`` -> ``missed`` in ``_candidates``): every other line then misses."""
    result = simulate(sequential(40), one_level(Prefetcher("next-line", trigger=trigger)))
    assert result.misses.tolist() == [1, 1]
    assert result.prefetches_issued.tolist() == [40, 0]
    assert result.prefetches_useful.tolist() == [39, 0]
    assert result.prefetches_useless.tolist() == [0, 0]
    assert result.prefetch_pending.tolist() == [1, 0]


def test_next_line_on_miss_halves_the_misses_of_a_sequential_stream_by_hand():
    """Prefetch on miss: the miss on line 2k fetches 2k + 1, whose hit triggers nothing, so
    line 2k + 2 misses again: 20 misses in 40 lines, 20 issued and useful.
    Fails if a hit triggers an on-miss prefetcher (drop the ``ON_MISS`` early return)."""
    result = simulate(sequential(40), one_level(Prefetcher("next-line", trigger="miss")))
    assert result.misses[0] == 20
    assert result.prefetches_issued[0] == 20 and result.prefetches_useful[0] == 20


def test_next_line_degree_and_distance_by_hand():
    """Degree 2, distance 2, on miss, lines 0, 1, 2 in a fully associative 8-line L1:
    line 0 misses and fetches 2 and 3; line 1 misses and fetches 4 (3 is there: not issued);
    line 2 hits a prefetched line. Issued 3, useful 1, pending 2 (3 and 4).
    Fails if a candidate already in the level is issued again (drop the lookup in ``_issue``)."""
    hierarchy = one_level(Prefetcher("next-line", degree=2, distance=2, trigger="miss"), size=8 * LINE,
                          assoc="full")
    result = simulate(sequential(3), hierarchy, return_levels=True)
    assert result.served_by.tolist() == [2, 2, 0]
    assert result.prefetches_issued[0] == 3
    assert result.prefetches_useful[0] == 1
    assert result.prefetch_pending[0] == 2
    assert result.state.resident_lines("L1").tolist() == [0, 1, 2, 3, 4]


def test_prefetched_lines_enter_the_levels_below_by_hand():
    """An L1 prefetch of line 1 fills L2 too (a demand fill's path), without counting an L2 access.
    Fails if the prefetch fills only its own level (``_fill_levels(served, level ...)`` called
    with ``served = level + 1``)."""
    result = simulate([0], one_level(Prefetcher("next-line")))
    assert result.state.resident_lines("L2").tolist() == [0, 1]
    assert result.accesses.tolist() == [1, 1]


def test_stride_prefetcher_learns_a_stride_of_three_lines_by_hand():
    """One id, a stride of 3 lines: the first access takes the table entry (initial), the
    second sets the stride (transient), the third confirms it (steady) and fetches the next;
    so 3 misses, then 27 hits on prefetched lines. Issued 28, useful 27, pending 1.
    Fails if a correct stride in the transient state does not reach steady
    (``STEADY`` -> ``TRANSIENT`` for it in ``_candidates``)."""
    stream = np.arange(30, dtype=np.uint64) * 3 * LINE
    result = simulate(stream, one_level(Prefetcher("stride")))
    assert result.misses[0] == 3
    assert result.prefetches_issued[0] == 28
    assert result.prefetches_useful[0] == 27
    assert result.prefetch_pending[0] == 1


def test_stride_table_is_indexed_by_the_pc_like_id_by_hand():
    """Two interleaved streams, +3 lines and -2 lines: with their own ids each entry learns
    its stride (3 misses each); under one id the strides alternate and it never reaches steady.
    Fails if the table ignores the ids (``pc`` -> ``0`` in the kernel)."""
    up = np.arange(20) * 3 * LINE
    down = 100_000 - np.arange(20) * 2 * LINE
    stream = np.ravel(np.column_stack([up, down])).astype(np.uint64)
    pcs = np.tile([4, 9], 20)
    hierarchy = one_level(Prefetcher("stride"), size=4096, assoc=4)
    assert simulate(stream, hierarchy, pcs=pcs).misses[0] == 6
    assert simulate(stream, hierarchy).misses[0] == 40


def test_useless_prefetches_by_hand():
    """Direct-mapped L1 of 4 lines, next-line on miss, lines 0, 5, 10: line 0 fetches 1 (set 1);
    line 5 (set 1) evicts 1 unused and fetches 6 (set 2); line 10 evicts 6 unused and fetches 11.
    Issued 3, useful 0, useless 2, pending 1. Fails if every resident line counts as pending
    (drop ``(prefetch.marks == tags) &`` in ``pending_prefetches``)."""
    hierarchy = one_level(Prefetcher("next-line", trigger="miss"), size=4 * LINE, assoc=1)
    result = simulate(np.array([0, 5, 10], dtype=np.uint64) * LINE, hierarchy)
    assert result.prefetch_counts[0].tolist() == [3, 0, 2]
    assert result.prefetch_pending[0] == 1


def test_useless_prefetches_on_a_random_stream():
    """Random lines of a large region: next-line prefetches are almost never used; the useless
    ones, derived from the marks, equal the reference's, counted at each eviction.
    Fails if demand fills mark their lines as prefetched (``marks[slot] = -1`` ->
    ``= lines[level]`` in ``_unmark``)."""
    rng = np.random.default_rng(5)
    stream = (rng.integers(0, 1 << 16, 3000) * LINE).astype(np.uint64)
    hierarchy = one_level(Prefetcher("next-line"))
    result = simulate(stream, hierarchy)
    reference = reference_prefetching(stream, hierarchy)
    issued, useful, useless = result.prefetch_counts[0]
    assert useless > 0.9 * issued
    np.testing.assert_array_equal(result.prefetch_counts, reference.prefetch)
    np.testing.assert_array_equal(result.prefetch_pending, reference.pending())


# --- against the reference ---------------------------------------------------

def mixed_stream(rng, n):
    """Sequential runs, strided runs (one id per stride) and random jumps, with writes."""
    addresses, pcs = [], []
    while len(addresses) < n:
        pick = rng.integers(0, 3)
        start = int(rng.integers(0, 1 << 14))
        length = int(rng.integers(1, 12))
        if pick == 0:
            step, pc = int(rng.choice([4, 8, 16, 32])), 1
        elif pick == 1:
            step = int(rng.choice([-3, 2, 3, 5])) * 32
            pc = 2 + step % 7
        else:
            step, pc = int(rng.integers(-4000, 4000)), int(rng.integers(0, 40))
        for k in range(length):
            addresses.append(max(start + k * step, 0))
            pcs.append(pc)
    writes = rng.random(n) < 0.2
    return np.array(addresses[:n], dtype=np.uint64), writes, np.array(pcs[:n], dtype=np.int64)


PREFETCHERS = [
    Prefetcher("next-line"),
    Prefetcher("next-line", degree=3, distance=2, trigger="access"),
    Prefetcher("next-line", degree=2, trigger="miss"),
    Prefetcher("stride", degree=2, table_size=8),
    Prefetcher("stride", distance=3, trigger="miss", table_size=3),
]


def reference_case(seed):
    rng = np.random.default_rng(seed)
    inclusion = ["non-inclusive", "inclusive"][seed % 2]
    policy = ["lru", "fifo", "random"][seed % 3]
    first = PREFETCHERS[seed % len(PREFETCHERS)]
    second = None if seed % 4 == 0 else PREFETCHERS[(seed * 7 + 1) % len(PREFETCHERS)]
    hierarchy = Hierarchy((
        CacheLevel("L1", 512, 32, int(rng.choice([1, 2, 4])), policy, seed=seed,
                   write_allocate=bool(seed % 5) or inclusion == "non-inclusive", prefetcher=first),
        CacheLevel("L2", 3 * 1024, 64, 3, policy, seed=seed + 1, prefetcher=second),
        CacheLevel("L3", 8 * 1024, 128, 2, "lru"),
    ), inclusion=inclusion)
    return hierarchy, mixed_stream(rng, 1500)


@pytest.mark.parametrize("seed", range(12))
def test_prefetching_matches_the_reference_on_random_streams(seed):
    """Counts, served levels, prefetches issued/useful/useless/pending and the clock agree with
    tests/reference_prefetch.py over inclusions, policies, triggers, degrees and distances.
    Fails if a prefetch does not advance the clock (drop ``clock += 1`` in ``_issue``: random
    replacement and LRU order change), among others."""
    hierarchy, (addresses, writes, pcs) = reference_case(seed)
    result = simulate(addresses, hierarchy, writes=writes, pcs=pcs, return_levels=True)
    reference = reference_prefetching(addresses, hierarchy, writes, pcs)
    assert result.served_by.tolist() == reference.served_by
    np.testing.assert_array_equal(result.counts, reference.counts)
    np.testing.assert_array_equal(result.prefetch_counts, reference.prefetch)
    np.testing.assert_array_equal(result.prefetch_pending, reference.pending())
    assert result.state.clock == reference.clock
    assert result.prefetch_counts[:, 0].sum() > 0


@pytest.mark.parametrize("seed", [1, 6])
def test_a_stream_in_pieces_equals_one_run(seed):
    """Continuing a state (with its stride tables and marks) gives the totals of one call, each
    call's useless count is its own, and a copy continues without touching the original.
    Fails if the useless count of a call ignores the lines pending before it
    (``pending_before`` taken as 0), or if copy() shares the prefetch arrays."""
    hierarchy, (addresses, writes, pcs) = reference_case(seed)
    whole = simulate(addresses, hierarchy, writes=writes, pcs=pcs)
    state = CacheState(hierarchy)
    parts = [simulate(addresses[a:b], state, writes=writes[a:b], pcs=pcs[a:b]) for a, b in [(0, 700), (700, 1500)]]
    np.testing.assert_array_equal(sum(part.counts for part in parts), whole.counts)
    np.testing.assert_array_equal(sum(part.prefetch_counts for part in parts), whole.prefetch_counts)
    np.testing.assert_array_equal(state.totals().prefetch_counts, whole.prefetch_counts)
    copy = whole.state.copy()
    simulate(addresses[:200], copy, pcs=pcs[:200])
    np.testing.assert_array_equal(whole.state.totals().prefetch_counts, whole.prefetch_counts)


def test_simulate_many_runs_prefetching_states_one_by_one():
    """simulate_many on a hierarchy with prefetchers gives each stream's simulate result.
    Fails if it takes the parallel path, which has no prefetchers (drop its prefetching branch)."""
    hierarchy, (addresses, writes, _) = reference_case(3)
    results = simulate_many([addresses[:600], addresses[600:]], hierarchy, writes=[writes[:600], writes[600:]])
    for result, (a, b) in zip(results, [(0, 600), (600, 1500)]):
        alone = simulate(addresses[a:b], hierarchy, writes=writes[a:b])
        np.testing.assert_array_equal(result.counts, alone.counts)
        np.testing.assert_array_equal(result.prefetch_counts, alone.prefetch_counts)


# --- configuration ------------------------------------------------------------

@pytest.mark.parametrize("kwargs, field", [
    ({"kind": "markov"}, "Prefetcher.kind"),
    ({"kind": "next-line", "degree": 0}, "Prefetcher.degree"),
    ({"kind": "stride", "distance": 5000}, "Prefetcher.distance"),
    ({"kind": "stride", "trigger": "tagged"}, "Prefetcher.trigger"),
    ({"kind": "stride", "table_size": 0}, "Prefetcher.table_size"),
])
def test_prefetcher_refuses_bad_fields_naming_them(kwargs, field):
    """Fails if a field is not validated (remove its check in Prefetcher.__post_init__)."""
    with pytest.raises(ValueError, match=field):
        Prefetcher(**kwargs)


def test_exclusive_hierarchies_refuse_prefetchers():
    """Fails if the check in Hierarchy.__post_init__ is removed."""
    with pytest.raises(ValueError, match="exclusive"):
        Hierarchy((CacheLevel("L1", 256, 64, 1, prefetcher=Prefetcher("next-line")), CacheLevel("L2", 1024, 64, 2)),
                  inclusion="exclusive")


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_prefetchers_round_trip_through_files(tmp_path, suffix):
    """A prefetcher is a level's optional table; a level without one writes no such key, so
    existing files and outputs are unchanged. Fails if from_dict drops the prefetcher."""
    hierarchy = Hierarchy((CacheLevel("L1", 256, 64, 1, prefetcher=Prefetcher("stride", degree=2, table_size=16)),
                           CacheLevel("L2", 1024, 64, 2)))
    path = hierarchy.save(tmp_path / f"h{suffix}")
    assert Hierarchy.load(path) == hierarchy
    assert "prefetcher" not in hierarchy.levels[1].to_dict()
    text = path.read_text()
    assert text.count("prefetcher") == 1


def test_a_bad_prefetcher_table_in_a_file_names_the_level(tmp_path):
    """Fails if the level's place is not in the message (from_dict's ``where``)."""
    path = tmp_path / "h.json"
    path.write_text(json.dumps({"levels": [{"name": "L1", "size": 256, "line_size": 64,
                                            "prefetcher": {"kind": "stride", "depth": 2}}]}))
    with pytest.raises(ValueError, match=r"levels\[0\]: prefetcher: unknown field"):
        Hierarchy.load(path)


def test_pcs_are_validated():
    """Fails if negative ids reach the kernel (remove the check in as_pcs)."""
    hierarchy = one_level(Prefetcher("stride"))
    with pytest.raises(ValueError, match="pcs must be non-negative"):
        simulate([0, 64], hierarchy, pcs=[0, -1])
    with pytest.raises(ValueError, match=r"pcs must have shape \(2,\)"):
        simulate([0, 64], hierarchy, pcs=[0])


def test_the_schedule_refuses_hierarchies_with_prefetchers(tmp_path):
    """An Experiment's hierarchy with a prefetcher is refused by name, not silently run without it.
    Fails if the check in analyses.experiment._hierarchy is removed."""
    from analyses.experiment import Experiment

    path = Hierarchy((CacheLevel("L1", 256, 64, 1, prefetcher=Prefetcher("next-line")),)).save(tmp_path / "h.toml")
    with pytest.raises(ValueError, match="Experiment.hierarchy: .* has prefetchers"):
        Experiment(hierarchy=str(path)).hierarchy_object()
