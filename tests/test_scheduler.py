"""The simulated operating system (coherence.scheduler) against a slow reference, and by hand."""
from dataclasses import replace

import numpy as np
import pytest

from cachesim import CacheState, Hierarchy, Tlb, simulate
from coherence.cost import CostModel
from coherence.layout import RecordLayout, get_layout
from coherence.mappings import Block, DynamicBlock, Pixel, Row, Strip
from coherence.metrics import run_summary
from coherence.pixel_lines import pixel_lines, skips_certain_hits
from coherence.simulation import Machine, simulate_run
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack, unpack

from reference_scheduler import reference_schedule
from trace_factory import SMALL, random_trace

# Integer costs and latencies: every cycle count is an integer-valued float,
# so the compiled and the reference schedules see identical clocks and ties.
COST = CostModel(ray=3, node_visit=1, test_sphere=5, test_triangle=7, shading=11)
INCLUSIVE = Hierarchy(SMALL.levels, memory_latency=50, inclusion="inclusive")
MAPPINGS = {"S": Strip(), "P": Pixel(), "R": Row(), "B": Block(field=4),
            "DB": DynamicBlock(block=2, dispatch_cycles=300.0),
            "DB+1": DynamicBlock(block=3, dispatch_cycles=300.0, take_ahead=1)}


def placed_for(sphere_bytes=None):
    """The alpha1997 layout for 60 records of every kind; ``sphere_bytes`` pins the sphere's size (and alignment)
    where a hand-worked case needs it not to follow the preset."""
    layout = get_layout("alpha1997")
    if sphere_bytes is not None:
        layout = replace(layout, records={**layout.records, "sphere": RecordLayout(sphere_bytes, sphere_bytes)})
    return layout.place({kind: 60 for kind in RecordKind}, textures=[[(60, 1)]])


def compare(trace, mapping, n, hierarchy, machine):
    placed = placed_for()
    distribution = MAPPINGS[mapping].build(trace.width, trace.height, n)
    compute = COST.compute_cycles(trace.counters, COUNTER_NAMES)
    run = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute)
    # the line accesses worked out once for a study must change nothing
    lines = pixel_lines(trace, placed, min(level.line_size for level in hierarchy.levels))
    shared = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute, lines=lines)
    assert shared.processes.equals(run.processes) and shared.real_cycles == run.real_cycles
    # nor must taking the hierarchy's certain first-level hits out of them
    line_size = min(level.line_size for level in hierarchy.levels)
    if skips_certain_hits(hierarchy, line_size):
        lines = pixel_lines(trace, placed, line_size, hierarchy=hierarchy)
        assert lines.skip_mask > 0
        taken = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute, lines=lines)
        assert taken.processes.equals(run.processes) and taken.real_cycles == run.real_cycles
    expected = reference_schedule(trace, distribution, hierarchy, placed, compute, machine)
    frame = run.processes
    for column in ("compute", "memory", "dispatch", "user", "finish"):
        assert frame[f"{column}_cycles"].tolist() == expected[column], column
    assert run.real_cycles == expected["real"]
    assert frame["cpu"].tolist() == expected["cpu"]
    assert frame["migrations"].tolist() == expected["migrations"]
    assert run.task_owner.tolist() == expected["task_owner"]
    for index, level in enumerate(hierarchy.levels):
        assert frame[f"{level.name}_hits"].tolist() == [hits[index] for hits in expected["hits"]]
        assert frame[f"{level.name}_misses"].tolist() == [misses[index] for misses in expected["misses"]]
    if hierarchy.tlb is not None:
        assert frame["tlb_accesses"].tolist() == expected["tlb_accesses"]
        assert frame["tlb_misses"].tolist() == expected["tlb_misses"]
    else:
        assert "tlb_misses" not in frame
    return run


@pytest.mark.parametrize("scheduler", ["shared-queue", "static"])
@pytest.mark.parametrize("background", [0, 2])
@pytest.mark.parametrize("mapping", list(MAPPINGS))
def test_compiled_schedule_equals_the_reference(mapping, background, scheduler):
    trace = random_trace(width=8, height=6, seed=11)
    machine = Machine(n_cpus=2, quantum_cycles=6000.0, scheduler=scheduler, background_load=background,
                      background_footprint=1024, switch_cycles=17.0)
    run = compare(trace, mapping, 5, SMALL, machine)
    assert run.processes["pixels"].sum() == 48


@pytest.mark.parametrize("seed", range(4))
def test_seeded_random_machines_equal_the_reference(seed):
    rng = np.random.default_rng(seed)
    trace = random_trace(width=int(rng.integers(3, 9)), height=int(rng.integers(2, 7)), seed=seed)
    mapping = ["S", "P", "R", "B", "DB", "DB+1"][seed % 6 if seed < 2 else int(rng.integers(6))]
    machine = Machine(n_cpus=int(rng.integers(1, 5)), quantum_cycles=float(rng.integers(1, 8) * 2000),
                      scheduler=["shared-queue", "static"][int(rng.integers(2))],
                      background_load=int(rng.integers(0, 4)), background_footprint=int(rng.integers(0, 3000)),
                      background_seed=seed, switch_cycles=float(rng.integers(0, 50)))
    hierarchy = [SMALL, INCLUSIVE][int(rng.integers(2))]
    compare(trace, mapping, int(rng.integers(1, 9)), hierarchy, machine)


def test_run_to_completion_with_no_quantum():
    trace = random_trace(width=6, height=4, seed=12)
    compare(trace, "S", 3, SMALL, Machine(n_cpus=2, quantum_cycles=0))
    compare(trace, "DB", 3, SMALL, Machine(n_cpus=2, quantum_cycles=0, scheduler="static"))


def pixel_cycles(trace, placed, pixels, state):
    """By hand: compute plus latency of each access, on ``state``."""
    compute = COST.compute_cycles(trace.counters, COUNTER_NAMES)
    total = 0.0
    for pixel in pixels:
        records = trace.records[trace.pixel_offsets[pixel]:trace.pixel_offsets[pixel + 1]]
        result = simulate(placed.addresses(records, 32), state)
        total += compute[pixel] + float(np.dot(result.hits, [2, 9]) + result.misses[-1] * 50)
    return total


def test_a_moved_process_finds_the_caches_its_cpu_kept():
    """Three processes of two pixels on two CPUs, worked out by hand.

    Row mapping on 2x3 pixels: process r renders pixels 2r, 2r+1. Every
    pixel costs 10000 compute cycles plus one sphere read, two 32-byte
    lines: 50 + 9 cycles on a miss (the second line comes from L2, which
    fetched the whole 64-byte line), 2 + 2 on a hit in L1. A quantum of 1 cycle ends a slice after every pixel.

    ====== ====== ============================================= ======
    CPU    at     what happens                                  until
    ====== ====== ============================================= ======
    0      0      takes p0; pixel 0 reads X0: miss               10059
    1      0      takes p1; pixel 2 reads X1: miss               10059
    0      10059  p2 waits: p0 to the queue, takes p2;
                  pixel 4 reads X2: miss                         20118
    1      10059  p0 waits: p1 to the queue, takes p0 (moved);
                  pixel 1 reads X1, which CPU 1 holds: hit;
                  p0 is done                                     20063
    1      20063  takes p1; pixel 3 reads X1: hit; p1 is done    30067
    0      20118  nobody waits: p2 runs on; pixel 5 reads X0,
                  which CPU 0 kept from p0: hit; p2 is done      30122
    ====== ====== ============================================= ======
    """
    x0, x1, x2 = 0, 3, 5
    reads = [x0, x1, x1, x1, x2, x0]
    records = pack(np.full(6, RecordKind.SPHERE), np.array(reads))
    trace = AccessTrace(np.arange(7, dtype=np.int64), records, np.zeros((6, len(COUNTER_NAMES)), dtype=np.int64),
                        2, 3, {})
    placed = placed_for(sphere_bytes=64)
    lines = {int(placed.addresses(pack(np.array([RecordKind.SPHERE]), np.array([x])), 32)[0]) // 32
             for x in (x0, x1, x2)}
    assert len({line % 16 for line in lines}) == 3  # three L1 sets (and the next three)
    run = simulate_run(trace, Row().build(2, 3, 3), SMALL, placed, COST, Machine(n_cpus=2, quantum_cycles=1.0),
                       compute=np.full(6, 10000.0))
    frame = run.processes
    assert frame["L1_hits"].tolist() == [2, 2, 2]
    assert frame["user_cycles"].tolist() == [20063.0, 20063.0, 20063.0]
    assert frame["finish_cycles"].tolist() == [20063.0, 30067.0, 30122.0]
    assert run.real_cycles == 30122.0
    assert frame["cpu"].tolist() == [0, 1, 0]
    assert frame["migrations"].tolist() == [1, 0, 0]
    # Pinned instead, p0 and p2 take turns on CPU 0: p0's pixel 1 finds
    # X0 and X2 there, not X1; p2's pixel 5 finds X0.
    static = simulate_run(trace, Row().build(2, 3, 3), SMALL, placed, COST,
                          Machine(n_cpus=2, quantum_cycles=1.0, scheduler="static"), compute=np.full(6, 10000.0))
    assert static.processes["cpu"].tolist() == [0, 1, 0]
    assert static.processes["L1_hits"].tolist() == [0, 2, 2]
    assert static.processes["migrations"].tolist() == [0, 0, 0]


def test_static_placement_never_moves_and_matches_old_round_robin():
    trace = random_trace(width=8, height=6, seed=14)
    placed = placed_for()
    run = simulate_run(trace, Row().build(8, 6, 4), SMALL, placed, COST,
                       Machine(n_cpus=2, quantum_cycles=4000.0, scheduler="static"))
    assert run.processes["migrations"].tolist() == [0, 0, 0, 0]
    assert run.processes["cpu"].tolist() == [0, 1, 0, 1]


def test_background_slices_evict_our_lines():
    """A lone process next to a background process on one CPU: every
    background slice streams more than the caches hold, so the process's
    misses grow with the background's footprint and not its hits."""
    trace = random_trace(width=8, height=6, seed=15)
    placed = placed_for()
    misses = []
    for footprint in (0, 4096):
        machine = Machine(n_cpus=1, quantum_cycles=3000.0, background_load=1, background_footprint=footprint)
        run = simulate_run(trace, Strip().build(8, 6, 1), SMALL, placed, COST, machine)
        misses.append(int(run.processes["L2_misses"].iloc[0]))
        # One CPU shared with an always-runnable process: real time is at
        # least our user time plus a quantum for every slice of ours but the last.
        assert run.real_cycles > run.processes["user_cycles"].iloc[0]
    assert misses[1] > misses[0]


def test_idle_machine_lone_process_keeps_its_cpu():
    trace = random_trace(width=8, height=6, seed=16)
    placed = placed_for()
    run = simulate_run(trace, Strip().build(8, 6, 1), SMALL, placed, COST,
                       Machine(n_cpus=8, quantum_cycles=1000.0, background_load=2))
    # 3 runnable processes on 8 CPUs: nobody waits, so nobody is preempted.
    assert run.processes["migrations"].tolist() == [0]
    assert run.real_cycles == run.processes["user_cycles"].iloc[0]
    state = CacheState(SMALL)
    assert run.processes["user_cycles"].iloc[0] == pytest.approx(pixel_cycles(trace, placed, range(48), state))


def test_machine_validation():
    with pytest.raises(ValueError, match="Machine.scheduler must be one of"):
        Machine(scheduler="fair")
    with pytest.raises(ValueError, match="applies to scheduler='static' only"):
        Machine(placement="neighbours")
    with pytest.raises(ValueError, match="Machine.quantum_cycles must be > 0 with a background load"):
        Machine(quantum_cycles=0, background_load=1)
    with pytest.raises(ValueError, match="Machine.background_footprint"):
        Machine(background_footprint=-1)
    with pytest.raises(ValueError, match="Machine.background_load"):
        Machine(background_load=1.5)
    assert Machine(scheduler="static", placement="neighbours").cpu_of(4).tolist() == [0, 1, 2, 3]


@pytest.mark.parametrize("inclusion", ["inclusive", "non-inclusive"])
@pytest.mark.parametrize("mapping", ["S", "P", "DB"])
def test_writes_equal_the_reference(mapping, inclusion):
    """Written records (ray stack, frame buffer) through a write-through, no-write-allocate L1."""
    trace = random_trace(width=8, height=6, seed=21)
    rng = np.random.default_rng(21)
    kinds, ids = unpack(trace.records)
    written = pack(kinds, ids, rng.random(ids.size) < 0.3)
    trace = AccessTrace(trace.pixel_offsets, written, trace.counters, trace.width, trace.height, {})
    l1, l2 = SMALL.levels
    hierarchy = Hierarchy((replace(l1, write_allocate=False), l2), memory_latency=SMALL.memory_latency,
                          inclusion=inclusion)
    run = compare(trace, mapping, 3, hierarchy, Machine(n_cpus=2, quantum_cycles=4000.0, background_load=1,
                                                        background_footprint=512))
    # the writes changed what the caches did: the same trace read-only gives other counts
    reads_only = AccessTrace(trace.pixel_offsets, pack(kinds, ids), trace.counters, trace.width, trace.height, {})
    other = simulate_run(reads_only, MAPPINGS[mapping].build(8, 6, 3), hierarchy, placed_for(), COST,
                         Machine(n_cpus=2, quantum_cycles=4000.0, background_load=1, background_footprint=512),
                         compute=COST.compute_cycles(trace.counters, COUNTER_NAMES))
    assert run.processes["memory_cycles"].tolist() != other.processes["memory_cycles"].tolist()


# A TLB small enough that the random traces' pages overflow it: 4 entries of 512-byte pages.
SMALL_TLB = Tlb(entries=4, page_size=512, miss_cycles=21.0)


@pytest.mark.parametrize("policy", ["nlu", "lru", "fifo"])
@pytest.mark.parametrize("mapping", ["S", "P", "DB"])
def test_tlb_in_the_schedule_equals_the_reference(mapping, policy):
    trace = random_trace(width=8, height=6, seed=13)
    hierarchy = replace(INCLUSIVE, tlb=replace(SMALL_TLB, policy=policy))
    machine = Machine(n_cpus=2, quantum_cycles=5000.0, background_load=1, background_footprint=768)
    run = compare(trace, mapping, 3, hierarchy, machine)
    frame = run.processes
    assert frame["tlb_misses"].sum() > 0 and (frame["tlb_misses"] < frame["tlb_accesses"]).all()
    assert frame["tlb_cycles"].tolist() == (frame["tlb_misses"] * 21.0).tolist()


@pytest.mark.parametrize("footprint", [768, 4096, 5000])
@pytest.mark.parametrize("mapping", ["P", "DB"])
def test_skipped_background_slices_look_their_pages_up(mapping, footprint):
    """Other users' slices of fresh lines are skipped with a data TLB too (cachesim.fresh for the caches, one
    lookup per page with its other lines as repeats for the TLB; footprints of 2 to 10 pages of 512 bytes,
    starting anywhere in a page), and every count equals the reference's, which walks them access by access.
    Fails when the skipped slice is not looked up (the ``_tlb_misses(..., buffer[:n_runs], ...)`` line after
    ``skip_fresh_lines`` dropped: checked)."""
    from cachesim import CacheState
    from coherence.simulation import _background, _cpu_tlbs

    trace = random_trace(width=8, height=6, seed=15)
    hierarchy = replace(INCLUSIVE, tlb=SMALL_TLB)
    machine = Machine(n_cpus=2, quantum_cycles=3000.0, background_load=2, background_footprint=footprint)
    state = CacheState(hierarchy)
    assert _background(machine, 5, state, _cpu_tlbs(state, 2, 5)).skip
    run = compare(trace, mapping, 3, hierarchy, machine)
    assert run.processes["tlb_misses"].sum() > 0


def test_tlb_misses_add_to_memory_cycles_only():
    trace = random_trace(width=6, height=4, seed=14)
    placed = placed_for()
    distribution = MAPPINGS["R"].build(6, 4, 2)
    compute = COST.compute_cycles(trace.counters, COUNTER_NAMES)
    machine = Machine(n_cpus=2, quantum_cycles=0)
    with_tlb = simulate_run(trace, distribution, replace(INCLUSIVE, tlb=SMALL_TLB), placed, COST, machine,
                            compute=compute).processes
    without = simulate_run(trace, distribution, INCLUSIVE, placed, COST, machine, compute=compute).processes
    # caches and compute are untouched; every miss costs exactly its penalty
    assert with_tlb["compute_cycles"].tolist() == without["compute_cycles"].tolist()
    assert with_tlb["L1_misses"].tolist() == without["L1_misses"].tolist()
    assert (with_tlb["memory_cycles"] - without["memory_cycles"]).tolist() == \
        (with_tlb["tlb_misses"] * SMALL_TLB.miss_cycles).tolist()
    summary = run_summary(with_tlb, [level.name for level in INCLUSIVE.levels], COST.clock_hz, 1.0)
    assert summary["tlb_misses"] == with_tlb["tlb_misses"].sum() > 0
    assert summary["tlb_cycles"] == summary["tlb_misses"] * SMALL_TLB.miss_cycles
    assert "tlb_misses" not in run_summary(without, [level.name for level in INCLUSIVE.levels], COST.clock_hz, 1.0)


def test_pixel_lines_are_each_pixels_converted_records():
    from coherence.record_lines import record_lines_and_writes

    trace = random_trace(width=8, height=6, seed=4)
    kinds, ids = unpack(trace.records)
    trace = AccessTrace(trace.pixel_offsets, pack(kinds, ids, np.random.default_rng(4).random(ids.size) < 0.3),
                        trace.counters, trace.width, trace.height, {})
    placed = placed_for()
    lines = pixel_lines(trace, placed, 32)
    for pixel in range(48):
        buffer, flags, n, n_writes = record_lines_and_writes(
            np.asarray(trace.records), trace.pixel_offsets[pixel], trace.pixel_offsets[pixel + 1], placed.placement,
            5, np.empty(1, dtype=np.uint64), np.empty(1, dtype=np.bool_))
        first, stop = lines.line_offsets[pixel], lines.line_offsets[pixel + 1]
        assert lines.addresses[first:stop].tolist() == buffer[:n].tolist()
        assert lines.writes[first:stop].tolist() == flags[:n].tolist() and lines.pixel_writes[pixel] == n_writes
    assert pixel_lines(trace, placed, 32, budget_bytes=9 * int(lines.line_offsets[-1]) - 1) is None
    with pytest.raises(ValueError, match="16-byte lines; this run needs 48 pixels of 32-byte lines"):
        simulate_run(trace, MAPPINGS["S"].build(8, 6, 2), SMALL, placed, COST, Machine(n_cpus=2),
                     lines=pixel_lines(trace, placed, 16))
