"""cachesim.multicore: shared levels and write-invalidate coherence against an interleaved reference."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy, alpha21164, alpha21164_with_dtb, simulate
from cachesim.interleave import interleave, interleave_order
from cachesim.multicore import simulate_threads
from cachesim.multicore_state import (BACK_INVALIDATIONS, COHERENCE_INVALIDATIONS, COHERENCE_MISSES,
                                      FALSE_SHARING_MISSES, SharedState)
from cachesim.sets import EVICTIONS, HITS, MISSES
from cachesim.sharing import SHARING, SharedHierarchy, private
from reference_multicore import reference_threads


def random_machine(rng):
    """2-4 cores, SMT 1-2, 2-3 small levels with growing lines and random sharing, policy and inclusion."""
    n_levels = int(rng.integers(2, 4))
    inclusion = str(rng.choice(["non-inclusive", "inclusive"]))
    line = int(rng.choice([8, 16]))
    levels = []
    for index in range(n_levels):
        line = line * int(rng.choice([1, 2])) if index else line
        ways = int(rng.choice([1, 2, 3, 4]))
        sets = int(rng.choice([1, 2, 3, 4, 8]))
        levels.append(CacheLevel(f"L{index + 1}", line * ways * sets * (index + 1), line, ways,
                                 str(rng.choice(["lru", "fifo", "random"])), seed=int(rng.integers(0, 9)),
                                 write_allocate=bool(index or rng.random() < 0.5)))
    scopes = sorted(rng.choice(len(SHARING), n_levels))
    n_cores = int(rng.integers(2, 5))
    per_complex = int(rng.choice([d for d in range(1, n_cores + 1) if n_cores % d == 0]))
    return SharedHierarchy(Hierarchy(tuple(levels), inclusion=inclusion), n_cores=n_cores,
                           smt=int(rng.integers(1, 3)), cores_per_complex=per_complex,
                           shared_by=tuple(SHARING[s] for s in scopes))


def random_stream(rng, machine, n):
    """Accesses to a few dozen lines, a third of them writes, 1-8 bytes each, random kinds; four in
    ten repeat the line and thread of the access before (other bytes, flag and kind)."""
    line = machine.hierarchy.levels[0].line_size
    fresh = np.maximum.accumulate(np.where(rng.random(n) < 0.4, 0, np.arange(n)))
    lines = rng.integers(0, 40, n)[fresh]
    addresses = lines * line + rng.integers(0, line, n)
    sizes = np.minimum(rng.integers(1, 9, n), line - addresses % line)
    return (addresses, rng.integers(0, machine.n_threads, n)[fresh], rng.random(n) < 0.3, sizes,
            rng.integers(0, 16, n))


@pytest.mark.parametrize("seed", range(12))
def test_random_machines_match_the_reference(seed):
    """Every counter of every instance and kind, and each thread's served counts, equal the
    reference's, for one call and for the stream run in two calls on one state.
    Mutations: drop the ``_drop_ghost`` of the line's own ghost in _fill_level; drop
    ``and thread == previous_thread`` in _replay."""
    rng = np.random.default_rng(seed)
    machine = random_machine(rng)
    addresses, threads, writes, sizes, kinds = random_stream(rng, machine, 1500)
    expected, served = reference_threads(addresses, threads, machine, writes, sizes, kinds)
    result = simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds)
    np.testing.assert_array_equal(result.counts, expected)
    np.testing.assert_array_equal(result.served, served)
    assert expected[..., COHERENCE_INVALIDATIONS].sum() > 0  # the case exercises coherence
    state = SharedState(machine)
    cut = 700
    first = simulate_threads(addresses[:cut], threads[:cut], state, writes=writes[:cut], sizes=sizes[:cut],
                             kinds=kinds[:cut])
    second = simulate_threads(addresses[cut:], threads[cut:], state, writes=writes[cut:], sizes=sizes[cut:],
                              kinds=kinds[cut:])
    np.testing.assert_array_equal(first.counts + second.counts, expected)


def wide_machine(rng):
    """:func:`random_machine`'s kind of machine with 1-3 levels of 1-16 ways, the associativities that have
    a loop of their own (8, 12, 16) among them, one or two sets; the first level private to a thread or a core."""
    n_levels = int(rng.integers(1, 4))
    line = int(rng.choice([8, 16]))
    levels = []
    for index in range(n_levels):
        ways = int(rng.choice([8, 12, 16, 5, 1]))
        levels.append(CacheLevel(f"L{index + 1}", line * ways * int(rng.choice([1, 2])) * (index + 1), line, ways,
                                 str(rng.choice(["lru", "lru", "fifo", "random"])), seed=int(rng.integers(0, 9)),
                                 write_allocate=bool(index or rng.random() < 0.5)))
    scopes = sorted([int(rng.integers(0, 2))] + list(rng.choice(len(SHARING), n_levels - 1)))  # first: thread or core
    return SharedHierarchy(Hierarchy(tuple(levels), inclusion=str(rng.choice(["non-inclusive", "inclusive"]))),
                           n_cores=int(rng.integers(2, 4)), smt=int(rng.integers(1, 3)),
                           shared_by=tuple(SHARING[s] for s in scopes))


@pytest.mark.parametrize("seed", range(10))
def test_wide_sets_and_single_levels_match_the_reference(seed):
    """Sets of up to 16 ways (each way compared and the victim found by fixed-length loops) and machines
    of one level (no second level to serve a first-level miss): every counter and the served counts equal
    the reference's, on a stream of 3-8 times as many lines as the first level holds, so that the wide sets fill,
    evict and lose lines to invalidations.
    Mutations: ``_probe_ways(tags, base, 8, line)`` in _probe's 12-way branch; ``if True:`` for
    ``if not is_write or geometry.write_allocate[0]:`` in shared_access (a write fills a first level that
    does not allocate on writes)."""
    rng = np.random.default_rng(300 + seed)
    machine = wide_machine(rng)
    level = machine.hierarchy.levels[0]
    n = 2500
    line = level.line_size
    held = level.size // line
    fresh = np.maximum.accumulate(np.where(rng.random(n) < 0.3, 0, np.arange(n)))
    addresses = rng.integers(0, held * int(rng.integers(3, 9)), n)[fresh] * line + rng.integers(0, line, n)
    sizes = np.minimum(rng.integers(1, 9, n), line - addresses % line)
    threads, writes, kinds = rng.integers(0, machine.n_threads, n)[fresh], rng.random(n) < 0.25, rng.integers(0, 16, n)
    expected, served = reference_threads(addresses, threads, machine, writes, sizes, kinds)
    result = simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds)
    np.testing.assert_array_equal(result.counts, expected)
    np.testing.assert_array_equal(result.served, served)
    assert expected[..., COHERENCE_INVALIDATIONS].sum() > 0 and expected[..., EVICTIONS].sum() > 0


def uniform_machine(rng):
    """:func:`random_machine` with every level's lines of the first level's size (the owners table is on) and
    the first level private to a thread or a core (SMT threads sharing it), so that writes invalidate."""
    machine = random_machine(rng)
    first = SHARING.index(str(rng.choice(["thread", "core"])))
    scopes = tuple(SHARING[min(first, SHARING.index(scope))] if index == 0 else scope
                   for index, scope in enumerate(machine.shared_by))
    line = machine.hierarchy.levels[0].line_size
    levels = tuple(CacheLevel(level.name, line * level.ways * level.n_sets, line, level.ways, level.policy,
                              seed=level.seed, write_allocate=level.write_allocate)
                   for level in machine.hierarchy.levels)
    return SharedHierarchy(Hierarchy(levels, inclusion=machine.hierarchy.inclusion), n_cores=machine.n_cores,
                           smt=machine.smt, cores_per_complex=machine.cores_per_complex, shared_by=scopes)


def owned_stream(rng, machine, n):
    """Runs of 1-30 accesses by one thread to 2-6 of a few dozen lines, half of them writes: writes to lines
    the thread alone holds, then reads and writes by others (many sharers)."""
    line = machine.hierarchy.levels[0].line_size
    runs = rng.integers(1, 31, n)
    starts = np.cumsum(runs)[np.cumsum(runs) < n]
    run_of = np.zeros(n, dtype=np.int64)
    run_of[starts] = 1
    run_of = np.cumsum(run_of)
    threads = rng.integers(0, machine.n_threads, run_of[-1] + 1)[run_of]
    pools = rng.integers(0, 30, (run_of[-1] + 1, 6))
    lines = pools[run_of, rng.integers(0, 6, n) % rng.integers(2, 7, run_of[-1] + 1)[run_of]]
    addresses = lines * line + rng.integers(0, line, n)
    sizes = np.minimum(rng.integers(1, 9, n), line - addresses % line)
    return addresses, threads, rng.random(n) < 0.5, sizes, rng.integers(0, 16, n)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("owners_size", [0, 2, None])
def test_owned_writes_match_the_reference(seed, owners_size):
    """Writes that skip the search for other copies (the owners table), on machines whose levels all have
    one line size: counts and served equal the reference's, with the table off (0 entries), crowded
    (2 entries) and as made. Mutations: drop ``_note_fill`` in shared_access (a line another thread
    filled is still owned); ``owners[entry, 1] |= _thread_bit(thread)`` -> ``= _thread_bit(thread)`` in
    _note_fill (only the last filler's copies are searched); ``_thread_bit(thread)`` -> ``_thread_bit(0)``
    at the end of _write_invalidate (checked)."""
    rng = np.random.default_rng(100 + seed)
    machine = uniform_machine(rng)
    addresses, threads, writes, sizes, kinds = owned_stream(rng, machine, 2000)
    state = SharedState(machine)
    assert state.owners.shape[0] > 0
    if owners_size is not None:
        state.owners = np.full((owners_size, 2), -1, dtype=np.int64)
    result = simulate_threads(addresses, threads, state, writes=writes, sizes=sizes, kinds=kinds)
    expected, served = reference_threads(addresses, threads, machine, writes, sizes, kinds)
    np.testing.assert_array_equal(result.counts, expected)
    np.testing.assert_array_equal(result.served, served)
    assert expected[..., COHERENCE_INVALIDATIONS].sum() > 0


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("n_cores, smt, chosen", [(36, 2, (0, 1, 64, 65, 2, 66)),
                                                  (24, 3, (0, 1, 63, 64, 65, 2))])
def test_sharer_masks_of_threads_64_apart_match_the_reference(seed, n_cores, smt, chosen):
    """On machines of 72 hardware threads, threads 64 apart share a bit of the owners table's sharers masks;
    a stream of runs by a few such threads, to lines they all read and write (many sharers), gives the
    reference's counts and served counts. With SMT 3, core 21 serves threads 63-65, whose bits wrap round
    from 63 to 0 and 1.
    Mutations: drop ``machine.instance_of.shape[1] <= 64 and`` in _write_invalidate (a write by thread 0
    after thread 64 filled the line then searches no other instance); drop the wrap-around term
    ``| (ones >> ...)`` in _instance_bits (SMT 3 cases fail: the core of threads 63-65 is not searched
    for bits 0 and 1)."""
    rng = np.random.default_rng(400 + seed)
    levels = (CacheLevel("L1", 16 * 2 * 2, 16, 2), CacheLevel("L2", 16 * 4 * 2, 16, 4),
              CacheLevel("L3", 16 * 4 * 8, 16, 4))
    scopes = (str(rng.choice(["thread", "core"])), "core", "machine")
    machine = SharedHierarchy(Hierarchy(levels), n_cores=n_cores, smt=smt, shared_by=scopes)
    addresses, threads, writes, sizes, kinds = owned_stream(rng, machine, 1500)
    threads = np.array(chosen)[threads % len(chosen)]
    state = SharedState(machine)
    assert state.owners.shape[0] > 0
    result = simulate_threads(addresses, threads, state, writes=writes, sizes=sizes, kinds=kinds)
    expected, served = reference_threads(addresses, threads, machine, writes, sizes, kinds)
    np.testing.assert_array_equal(result.counts, expected)
    np.testing.assert_array_equal(result.served, served)
    assert expected[..., COHERENCE_INVALIDATIONS].sum() > 0


def test_a_crowded_ghost_filter_stays_exact():
    """With a filter of two entries nearly every miss and fill collides with some ghost's entry;
    the counts still equal the reference's.
    Mutation: ``ghost_filter[entry] -= 2`` in _drop_ghost."""
    rng = np.random.default_rng(21)
    machine = random_machine(rng)
    addresses, threads, writes, sizes, kinds = random_stream(rng, machine, 1500)
    state = SharedState(machine)
    state.ghost_filter = np.zeros(2, dtype=np.int32)
    result = simulate_threads(addresses, threads, state, writes=writes, sizes=sizes, kinds=kinds)
    expected, _ = reference_threads(addresses, threads, machine, writes, sizes, kinds)
    np.testing.assert_array_equal(result.counts, expected)
    assert expected[..., COHERENCE_MISSES].sum() > 0


def test_a_copied_state_continues_independently():
    """Mutation: leave "ghosts" out of the arrays SharedState.copy copies (the clone shares them)."""
    rng = np.random.default_rng(3)
    machine = random_machine(rng)
    addresses, threads, writes, sizes, _ = random_stream(rng, machine, 1200)
    state = SharedState(machine)
    simulate_threads(addresses[:600], threads[:600], state, writes=writes[:600], sizes=sizes[:600])
    clone = state.copy()
    once = simulate_threads(addresses[600:], threads[600:], state, writes=writes[600:], sizes=sizes[600:])
    again = simulate_threads(addresses[600:], threads[600:], clone, writes=writes[600:], sizes=sizes[600:])
    np.testing.assert_array_equal(once.counts, again.counts)
    assert once.counts[..., COHERENCE_MISSES].sum() > 0


@pytest.mark.parametrize("make", [alpha21164, lambda: Hierarchy(
    (CacheLevel("L1", 512, 16, 2, "random", seed=3), CacheLevel("L2", 2048, 32, 4, "fifo")),
    inclusion="inclusive")])
def test_one_thread_of_private_levels_equals_simulate(make):
    """Mutation: fill the levels top-down (``range(served)``) in _fill."""
    rng = np.random.default_rng(7)
    addresses = rng.integers(0, 1 << 23, 20000) & ~np.int64(3)
    writes = rng.random(addresses.size) < 0.2
    expected = simulate(addresses, make(), writes=writes)
    result = simulate_threads(addresses, np.zeros(addresses.size, dtype=np.int64), private(make()), writes=writes)
    np.testing.assert_array_equal(result.level_counts()[:, :8], expected.counts)
    served = np.bincount(simulate(addresses, make(), writes=writes, return_levels=True).served_by,
                         minlength=len(make().levels) + 1)
    np.testing.assert_array_equal(result.served[0], served)


def two_cores():
    """Two cores of one thread; 64-byte lines; private 1 KB L1s under a shared 8 KB L2."""
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 64, 2), CacheLevel("L2", 8192, 64, 4)))
    return SharedHierarchy(hierarchy, n_cores=2, shared_by=("core", "machine"))


def ping_pong(n, first_bytes):
    """Threads 0 and 1 write in turn to line 0x1000; thread t writes 4 bytes from ``first_bytes[t]``."""
    threads = np.arange(n) % 2
    return (0x1000 + np.array(first_bytes)[threads], threads, np.ones(n, dtype=bool), np.full(n, 4))


def test_ping_pong_writes_invalidate_each_other():
    """Both threads write the same bytes in turn: write i (i >= 1) removes the line from the other L1,
    so every write misses its L1, all after the first two are coherence misses, none false sharing;
    the shared L2 holds the line throughout (one cold miss). Counted by hand for 10 writes.
    Mutation: ``continue`` at the top of _invalidate_others' instance loop (no invalidation)."""
    addresses, threads, writes, sizes = ping_pong(10, [0, 0])
    result = simulate_threads(addresses, threads, two_cores(), writes=writes, sizes=sizes)
    l1 = result.counts[0].sum(axis=1)  # per instance
    assert l1[:, MISSES].tolist() == [5, 5]
    assert l1[:, COHERENCE_INVALIDATIONS].tolist() == [5, 4]  # thread 0's copy lost after writes 1, 3, ..., 9
    assert l1[:, COHERENCE_MISSES].tolist() == [4, 4]
    assert l1[:, FALSE_SHARING_MISSES].tolist() == [0, 0]
    l2 = result.counts[1].sum(axis=1)
    assert l2[0, MISSES] == 1 and l2[0, HITS] == 9 and l2[0, COHERENCE_INVALIDATIONS] == 0


def test_disjoint_bytes_of_one_line_are_false_sharing():
    """Thread 0 writes bytes 0-3 and thread 1 bytes 4-7 of one line (adjacent, disjoint): the same
    misses as ping-pong, and every coherence miss is a false-sharing miss.
    Mutation: ``end < written_first or written_end < first`` in _count_miss (touching counts as shared)."""
    addresses, threads, writes, sizes = ping_pong(10, [0, 4])
    frame = simulate_threads(addresses, threads, two_cores(), writes=writes, sizes=sizes).to_frame()
    l1 = frame[frame.level == "L1"]
    assert l1.coherence_misses.tolist() == [4, 4]
    assert l1.false_sharing_misses.tolist() == [4, 4]
    assert l1.threads.tolist() == ["0", "1"]
    assert frame[frame.level == "L2"].threads.tolist() == ["0-1"]
    # Without byte ranges an access covers its line: the same coherence misses, no false sharing.
    whole = simulate_threads(addresses, threads, two_cores(), writes=writes).to_frame()
    assert whole.coherence_misses.tolist() == [4, 4, 0] and whole.false_sharing_misses.sum() == 0


def test_a_ghost_lasts_until_its_way_is_filled():
    """Thread 1 reads A, thread 0 writes A (thread 1's copy becomes a ghost). Then thread 1 reads B
    of the other L1 set and A: a coherence miss; or C of A's set, which fills the ghost's way, and
    A: an ordinary miss. In an L1 that does not allocate writes, a write miss on the ghost leaves it,
    so the read after it is a coherence miss too. Direct-mapped L1s of 2 sets, counted by hand.
    Mutation: leave out the ``_drop_ghost`` of the way an empty-way fill takes, in _fill_level."""
    def l1_coherence_misses(addresses, threads, writes, allocate=True):
        hierarchy = Hierarchy((CacheLevel("L1", 128, 64, 1, write_allocate=allocate), CacheLevel("L2", 4096, 64, 4)))
        machine = SharedHierarchy(hierarchy, n_cores=2, shared_by=("core", "machine"))
        result = simulate_threads(addresses, threads, machine, writes=writes)
        return result.counts[0, 1, :, COHERENCE_MISSES].sum()

    a, b, c = 0x1000, 0x1040, 0x1080  # sets 0, 1, 0
    assert l1_coherence_misses([a, a, b, a], [1, 0, 1, 1], [False, True, False, False]) == 1
    assert l1_coherence_misses([a, a, c, a], [1, 0, 1, 1], [False, True, False, False]) == 0
    assert l1_coherence_misses([a, a, a, a], [1, 0, 1, 1], [False, True, True, False], allocate=False) == 2


def test_level_totals_and_json_agree_with_the_instance_rows():
    """Mutation: sum only instance 0 in level_counts (``self.counts[:, 0].sum(axis=1)``)."""
    import json

    rng = np.random.default_rng(3)
    machine = random_machine(rng)
    addresses, threads, writes, sizes, kinds = random_stream(rng, machine, 800)
    result = simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds)
    rows = result.to_frame()
    levels = result.level_frame()
    summed = rows.drop(columns=["instance", "threads", "kind"]).groupby("level", sort=False).sum()
    assert summed.to_dict(orient="list") == levels.drop(columns="instances").set_index("level").to_dict(orient="list")
    assert levels.instances.tolist() == [machine.n_instances(level) for level in range(len(levels))]
    table = json.loads(json.dumps(result.to_dict()))
    assert table["levels"][0]["coherence_misses"] == int(levels.coherence_misses[0])
    assert len(table["instances"]) == len(rows) and table["served"] == result.served.tolist()
    assert SharedHierarchy.from_dict(table["machine"]) == machine


def test_a_read_only_shared_line_is_never_invalidated():
    """Both threads read one line 20 times in turn: one cold L1 miss each, one L2 miss, nothing lost.
    Mutation: call _invalidate_others for reads too (``if True:``)."""
    threads = np.arange(40) % 2
    result = simulate_threads(np.full(40, 0x2000), threads, two_cores())
    counts = result.level_counts()
    assert counts[0, MISSES] == 2 and counts[1, MISSES] == 1
    assert counts[:, COHERENCE_INVALIDATIONS].sum() == 0 and counts[:, COHERENCE_MISSES].sum() == 0
    assert result.served.tolist() == [[19, 0, 1], [19, 1, 0]]


def test_an_inclusive_shared_level_back_invalidates_the_instances_it_serves():
    """A shared direct-mapped L2 of 2 lines under private L1s: thread 0 reads A, thread 1 reads B
    (same L2 set), which evicts A from L2 and so from thread 0's L1 only; thread 0 reads A again,
    which evicts B and removes it from thread 1's L1 only. Counted by hand.
    Mutation: back-invalidate only instance ``instance`` of each upper level in _back_invalidate."""
    hierarchy = Hierarchy((CacheLevel("L1", 256, 64, 4), CacheLevel("L2", 128, 64, 1)), inclusion="inclusive")
    machine = SharedHierarchy(hierarchy, n_cores=2, shared_by=("thread", "machine"))
    result = simulate_threads([0, 128, 0], [0, 1, 0], machine, kinds=[3, 5, 3])
    back = result.counts[0, :, :, BACK_INVALIDATIONS]
    assert back[0, 5] == 1 and back[1, 3] == 1 and back.sum() == 2  # by the kind of the evicting access
    assert result.served.tolist() == [[0, 0, 2], [0, 0, 1]]
    frame = result.to_frame()
    assert frame[frame.level == "L1"].kind.tolist() == [3, 5, 3, 5]
    assert frame[frame.level == "L1"].back_invalidations.tolist() == [0, 1, 1, 0]


def test_interleave_takes_quantum_accesses_per_turn():
    """Mutation: sort by ``(rounds, threads)`` the other way round (thread-major order)."""
    addresses, threads = interleave([[1, 2, 3, 4, 5], [10, 20], [100, 200, 300]], quantum=2)
    assert addresses.tolist() == [1, 2, 10, 20, 100, 200, 3, 4, 300, 5]
    assert threads.tolist() == [0, 0, 1, 1, 2, 2, 0, 0, 2, 0]
    with pytest.raises(ValueError, match="quantum must be an integer >= 1"):
        interleave([[1]], quantum=0)


def test_interleave_by_time_takes_windows_of_quantum():
    """Thread 0 issues at cycles 0, 1, 5, 9 and thread 1 at 2, 3, 4, 10; in windows of 4 cycles:
    [0, 4): 0's 0, 1 then 1's 2, 3; [4, 8): 0's 5, 1's 4; [8, 12): 0's 9, 1's 10 (by hand). With one
    access a cycle each and quantum 1 the threads alternate access by access.
    Mutation: ``rounds.append(stamps)`` (windows of one cycle whatever the quantum)."""
    addresses, threads = interleave([[10, 11, 12, 13], [20, 21, 22, 23]], quantum=4,
                                    times=[[0, 1, 5, 9], [2, 3, 4, 10]])
    assert addresses.tolist() == [10, 11, 20, 21, 12, 22, 13, 23]
    assert threads.tolist() == [0, 0, 1, 1, 0, 1, 0, 1]
    order, threads = interleave_order([3, 2], 1, times=[np.arange(3), np.arange(2)])
    assert order.tolist() == [0, 3, 1, 4, 2] and threads.tolist() == [0, 1, 0, 1, 0]
    with pytest.raises(ValueError, match=r"times\[1\] must not decrease; it does at access 2"):
        interleave_order([2, 3], 2, times=[[0, 1], [0, 5, 4]])
    with pytest.raises(ValueError, match=r"times\[0\] must have shape \(2,\)"):
        interleave_order([2], 2, times=[[0, 1, 2]])


@pytest.mark.parametrize("kwargs, message", [
    ({"thread_ids": [0, 2]}, r"thread_ids\[1\] is 2; expected an integer in \[0, 2\)"),
    ({"kinds": [0, 16]}, r"kinds\[1\] is 16"),
    ({"sizes": [4, 0]}, r"sizes\[1\] is 0"),
    ({"sizes": [4]}, r"sizes must have shape \(2,\)"),
    ({"thread_ids": [0.0, 1.0]}, "thread_ids must be integers"),
])
def test_bad_streams_name_the_argument(kwargs, message):
    """Mutation: drop the range check in cachesim.inputs.small_integers."""
    arguments = {"thread_ids": [0, 1], **kwargs}
    thread_ids = arguments.pop("thread_ids")
    with pytest.raises(ValueError, match=message):
        simulate_threads([0, 64], thread_ids, two_cores(), **arguments)


def test_unsupported_hierarchies_are_refused():
    """Mutation: drop the exclusive check in SharedState.__init__."""
    exclusive = Hierarchy((CacheLevel("L1", 256, 64, 2), CacheLevel("L2", 1024, 64, 4)), inclusion="exclusive")
    with pytest.raises(ValueError, match="exclusive hierarchies are not simulated with threads"):
        simulate_threads([0], [0], private(exclusive))
    with pytest.raises(ValueError, match="data TLB is not simulated with threads"):
        simulate_threads([0], [0], private(alpha21164_with_dtb()))
    one_byte = Hierarchy((CacheLevel("L1", 64, 1, 4),))
    with pytest.raises(ValueError, match="addresses must be below 2\\*\\*63"):
        simulate_threads([2**63], [0], private(one_byte))
