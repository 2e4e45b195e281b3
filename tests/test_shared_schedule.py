"""coherence.shared_schedule / shared_run: the schedule on shared levels, against the interleaved replay."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy, Prefetcher
from cachesim.multicore import simulate_threads
from cachesim.multicore_state import COHERENCE_INVALIDATIONS, COHERENCE_MISSES, FALSE_SHARING_MISSES
from cachesim.sharing import SharedHierarchy
from coherence.cost import get_cost_model
from coherence.layout import get_layout
from coherence.mappings import get_mapping
from coherence.shared_run import pixel_pieces, simulate_shared_run
from coherence.shared_schedule import COUNTER_ACCESS, cpu_threads
from coherence.simulation import Machine
from coherence.thread_streams import COUNTER_BYTES, PRIVATE_KINDS
from coherence.studies import place_layout
from test_thread_streams import SCENE_KINDS, synthetic_trace
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack
from tracer.trace.records import AUXILIARY_KIND

COST = get_cost_model("modern")


def tiny_machine(smt, shared_by, seed, prefetchers=(None, None)):
    """Two cores of ``smt`` threads with a small L1 and L2, so that lines are evicted and shared; ``prefetchers``
    of L1 and L2."""
    rng = np.random.default_rng(seed)
    l1_ways = int(rng.choice([1, 2, 4]))
    hierarchy = Hierarchy((CacheLevel("L1", 32 * 4 * l1_ways, 32, l1_ways, "lru", latency=1,
                                      prefetcher=prefetchers[0]),
                           CacheLevel("L2", 4096, 32, 4, "lru", latency=6, prefetcher=prefetchers[1])),
                          memory_latency=40, name="tiny")
    return SharedHierarchy(hierarchy, n_cores=2, smt=smt, shared_by=shared_by)


def replay_log(run, machine, pieces):
    """The logged order replayed access by access through cachesim.multicore.simulate_threads (a task counter
    access: a write of its 4 bytes, of the auxiliary kind)."""
    addresses, threads, piece = run.log
    counter = piece == COUNTER_ACCESS
    writes = np.where(counter, True, pieces.writes[piece])
    sizes = np.where(counter, COUNTER_BYTES, pieces.sizes[piece])
    kinds = np.where(counter, AUXILIARY_KIND, pieces.kinds[piece]).astype(np.uint8)
    return simulate_threads(addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds)


NEXT_LINE = Prefetcher("next-line", degree=2, distance=1, trigger="access")
STRIDE = Prefetcher("stride", degree=2, distance=1, trigger="access", table_size=8)


@pytest.mark.parametrize("seed, mapping, n_processes, smt, shared_by, scheduler, prefetchers", [
    (0, "P", 3, 1, ("thread", "machine"), "shared-queue", (None, None)),
    (1, "S", 4, 2, ("thread", "machine"), "static", (None, None)),
    (2, "DB", 5, 2, ("core", "machine"), "shared-queue", (None, None)),
    (3, "B", 2, 2, ("thread", "core"), "shared-queue", (None, None)),
    (4, "R", 6, 1, ("thread", "thread"), "static", (None, None)),
    (5, "P", 3, 2, ("thread", "machine"), "shared-queue", (NEXT_LINE, STRIDE)),
    (6, "S", 4, 2, ("core", "machine"), "static", (Prefetcher("next-line", trigger="tagged"), None)),
    (7, "DB", 5, 1, ("thread", "machine"), "shared-queue", (STRIDE, NEXT_LINE)),
    (8, "R", 3, 2, ("thread", "core"), "static", (None, Prefetcher("next-line", degree=3, trigger="miss"))),
])
def test_q1_equals_the_interleaved_replay_of_its_order(seed, mapping, n_processes, smt, shared_by, scheduler,
                                                       prefetchers):
    """At Q = 1 every count of every instance (and the accesses each thread had served by each level, and the
    prefetches issued, useful, useless and pending of each instance) equals simulate_threads replaying the order
    the kernel served the accesses in, with the same prefetchers; each process's per-level counts sum to the
    machine's. Mutations: ``shared_access(thread, address, is_write, ...`` -> ``shared_access(0, address,
    is_write, ...`` in _event_loop; ``if prefetchers is not None:`` -> ``if False:`` before the access loop's
    prefetching_access (the prefetch cases then fail)."""
    trace = synthetic_trace(7, 5, seed=seed)
    placed = place_layout(get_layout("alpha1997"), trace)
    machine = tiny_machine(smt, shared_by, seed, prefetchers)
    distribution = get_mapping(mapping).build(trace.width, trace.height, n_processes)
    os_machine = Machine(n_cpus=machine.n_threads, quantum_cycles=400.0, scheduler=scheduler, switch_cycles=3.0)
    compute = np.random.default_rng(seed).uniform(0, 50, trace.width * trace.height)
    run = simulate_shared_run(trace, distribution, machine, placed, COST, os_machine, interleave_cycles=1,
                              compute=compute, record=("log",))
    pieces = pixel_pieces(trace, placed, 32)
    hand_outs = distribution.n_tasks if distribution.dynamic else 0
    assert np.array_equal(np.sort(run.log[2][run.log[2] >= 0]), np.arange(pieces.addresses.size))  # each once
    assert (run.log[2] == COUNTER_ACCESS).sum() == hand_outs
    reference = replay_log(run, machine, pieces)
    np.testing.assert_array_equal(run.shared.counts, reference.counts)
    np.testing.assert_array_equal(run.shared.served, reference.served)
    if machine.hierarchy.prefetches:
        np.testing.assert_array_equal(run.shared.prefetch_counts, reference.prefetch_counts)
        np.testing.assert_array_equal(run.shared.prefetch_pending, reference.prefetch_pending)
        assert run.shared.prefetch_counts[..., 0].sum() > 0
    else:
        assert run.shared.prefetch_counts is None
    processes = run.run.processes
    totals = run.shared.level_counts()
    for level, name in enumerate(machine.hierarchy.level_names):
        assert processes[f"{name}_misses"].sum() == totals[level, 2]
    assert processes["pixels"].sum() == trace.width * trace.height


def test_larger_q_still_replays_exactly_and_keeps_each_process_in_order():
    """At Q = 200 the logged order still replays to the same counts, and each process's accesses come in
    its pixels' order (a turn splits a pixel but never reorders it). Mutation: ``shared_access(thread, address,
    is_write, ...`` -> ``shared_access(0, address, is_write, ...`` in _event_loop."""
    trace = synthetic_trace(6, 6, seed=7)
    placed = place_layout(get_layout("alpha1997"), trace)
    machine = tiny_machine(2, ("thread", "machine"), 7)
    distribution = get_mapping("P").build(6, 6, 4)
    run = simulate_shared_run(trace, distribution, machine, placed, COST, Machine(n_cpus=4, quantum_cycles=0),
                              interleave_cycles=200, compute=np.full(36, 30.0), record=("log",))
    pieces = pixel_pieces(trace, placed, 32)
    np.testing.assert_array_equal(run.shared.counts, replay_log(run, machine, pieces).counts)
    piece = run.log[2]
    thread_of = cpu_threads(2, 2)  # static round robin: process p on CPU p
    for process in range(4):
        pixels = distribution.process_pixels(process)
        expected = np.concatenate([np.arange(pieces.piece_offsets[p], pieces.piece_offsets[p + 1]) for p in pixels])
        np.testing.assert_array_equal(piece[run.log[1] == thread_of[process]], expected)


def test_a_shared_run_is_never_recosted():
    """A run on shared levels says its counts depend on cycles, so re-costing refuses it even where a
    private-cache run of the same mapping and machine would qualify (one process per CPU, static mapping,
    no other users). Fails if simulate_shared_run passes fixed_schedule(distribution, machine) (checked)."""
    from coherence.recost import fixed_schedule, recost_run

    trace = synthetic_trace(4, 4, seed=3)
    placed = place_layout(get_layout("alpha1997"), trace)
    machine = tiny_machine(1, ("thread", "machine"), 3)
    distribution = get_mapping("S").build(4, 4, 2)
    os_machine = Machine(n_cpus=2, quantum_cycles=0)
    assert fixed_schedule(distribution, os_machine)
    run = simulate_shared_run(trace, distribution, machine, placed, COST, os_machine, interleave_cycles=100)
    assert not run.run.miss_counts.fixed_schedule
    assert recost_run(run.run, machine.hierarchy, COST) is None


def two_pixel_trace():
    """Pixel 0 writes then reads frame-buffer pixel 0; pixel 1 the same with pixel 1 (one line holds both)."""
    records = []
    for pixel in range(2):
        records.append(pack(np.array([RecordKind.FRAME_BUFFER] * 2), np.array([pixel, pixel]),
                            np.array([True, False])))
    counters = np.zeros((2, len(COUNTER_NAMES)), dtype=np.int64)
    return AccessTrace(np.array([0, 2, 4], dtype=np.int64), np.concatenate(records), counters, 2, 1, {})


@pytest.mark.parametrize("q, false_sharing", [(1, 1), (1000, 0)])
def test_hand_checked_false_sharing_needs_fine_interleaving(q, false_sharing):
    """Two cores, private L1 (latency 1), shared L2 (6), memory 40, no compute. At Q = 1: thread 0 writes
    pixel 0 (memory; a write costs 1, clock 1), thread 1 writes pixel 1 (L2 hit; invalidates thread 0's line),
    thread 0 reads pixel 0: a coherence miss on disjoint bytes (false sharing) served by L2 (clock 1 + 6),
    thread 1 reads pixel 1 (L1 hit). At Q = 1000 each thread does its pixel in one turn: thread 0's read hits
    before thread 1 writes, no false sharing. Mutation: ``clock + advance - turn_start < interleave_cycles`` ->
    ``True`` in the access loop (turns never end inside a pixel)."""
    trace = two_pixel_trace()
    placed = place_layout(get_layout("alpha1997"), trace)
    row = placed.kind_first[RecordKind.FRAME_BUFFER]
    assert placed.record_start[row] // 32 == placed.record_start[row + 1] // 32  # one line holds both pixels
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 2, "lru", latency=1),
                           CacheLevel("L2", 8192, 32, 4, "lru", latency=6)), memory_latency=40, name="two")
    machine = SharedHierarchy(hierarchy, n_cores=2, smt=1, shared_by=("thread", "machine"))
    run = simulate_shared_run(trace, get_mapping("P").build(2, 1, 2), machine, placed, COST,
                              Machine(n_cpus=2, quantum_cycles=0), interleave_cycles=q, compute=np.zeros(2))
    l1 = run.shared.counts[0].sum(axis=1)  # (instance, counter)
    assert l1[0, FALSE_SHARING_MISSES] == false_sharing
    assert l1[0, COHERENCE_MISSES] == false_sharing
    assert l1[1, FALSE_SHARING_MISSES] == 0
    memory = run.run.processes["memory_cycles"].tolist()
    if q == 1:
        assert l1[0, COHERENCE_INVALIDATIONS] == 1
        assert memory == [1 + 6, 1 + 1]
    else:  # thread 0: write, read hit; thread 1: write (L2), read hit; thread 1's write invalidates 0's copy
        assert memory == [1 + 1, 1 + 1]


def test_refusals_name_the_field():
    """A machine with the wrong CPU count, page placement or Q, or an unknown thing to record, is refused in one
    line. Mutation: drop the n_cpus check in simulate_shared_run; for ``record``: drop its check there."""
    from coherence.page_placement import PagePlacement
    from rtcommon.validate import InputError

    trace = two_pixel_trace()
    placed = place_layout(get_layout("alpha1997"), trace)
    machine = tiny_machine(1, ("thread", "machine"), 0)
    distribution = get_mapping("P").build(2, 1, 2)
    with pytest.raises(InputError, match="n_cpus is 8"):
        simulate_shared_run(trace, distribution, machine, placed, COST, Machine(n_cpus=8))
    with pytest.raises(InputError, match="interleave_cycles"):
        simulate_shared_run(trace, distribution, machine, placed, COST, Machine(n_cpus=2), interleave_cycles=0)
    with pytest.raises(InputError, match="virtual addresses"):
        simulate_shared_run(trace, distribution, machine, placed, COST,
                            Machine(n_cpus=2, page_placement=PagePlacement("random")))
    for record in ("pixel_misses", ("log", "misses")):
        with pytest.raises(InputError, match="record must be a tuple of 'log', 'pixel_misses'"):
            simulate_shared_run(trace, distribution, machine, placed, COST, Machine(n_cpus=2), record=record)


def test_cpus_go_over_the_cores_before_their_smt_siblings():
    """3 cores of 2 threads (thread = core * 2 + sibling): CPUs 0, 1, 2 are the cores' first threads, 3, 4, 5
    their second; one thread per core is the identity. Mutation: ``cpus % n_cores`` -> ``cpus // smt``."""
    np.testing.assert_array_equal(cpu_threads(3, 2), [0, 2, 4, 1, 3, 5])
    np.testing.assert_array_equal(cpu_threads(4, 1), [0, 1, 2, 3])


def test_default_q_keeps_l3_misses_within_1_percent_of_q1_on_balls_64(tmp_path):
    """balls 64x64 under zen4-7950x, 8 processes (the report's machine: background load, shared queue): at
    the default Q every mapping's L3 misses are within 1% of Q = 1 (docs/multicore.md has the table:
    P, the most sensitive, is 0.09% off at Q = 1000 and 1.03% at Q = 100000). Mutation:
    DEFAULT_INTERLEAVE_CYCLES = 100000 (P goes 1.03% off)."""
    from analyses.experiment import Experiment
    from analyses.traces import cached_trace
    from coherence.shared_run import DEFAULT_INTERLEAVE_CYCLES, SharedLevels
    from coherence.studies import study

    experiment = Experiment(scene="balls", size=64, platform="zen4-7950x", progress=False, cache_dir=tmp_path,
                            mappings=("S", "P", "R"))
    scene, trace, _ = cached_trace("balls", 64, cache_dir=tmp_path, kd=experiment.kd_builder(),
                                   workload=experiment.trace_workload(), progress=False)
    machine = experiment.platform_object().hierarchy
    l3 = {}
    for q in (1, DEFAULT_INTERLEAVE_CYCLES):
        processes = study(trace, experiment.mapping_objects(), [8], hierarchy=SharedLevels(machine, q),
                          layout=experiment.layout_object(), cost=experiment.cost_model(),
                          machine=experiment.machine(), scene=scene, progress=False).processes
        at_8 = processes[processes["n_processes"] == 8]
        l3[q] = at_8.groupby("mapping")["L3_misses"].sum()
    assert (l3[1] > 0).all()
    assert ((l3[DEFAULT_INTERLEAVE_CYCLES] / l3[1] - 1).abs() <= 0.01).all(), (l3[1], l3[DEFAULT_INTERLEAVE_CYCLES])


def test_whatif_points_under_a_platform_run_on_its_shared_levels():
    """A what-if point under a platform runs on the platform variant's whole shared levels with the point's
    level changes and the base's Q; without a platform there are none. Mutation: ``return None`` first in
    analyses.whatif.shared_levels."""
    from dataclasses import replace

    from analyses.whatif import WhatIf, shared_levels
    from coherence.platforms import get_platform

    study = WhatIf.of("latency", {"memory_latency": [100, 200]}, scene="tetra", size=8, platform="zen4-7950x")
    caches = shared_levels(study, {"memory_latency": 200, "L2.latency": 20, "cores": 8})
    zen = get_platform("zen4-7950x")
    assert caches.interleave_cycles == study.experiment.interleave_cycles
    assert caches.machine.n_cores == 8 and caches.hierarchy.memory_latency == 200
    assert [level.size for level in caches.hierarchy.levels] == [level.size for level in zen.hierarchy.hierarchy.levels]
    assert caches.hierarchy.levels[1].latency == 20
    assert shared_levels(replace(study, experiment=replace(study.experiment, platform=None,
                                                           frame_buffer_bytes=None)), {}) is None


@pytest.mark.parametrize("layout, line_size", [("alpha1997", 32), ("compact", 64), ("alpha1997", 16)])
def test_pixel_pieces_match_a_byte_by_byte_split(layout, line_size):
    """Each pixel's pieces (first byte, write flag, bytes, kind) are its records split byte by byte at the
    lines, private kinds at their layout address and flagged private. Mutation: ``np.full(..., -1, ...)`` ->
    ``np.full(..., 0, ...)`` in pixel_pieces (private kinds at the first process's copy) (checked)."""
    from coherence.thread_streams import private_span
    from test_thread_streams import slow_pixel

    trace = synthetic_trace(5, 4, seed=3)
    placed = place_layout(get_layout(layout), trace)
    pieces = pixel_pieces(trace, placed, line_size)
    assert pieces.private_span == private_span(placed)
    for pixel in range(trace.width * trace.height):
        span = slice(pieces.piece_offsets[pixel], pieces.piece_offsets[pixel + 1])
        expected = slow_pixel(trace, placed, pixel, -1, line_size)
        got = list(zip(pieces.addresses[span].tolist(), [-1] * (span.stop - span.start), pieces.writes[span].tolist(),
                       pieces.sizes[span].tolist(), pieces.kinds[span].tolist()))
        assert got == expected
        assert pieces.private[span].tolist() == [kind in PRIVATE_KINDS for kind in pieces.kinds[span].tolist()]
    assert pieces.piece_offsets[-1] == pieces.addresses.size


def random_shared_machine(rng):
    """1-3 cores of 1 or 2 threads, two small levels (each sharing scope at least the one above), any policy."""
    from cachesim.sharing import SHARING

    policy = str(rng.choice(["lru", "fifo", "random"]))
    l1_ways = int(rng.choice([1, 2]))
    hierarchy = Hierarchy((CacheLevel("L1", 32 * 4 * l1_ways, 32, l1_ways, policy, latency=1),
                           CacheLevel("L2", 2048, 32, 4, policy, latency=int(rng.integers(3, 9)))),
                          memory_latency=int(rng.integers(20, 60)), name="random")
    scopes = sorted(rng.choice(SHARING, 2), key=SHARING.index)
    return SharedHierarchy(hierarchy, n_cores=int(rng.integers(1, 4)), smt=int(rng.choice([1, 2])),
                           shared_by=tuple(str(scope) for scope in scopes))


def whole_cycle_compute(trace, placed, rng):
    """Compute cycles per pixel, a whole multiple of its accesses: every per-access share is a whole number."""
    from reference_shared_schedule import pixel_accesses

    counts = [len(pixel_accesses(trace, placed, pixel, 0, 32)) for pixel in range(trace.width * trace.height)]
    return np.array([count * int(rng.integers(0, 12)) if count else int(rng.integers(0, 40)) for count in counts],
                    dtype=np.float64)


def run_both(seed, q, background=0, log=True):
    """A seeded random tiny run through simulate_shared_run and the reference: (run, reference, pieces, machine).
    Without a background load the run logs its accesses unless ``log`` is False (a run without a log serves
    first-level read hits on coherence.turn_reads' path)."""
    from reference_shared_schedule import reference_shared_schedule

    rng = np.random.default_rng(seed)
    trace = synthetic_trace(int(rng.integers(2, 6)), int(rng.integers(2, 5)), seed=seed, reads=int(rng.integers(1, 6)))
    placed = place_layout(get_layout("alpha1997"), trace)
    machine = random_shared_machine(rng)
    n_processes = int(rng.integers(1, 2 * machine.n_threads + 2))
    distribution = get_mapping(str(rng.choice(["S", "P", "R", "B", "DB"]))).build(trace.width, trace.height,
                                                                                   n_processes)
    quantum = float(rng.choice([150, 600] if background else [0, 150, 600]))
    os_machine = Machine(n_cpus=machine.n_threads, quantum_cycles=quantum,
                         scheduler=str(rng.choice(["shared-queue", "static"])),
                         switch_cycles=float(rng.integers(0, 5)), background_load=background,
                         background_footprint=96, background_seed=seed)
    compute = whole_cycle_compute(trace, placed, rng)
    run = simulate_shared_run(trace, distribution, machine, placed, COST, os_machine, interleave_cycles=q,
                              compute=compute,
                              record=("log", "pixel_misses") if log and not background else ("pixel_misses",))
    reference = reference_shared_schedule(trace, distribution, machine, placed, compute, os_machine, q)
    return run, reference, pixel_pieces(trace, placed, 32), machine


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("q", [1, 9, 80, 1e9])
def test_event_loop_equals_the_plain_python_reference(seed, q):
    """On seeded random tiny machines (1-3 cores, SMT on or off, shared or private levels, up to twice as many
    processes as threads, static or dynamic mappings, either scheduler, slices, switches) every process's
    compute, memory, dispatch and finish cycles, first CPU, migrations and tasks, every access in the order the
    machine served it (so the turn order), each process's hits and misses per level, each pixel's misses per
    level and every instance's counts equal tests/reference_shared_schedule.py. Mutation: ``clock + advance -
    turn_start < interleave_cycles`` -> ``clock - turn_start < interleave_cycles`` in _event_loop's access loop (a
    turn runs its pixel to the end); for the pixels' misses alone: drop ``+ accesses[process, level,
    WRITE_MISSES]`` in shared_schedule._add_misses."""
    run, reference, pieces, machine = run_both(seed, q)
    processes = run.run.processes
    for column in ("compute", "memory", "dispatch", "finish"):
        np.testing.assert_array_equal(processes[f"{column}_cycles"], reference[column], err_msg=column)
    np.testing.assert_array_equal(processes["cpu"], reference["cpu"])
    np.testing.assert_array_equal(processes["migrations"], reference["migrations"])
    np.testing.assert_array_equal(run.run.task_owner, reference["task_owner"])
    addresses, threads, piece = run.log
    logged = [(int(a), int(t), int(k)) for a, t, k in zip(addresses, threads, piece)]
    expected = [(a, t, pixel if pixel == COUNTER_ACCESS else int(pieces.piece_offsets[pixel]) + index)
                for a, t, pixel, index in reference["log"]]
    assert logged == expected
    assert_counts_equal_the_reference(run, reference, machine)


def assert_counts_equal_the_reference(run, reference, machine):
    """Each process's hits and misses per level, each pixel's misses, every instance's counts and each thread's
    accesses per serving level equal the reference's."""
    np.testing.assert_array_equal(run.run.miss_counts.accesses, reference["accesses"])
    np.testing.assert_array_equal(run.run.pixel_misses.reshape(-1, len(machine.hierarchy.levels)),
                                  reference["pixel_misses"])
    np.testing.assert_array_equal(run.shared.counts[..., :11], reference["reference"].counts)
    np.testing.assert_array_equal(run.shared.served, reference["reference"].served)


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("q", [1, 9, 80, 1e9])
def test_runs_without_a_log_equal_the_reference(seed, q):
    """Without a log the first level's read hits take coherence.turn_reads' loop: every process's cycles,
    first CPU and tasks, and the counts of assert_counts_equal_the_reference still equal the reference.
    Mutation in turn_reads.first_level_reads: ``kind_hits[...] += 1`` -> ``kind_hits[0] += 1``. A lost LRU
    stamp is seldom seen on these one- and two-way first levels:
    test_first_level_read_loop_equals_the_access_by_access_path holds it."""
    run, reference, _, machine = run_both(seed, q, log=False)
    processes = run.run.processes
    for column in ("compute", "memory", "dispatch", "finish"):
        np.testing.assert_array_equal(processes[f"{column}_cycles"], reference[column], err_msg=column)
    np.testing.assert_array_equal(processes["cpu"], reference["cpu"])
    np.testing.assert_array_equal(run.run.task_owner, reference["task_owner"])
    assert_counts_equal_the_reference(run, reference, machine)


@pytest.mark.parametrize("seed", range(6))
def test_first_level_read_loop_equals_the_access_by_access_path(seed):
    """On two SMT cores with 4-way LRU first levels (so a hit's stamp decides later victims), a run without a
    log (first-level read hits on coherence.turn_reads' loop) and the same run with one (every access through
    shared_access, held to the reference above) give the same cycles, per-process counts, pixels' misses,
    instance counts and served accesses. Mutation in turn_reads.first_level_reads: drop ``first.stamps[slot] =
    access_clock + 1`` (3 of 6 fail)."""
    trace = synthetic_trace(8, 6, seed=seed, reads=12)
    placed = place_layout(get_layout("alpha1997"), trace)
    hierarchy = Hierarchy((CacheLevel("L1", 32 * 4 * 4, 32, 4, "lru", latency=1),
                           CacheLevel("L2", 4096, 32, 4, "lru", latency=5)), memory_latency=30, name="lru4")
    machine = SharedHierarchy(hierarchy, n_cores=2, smt=2, shared_by=("thread", "machine"))
    distribution = get_mapping(["S", "P", "B", "DB", "R", "P"][seed]).build(trace.width, trace.height, 5)
    os_machine = Machine(n_cpus=machine.n_threads, quantum_cycles=300.0, scheduler="shared-queue", switch_cycles=2.0)
    compute = np.random.default_rng(seed).uniform(0, 40, trace.width * trace.height)
    logged, fast = (simulate_shared_run(trace, distribution, machine, placed, COST, os_machine, interleave_cycles=20,
                                        compute=compute, record=record)
                    for record in (("log", "pixel_misses"), ("pixel_misses",)))
    assert fast.log is None
    np.testing.assert_array_equal(fast.run.processes.to_numpy(), logged.run.processes.to_numpy())
    np.testing.assert_array_equal(fast.run.miss_counts.accesses, logged.run.miss_counts.accesses)
    np.testing.assert_array_equal(fast.run.pixel_misses, logged.run.pixel_misses)
    np.testing.assert_array_equal(fast.shared.counts, logged.shared.counts)
    np.testing.assert_array_equal(fast.shared.served, logged.shared.served)


@pytest.mark.parametrize("seed", range(4))
def test_background_slices_equal_the_reference(seed):
    """With one background process (whole slices of reads through the thread's instances) the cycles, every
    instance's counts and each pixel's misses (no background read counted in a pixel) equal the reference.
    Mutation: ``clock += quantum`` -> ``clock += quantum / 2`` in the background branch of _event_loop."""
    run, reference, _, machine = run_both(100 + seed, 40, background=1)
    processes = run.run.processes
    for column in ("compute", "memory", "dispatch", "finish"):
        np.testing.assert_array_equal(processes[f"{column}_cycles"], reference[column], err_msg=column)
    np.testing.assert_array_equal(run.shared.counts[..., :11], reference["reference"].counts)
    np.testing.assert_array_equal(run.run.pixel_misses.reshape(-1, len(machine.hierarchy.levels)),
                                  reference["pixel_misses"])


def scene_only_trace(width, height, seed):
    """Each pixel reads random scene records and writes and reads its private records: no line is written by
    two processes."""
    rng = np.random.default_rng(seed)
    records, lengths = [], []
    for pixel in range(width * height):
        reads = int(rng.integers(1, 8))
        kinds = list(rng.choice(SCENE_KINDS, reads)) + list(PRIVATE_KINDS) * 2
        indices = list(rng.integers(0, 60, reads)) + [int(rng.integers(0, 2))] * (2 * len(PRIVATE_KINDS))
        flags = [False] * reads + [True] * len(PRIVATE_KINDS) + [False] * len(PRIVATE_KINDS)
        records.append(pack(np.array(kinds), np.array(indices), np.array(flags)))
        lengths.append(len(kinds))
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    return AccessTrace(offsets, np.concatenate(records), np.zeros((width * height, len(COUNTER_NAMES)), np.int64),
                       width, height, {})


@pytest.mark.parametrize("seed, mapping, scheduler", [(0, "S", "static"), (1, "P", "shared-queue"),
                                                      (2, "B", "shared-queue"), (3, "R", "static")])
def test_private_levels_one_process_per_thread_and_huge_q_equal_simulate_run(seed, mapping, scheduler):
    """Every level per thread, one process per hardware thread, Q = 1e12, static mappings (a dynamic one also
    writes the shared task counter, which private caches do not model) and no line written by two processes:
    each process's cycles, hits and misses, each pixel's misses per level and the task owners equal
    coherence.simulation.simulate_run on private caches (private copies lie a multiple of every level's set span
    apart, so they map to the same sets). Mutation: ``level_served = 0`` -> ``level_served = 1`` in _event_loop's
    same-line read path; for the pixels' misses alone: drop ``+ accesses[process, level, WRITE_MISSES]`` in
    shared_schedule._add_misses."""
    from coherence.simulation import simulate_run

    rng = np.random.default_rng(seed)
    trace = scene_only_trace(8, 6, seed)
    placed = place_layout(get_layout("alpha1997"), trace)
    policy = ("lru", "fifo")[seed % 2]
    hierarchy = Hierarchy((CacheLevel("L1", 256, 32, 2, policy, latency=1),
                           CacheLevel("L2", 1024, 32, 4, policy, latency=5)), memory_latency=30, name="private")
    machine = SharedHierarchy(hierarchy, n_cores=2, smt=2, shared_by=("thread", "thread"))
    distribution = get_mapping(mapping).build(8, 6, 4)
    os_machine = Machine(n_cpus=4, quantum_cycles=float(rng.choice([0, 300])), scheduler=scheduler)
    compute = whole_cycle_compute(trace, placed, rng)
    shared = simulate_shared_run(trace, distribution, machine, placed, COST, os_machine, interleave_cycles=1e12,
                                 compute=compute, record=("pixel_misses",)).run
    private = simulate_run(trace, distribution, hierarchy, placed, COST, os_machine, compute=compute,
                           pixel_misses=True)
    columns = ["cpu", "migrations", "tasks", "pixels", "compute_cycles", "memory_cycles", "dispatch_cycles",
               "finish_cycles"] + [f"{level}_{what}" for level in ("L1", "L2") for what in ("hits", "misses")]
    for column in columns:
        np.testing.assert_array_equal(shared.processes[column], private.processes[column], err_msg=column)
    np.testing.assert_array_equal(shared.task_owner, private.task_owner)
    np.testing.assert_array_equal(shared.pixel_misses, private.pixel_misses)


@pytest.mark.parametrize("mapping", ["DB", "S"])
def test_db_hands_out_every_task_through_the_shared_counter(mapping):
    """Four cores with private L1s and a shared L2, 8x8 pixels, 4 processes: under DB (2x2 blocks) every task is one access of
    the task counter (shared_run_row's task_counter_accesses = the tasks) and its line moves between the L1s
    (coherence invalidations of the auxiliary kind > 0); a static mapping never touches it. Mutation:
    ``range(system.next_task[0] - handed_before)`` -> ``range(0)`` in _event_loop."""
    from coherence.shared_run import shared_run_row
    from coherence.study_mappings import DynamicBlock

    trace = synthetic_trace(8, 8, seed=5)
    placed = place_layout(get_layout("alpha1997"), trace)
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 2, "lru", latency=1),
                           CacheLevel("L2", 8192, 32, 4, "lru", latency=6)), memory_latency=40, name="four")
    machine = SharedHierarchy(hierarchy, n_cores=4, smt=1, shared_by=("thread", "machine"))
    distribution = (DynamicBlock(block=2) if mapping == "DB" else get_mapping(mapping)).build(8, 8, 4)
    run = simulate_shared_run(trace, distribution, machine, placed, COST, Machine(n_cpus=4, quantum_cycles=0),
                              interleave_cycles=50, compute=np.full(64, 40.0))
    row = shared_run_row(run.shared)
    if mapping == "S":
        assert row["task_counter_accesses"] == row["task_counter_coherence_misses"] == 0
        return
    assert row["task_counter_accesses"] == distribution.n_tasks
    assert row["task_counter_invalidations"] > 0
