"""Each pixel's misses per level from the schedule replay (simulate_run(pixel_misses=True)) against the slow
reference scheduler, and by hand.

The machines, mappings and traces are those of test_scheduler.py, whose compare() checks the per-process
numbers; here the same runs must also give every pixel's misses.
"""
from dataclasses import replace

import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy
from coherence.mappings import Strip
from coherence.pixel_lines import pixel_lines
from coherence.simulation import Machine, simulate_run
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack, unpack

from reference_scheduler import reference_schedule
from test_scheduler import COST, INCLUSIVE, MAPPINGS, SMALL_TLB, placed_for
from trace_factory import SMALL, random_trace


def check_pixel_sums(run, distribution, hierarchy):
    """Each process's pixels' misses add up to its ``<level>_misses``."""
    owner = np.empty(distribution.width * distribution.height, dtype=np.int64)
    owner[distribution.task_pixels] = np.repeat(run.task_owner, np.diff(distribution.task_offsets))
    per_pixel = run.pixel_misses.reshape(-1, len(hierarchy.levels))
    for index, level in enumerate(hierarchy.levels):
        sums = np.bincount(owner, weights=per_pixel[:, index], minlength=distribution.n_processes)
        assert sums.tolist() == run.processes[f"{level.name}_misses"].tolist(), level.name


def compare_pixel_misses(trace, mapping, n, hierarchy, machine):
    placed = placed_for()
    distribution = MAPPINGS[mapping].build(trace.width, trace.height, n)
    compute = COST.compute_cycles(trace.counters, COUNTER_NAMES)
    run = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute, pixel_misses=True)
    # without the per-pixel output, the same run
    plain = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute)
    assert plain.pixel_misses is None
    assert plain.processes.equals(run.processes) and plain.real_cycles == run.real_cycles
    # the line accesses worked out once for a study give the same pixels' misses
    lines = pixel_lines(trace, placed, min(level.line_size for level in hierarchy.levels))
    shared = simulate_run(trace, distribution, hierarchy, placed, COST, machine, compute=compute, lines=lines,
                          pixel_misses=True)
    assert np.array_equal(shared.pixel_misses, run.pixel_misses)
    expected = reference_schedule(trace, distribution, hierarchy, placed, compute, machine)
    n_levels = len(hierarchy.levels)
    assert run.pixel_misses.shape == (trace.height, trace.width, n_levels)
    assert run.pixel_misses.dtype == np.int64
    assert run.pixel_misses.tolist() == np.array(expected["pixel_misses"]).reshape(
        trace.height, trace.width, n_levels).tolist()
    check_pixel_sums(run, distribution, hierarchy)
    assert run.pixel_misses.sum() > 0
    return run


@pytest.mark.parametrize("scheduler", ["shared-queue", "static"])
@pytest.mark.parametrize("background", [0, 2])
@pytest.mark.parametrize("mapping", list(MAPPINGS))
def test_pixel_misses_equal_the_reference(mapping, background, scheduler):
    trace = random_trace(width=8, height=6, seed=11)
    machine = Machine(n_cpus=2, quantum_cycles=6000.0, scheduler=scheduler, background_load=background,
                      background_footprint=1024, switch_cycles=17.0)
    compare_pixel_misses(trace, mapping, 5, SMALL, machine)


@pytest.mark.parametrize("seed", range(4))
def test_seeded_random_machines_give_the_reference_pixel_misses(seed):
    rng = np.random.default_rng(100 + seed)
    trace = random_trace(width=int(rng.integers(3, 9)), height=int(rng.integers(2, 7)), seed=seed)
    mapping = ["S", "P", "R", "B", "DB", "DB+1"][int(rng.integers(6))]
    machine = Machine(n_cpus=int(rng.integers(1, 5)), quantum_cycles=float(rng.integers(1, 8) * 2000),
                      scheduler=["shared-queue", "static"][int(rng.integers(2))],
                      background_load=int(rng.integers(0, 4)), background_footprint=int(rng.integers(0, 3000)),
                      background_seed=seed, switch_cycles=float(rng.integers(0, 50)))
    hierarchy = [SMALL, INCLUSIVE][int(rng.integers(2))]
    compare_pixel_misses(trace, mapping, int(rng.integers(1, 9)), hierarchy, machine)


@pytest.mark.parametrize("inclusion", ["inclusive", "non-inclusive"])
@pytest.mark.parametrize("mapping", ["S", "DB"])
def test_write_misses_count_in_the_pixel(mapping, inclusion):
    """Written records through a write-through, no-write-allocate L1: a write miss is the pixel's miss too."""
    trace = random_trace(width=8, height=6, seed=21)
    kinds, ids = unpack(trace.records)
    written = pack(kinds, ids, np.random.default_rng(21).random(ids.size) < 0.3)
    trace = AccessTrace(trace.pixel_offsets, written, trace.counters, trace.width, trace.height, {})
    l1, l2 = SMALL.levels
    hierarchy = Hierarchy((replace(l1, write_allocate=False), l2), memory_latency=SMALL.memory_latency,
                          inclusion=inclusion)
    compare_pixel_misses(trace, mapping, 3, hierarchy, Machine(n_cpus=2, quantum_cycles=4000.0, background_load=1,
                                                               background_footprint=512))


def test_a_tlb_changes_no_pixel_misses():
    """TLB lookups touch no cache: with each process alone on its CPU from start to end (so that the TLB's
    extra cycles cannot change who runs where), the pixels' misses are the same with and without one."""
    trace = random_trace(width=8, height=6, seed=13)
    machine = Machine(n_cpus=3, quantum_cycles=0, scheduler="static")
    with_tlb = compare_pixel_misses(trace, "P", 3, replace(INCLUSIVE, tlb=SMALL_TLB), machine)
    without = compare_pixel_misses(trace, "P", 3, INCLUSIVE, machine)
    assert np.array_equal(with_tlb.pixel_misses, without.pixel_misses)
    assert (with_tlb.processes["memory_cycles"] > without.processes["memory_cycles"]).all()


def test_pixel_misses_by_hand():
    """A 2x2 image, one process, a direct-mapped cache of two 32-byte lines.

    Every sphere record is one line; spheres i and i + 2 share a set, i and
    i + 1 do not (whichever set sphere 0 lands in). In scan order:

    ===== ============ ========================================== ======
    pixel reads        what happens                               misses
    ===== ============ ========================================== ======
    0     X0 X1        both miss                                  2
    1     X0 X2        X0 hits; X2 misses, evicts X0              1
    2     X1 X0        X1 hits (its set untouched); X0 misses     1
    3     X2 X2 X3     X2 misses, then hits; X3 misses, evicts X1 2
    ===== ============ ========================================== ======
    """
    reads = [[0, 1], [0, 2], [1, 0], [2, 2, 3]]
    offsets = np.cumsum([0] + [len(r) for r in reads]).astype(np.int64)
    records = pack(np.full(int(offsets[-1]), RecordKind.SPHERE), np.concatenate(reads))
    trace = AccessTrace(offsets, records, np.zeros((4, len(COUNTER_NAMES)), dtype=np.int64), 2, 2, {})
    tiny = Hierarchy((CacheLevel("D", 64, 32, 1, latency=2),), memory_latency=50)
    run = simulate_run(trace, Strip().build(2, 2, 1), tiny, placed_for(sphere_bytes=32), COST,
                       Machine(n_cpus=1, quantum_cycles=0), compute=np.zeros(4), pixel_misses=True)
    assert run.pixel_misses[:, :, 0].tolist() == [[2, 1], [1, 2]]
    assert run.processes["D_misses"].tolist() == [6]


def test_pixel_misses_must_be_a_bool():
    trace = random_trace(width=2, height=2, seed=3)
    with pytest.raises(ValueError, match="pixel_misses must be True or False, got 1"):
        simulate_run(trace, Strip().build(2, 2, 1), SMALL, placed_for(), COST, pixel_misses=1)
