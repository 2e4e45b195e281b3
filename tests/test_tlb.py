"""The data TLB against hand-checked cases and a slow reference of each policy."""
import numpy as np
import pytest

from cachesim import CacheState, Hierarchy, alpha21164, get_hierarchy, simulate, simulate_many
from cachesim.tlb import tlb_lookup
from cachesim.tlb_config import DTB_MISS_CYCLES, Tlb, alpha21164_dtb
from reference_tlb import ReferenceTlb

PAGE = 8192


def with_tlb(entries, policy, page_size=PAGE, miss_cycles=10.0):
    machine = alpha21164()
    return Hierarchy(machine.levels, memory_latency=80, inclusion="inclusive",
                     tlb=Tlb(entries, page_size, miss_cycles, policy))


def tlb_counts(pages, entries, policy):
    result = simulate(np.array(pages, dtype=np.uint64) * PAGE + 8, with_tlb(entries, policy))
    return result.tlb_hits, result.tlb_misses


# --- hand-checked cases ------------------------------------------------------

def test_not_last_used_skips_the_entry_just_used_by_hand():
    # Two entries; pages A B A C A. A -> entry 0, B -> entry 1, A hits entry 0,
    # C: the fill pointer is back at entry 0, but entry 0 was used last, so
    # NLU fills entry 1 (evicting B) and A hits again. Round robin (fifo)
    # evicts A for C, so the last A misses. LRU evicts B like NLU here.
    a, b, c = 0, 1, 2
    stream = [a, b, a, c, a]
    assert tlb_counts(stream, 2, "nlu") == (2, 3)
    assert tlb_counts(stream, 2, "fifo") == (1, 4)
    assert tlb_counts(stream, 2, "lru") == (2, 3)


def test_not_last_used_differs_from_lru_by_hand():
    # Three entries; A B C A B D C. After A B C (pointer back at 0) and hits on
    # A then B, D goes to entry 0 (A's; B was used last, not A): C still hits.
    # LRU evicts C, the least recently used, so C misses.
    stream = [0, 1, 2, 0, 1, 3, 2]
    assert tlb_counts(stream, 3, "nlu") == (3, 4)
    assert tlb_counts(stream, 3, "lru") == (2, 5)


def test_every_access_is_looked_up_and_pages_group_addresses():
    # Reads and writes alike; addresses within one 8 KB page share an entry.
    addresses = [0, 8191, 8192, 100, 3 * 8192]
    result = simulate(addresses, with_tlb(4, "nlu"), writes=[True, False, True, False, True])
    assert (result.tlb_accesses, result.tlb_hits, result.tlb_misses) == (5, 2, 3)
    assert result.tlb_cycles == 3 * 10.0
    assert result.to_dict()["tlb"] == {"accesses": 5, "hits": 2, "misses": 3, "cycles": 30.0}


def test_no_tlb_means_no_tlb_counts():
    result = simulate([0, 1, 2], alpha21164())
    assert result.tlb_counts is None and result.tlb_misses is None
    assert "tlb" not in result.to_dict()


# --- against the slow reference ---------------------------------------------

def page_streams(rng, entries, page_size):
    n = 5000
    yield "uniform over 4x the reach", rng.integers(0, 4 * entries * page_size, n)
    yield "cyclic, one page more than the entries", (np.arange(n) % (entries + 1)) * page_size
    yield "cyclic, exactly the entries", (np.arange(n) % entries) * page_size + 17
    walk = np.cumsum(rng.integers(-page_size // 2, page_size // 2 + 64, n)) + (1 << 36)
    yield "local walk above 2**32", walk
    hot = rng.integers(0, entries // 2 * page_size + 1, n)
    yield "hot and cold", np.where(rng.random(n) < 0.85, hot, rng.integers(0, 1 << 30, n))
    yield "runs of one page", np.repeat(rng.integers(0, 3 * entries, n // 5), 5) * page_size
    # mostly back to the page used before the last (tree nodes and primitives), now and then a new page that
    # may evict it: the kernel's check of that entry must agree with a scan
    pair = np.where(np.arange(n) % 2 == 0, rng.integers(0, 2, n), rng.integers(2, 4, n))
    yield "ping-pong between pages", np.where(rng.random(n) < 0.9, pair, rng.integers(0, 2 * entries + 4, n)) \
        * page_size + rng.integers(0, page_size, n)


@pytest.mark.parametrize("policy", ["nlu", "lru", "fifo"])
@pytest.mark.parametrize("entries, page_size", [(64, 8192), (1, 4096), (2, 512), (7, 65536), (48, 8192)])
def test_tlb_matches_reference(policy, entries, page_size):
    """Counts and held pages equal the reference's on every stream (the ping-pong one exercises the kernel's
    check of the entry used before the last). Fails when that check drops ``pages[before] == page`` (checked).
    """
    hierarchy = with_tlb(entries, policy, page_size)
    rng = np.random.default_rng(entries * 31 + page_size)
    for name, stream in page_streams(rng, entries, page_size):
        stream = np.asarray(stream).astype(np.uint64)
        reference = ReferenceTlb(entries, page_size, policy)
        hits = [reference.lookup(address) for address in stream]
        state = CacheState(hierarchy)
        result = simulate(stream, state)
        assert (result.tlb_hits, result.tlb_misses) == (reference.hits, reference.misses), name
        assert sum(hits) == reference.hits
        held = sorted(page for page in state.tlb.pages.tolist() if page >= 0)
        assert held == sorted(page for page in reference.entries if page is not None), name


@pytest.mark.parametrize("policy", ["nlu", "lru", "fifo"])
def test_pieces_equal_one_run_and_copies_are_independent(policy):
    hierarchy = with_tlb(16, policy)
    rng = np.random.default_rng(3)
    stream = rng.integers(0, 40 * PAGE, 6000).astype(np.uint64)
    whole = simulate(stream, hierarchy)
    state = CacheState(hierarchy)
    pieces = [simulate(piece, state) for piece in np.array_split(stream, [1, 2, 500, 3000])]
    assert sum(piece.tlb_misses for piece in pieces) == whole.tlb_misses
    assert state.totals().tlb_counts.tolist() == whole.tlb_counts.tolist()
    clone = state.copy()
    follow = rng.integers(0, 40 * PAGE, 2000).astype(np.uint64)
    assert simulate(follow, clone).tlb_misses == simulate(follow, state).tlb_misses
    simulate(follow, state)
    assert state.tlb.counts.tolist() != clone.tlb.counts.tolist()
    state.reset()
    assert state.tlb.counts.sum() == 0 and (state.tlb.pages == -1).all()


def test_kernel_entry_point_returns_the_misses_of_the_call():
    state = CacheState(with_tlb(8, "nlu"))
    stream = (np.arange(100, dtype=np.uint64) % 10) * PAGE
    misses = tlb_lookup(stream, state.tlb_geometry, state.tlb_arrays)
    reference = ReferenceTlb(8, PAGE, "nlu")
    for address in stream:
        reference.lookup(address)
    assert misses == reference.misses == state.tlb.counts[2]


def test_simulate_many_runs_one_tlb_per_stream():
    hierarchy = with_tlb(4, "nlu")
    rng = np.random.default_rng(9)
    streams = [rng.integers(0, 12 * PAGE, 800 + 100 * s).astype(np.uint64) for s in range(3)]
    many = simulate_many(streams, hierarchy)
    for stream, result in zip(streams, many):
        assert result.tlb_counts.tolist() == simulate(stream, hierarchy).tlb_counts.tolist()


# --- configuration -----------------------------------------------------------

def test_dtb_preset_facts():
    dtb = alpha21164_dtb()
    assert (dtb.entries, dtb.page_size, dtb.policy) == (64, 8192, "nlu")
    assert dtb.miss_cycles == DTB_MISS_CYCLES == 21
    machine = get_hierarchy("alpha21164-dtb")
    assert machine.tlb == dtb and machine.levels == alpha21164().levels


@pytest.mark.parametrize("kwargs, field", [
    (dict(entries=0), "entries"),
    (dict(entries=5000), "entries"),
    (dict(page_size=1000), "page_size"),
    (dict(page_size=256), "page_size"),
    (dict(miss_cycles=-1), "miss_cycles"),
    (dict(policy="random"), "policy"),
    (dict(name=""), "name"),
])
def test_bad_tlb_names_the_field(kwargs, field):
    arguments = dict(entries=64, page_size=8192, miss_cycles=21)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=field):
        Tlb(**arguments)
    with pytest.raises(ValueError, match="Hierarchy.tlb"):
        Hierarchy(alpha21164().levels, tlb="DTB")


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_tlb_round_trips_through_files(tmp_path, suffix):
    hierarchy = get_hierarchy("alpha21164-dtb")
    path = hierarchy.save(tmp_path / f"h{suffix}")
    assert Hierarchy.load(path) == hierarchy
    data = hierarchy.to_dict()
    data["tlb"]["colour"] = "red"
    with pytest.raises(ValueError, match="tlb: unknown field"):
        Hierarchy.from_dict(data)
    del data["tlb"]["colour"], data["tlb"]["miss_cycles"]
    with pytest.raises(ValueError, match="tlb: missing field.*miss_cycles"):
        Hierarchy.from_dict(data)


def test_stacked_tlbs_behave_as_separate_ones():
    from cachesim.tlb import TlbArrays, empty_tlbs

    state = CacheState(with_tlb(4, "nlu"))
    stacked = empty_tlbs(2, 4)
    rng = np.random.default_rng(12)
    streams = [rng.integers(0, 9 * PAGE, 300).astype(np.uint64) for _ in range(2)]
    for index, stream in enumerate(streams):
        tlb = TlbArrays(stacked.pages[index], stacked.stamps[index], stacked.cursor[index], stacked.counts[index])
        tlb_lookup(stream, state.tlb_geometry, tlb)
    for index, stream in enumerate(streams):
        reference = ReferenceTlb(4, PAGE, "nlu")
        for address in stream:
            reference.lookup(address)
        assert stacked.counts[index].tolist() == [300, reference.hits, reference.misses]


# --- entry guesses -------------------------------------------------------------

def test_entry_guesses_by_hand():
    """Four entries, NLU; pages A = 0 and B = 256 share a guess (their low bits), C = 1 has its own.
    A B C miss (entries 0-2, guesses A -> 0, B -> 1 over it, C -> 2); A: neither of the last two pages,
    its guess is B's entry, which does not hold it: the scan finds entry 0 (a hit; guess -> 0); B: the guess
    (0) is A's, the scan finds entry 1 (guess -> 1); C: the guess holds it. Fails when a guess is taken
    without the check that its entry holds the page (``if pages[found] != page`` made ``if False``: checked).
    """
    from cachesim.tlb import HINTS, N_CURSOR, NLU, TlbGeometry, empty_tlb

    a, b, c = 0, HINTS, 1
    tlb = empty_tlb(4)
    misses = tlb_lookup(np.array([a, b, c, a, b, c], dtype=np.uint64) * PAGE, TlbGeometry(13, 4, NLU), tlb)
    assert misses == 3 and tlb.counts.tolist() == [6, 3, 3]
    assert tlb.pages.tolist() == [a, b, c, -1]
    assert tlb.cursor[N_CURSOR:N_CURSOR + 2].tolist() == [1, 2]


@pytest.mark.parametrize("policy", ["nlu", "lru", "fifo"])
@pytest.mark.parametrize("entries", [1, 3, 8, 64])
def test_entry_guesses_change_nothing(policy, entries):
    """A TLB with entry guesses (:func:`cachesim.tlb.empty_tlb`) against the reference and against the same
    TLB whose cursor has no guesses, on seeded random streams whose pages crowd a few guesses (pages that
    share their low bits), in pieces: equal counts, entries, stamps and cursor columns. Fails when a guess
    is taken without the check that its entry holds the page (checked)."""
    from cachesim.tlb import HINTS, N_CURSOR, TlbArrays, empty_tlb

    state = CacheState(with_tlb(entries, policy))
    rng = np.random.default_rng(entries * 7 + len(policy))
    n = 4000
    crowded = rng.integers(0, 3 * entries + 2, n) * HINTS + rng.integers(0, 3, n)
    pair = np.where(np.arange(n) % 2 == 0, crowded[0], crowded[1])
    streams = [crowded, np.where(rng.random(n) < 0.8, pair, crowded), rng.integers(0, 4 * entries, n)]
    for pages in streams:
        stream = (pages * PAGE + rng.integers(0, PAGE, n)).astype(np.uint64)
        reference = ReferenceTlb(entries, PAGE, policy)
        for address in stream:
            reference.lookup(address)
        guessing = empty_tlb(entries)
        plain = TlbArrays(guessing.pages.copy(), guessing.stamps.copy(), guessing.cursor[:N_CURSOR].copy(),
                          guessing.counts.copy())
        for piece in np.array_split(stream, [1, 7, 1500]):
            assert tlb_lookup(piece, state.tlb_geometry, guessing) == tlb_lookup(piece, state.tlb_geometry, plain)
        assert guessing.counts.tolist() == plain.counts.tolist() == [n, reference.hits, reference.misses]
        np.testing.assert_array_equal(guessing.pages, plain.pages)
        np.testing.assert_array_equal(guessing.stamps, plain.stamps)
        np.testing.assert_array_equal(guessing.cursor[:N_CURSOR], plain.cursor)
