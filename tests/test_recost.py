"""Re-costing runs from stored miss counts: equal to a full simulation where the schedule does not depend on
cycles, refused (and simulated again) where it does."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from cachesim import CacheLevel, Hierarchy
from cachesim.tlb_config import Tlb
from coherence.cost import CostModel
from coherence.layout import get_layout
from coherence.mappings import get_mapping
from coherence.recost import CYCLE_COLUMNS, RunStore, fixed_schedule, recost_run
from coherence.simulation import Machine, simulate_run
from coherence.studies import Execution, place_layout, study
from trace_factory import SMALL, random_trace
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack
from tracer.trace.records import WRITE_FLAG

SMALL_TLB = replace(SMALL, tlb=Tlb(entries=4, page_size=512, miss_cycles=30.0), name="small-tlb")


def written_trace(width, height, seed):
    """random_trace with a fifth of its records turned into writes."""
    trace = random_trace(width=width, height=height, seed=seed)
    records = np.array(trace.records, dtype=np.uint32)
    records[np.random.default_rng(seed + 100).random(records.size) < 0.2] |= np.uint32(WRITE_FLAG)
    return AccessTrace(trace.pixel_offsets, records, trace.counters, width, height, {})


def random_costs(rng, hierarchy):
    """The hierarchy with random latencies and TLB penalty, and a cost model of random weights and clock."""
    levels = tuple(replace(level, latency=float(rng.uniform(1, 30))) for level in hierarchy.levels)
    tlb = None if hierarchy.tlb is None else replace(hierarchy.tlb, miss_cycles=float(rng.uniform(10, 200)))
    hierarchy = replace(hierarchy, levels=levels, memory_latency=float(rng.uniform(40, 300)), tlb=tlb)
    names = [name for name in CostModel.__dataclass_fields__ if name not in ("clock_hz", "name")]
    cost = CostModel(**{name: float(rng.uniform(0, 500)) for name in names}, clock_hz=float(rng.uniform(1e8, 3e9)))
    return hierarchy, cost


COUNT_COLUMNS_EXCLUDED = set(CYCLE_COLUMNS)

# (machine, mapping, processes): every case qualifies (fixed_schedule is True)
QUALIFYING = [
    (Machine(n_cpus=4, quantum_cycles=3000), "S", 4),
    (Machine(n_cpus=4, quantum_cycles=3000), "B", 3),
    (Machine(n_cpus=4, quantum_cycles=2000, background_load=2, background_footprint=2048), "P", 2),
    (Machine(n_cpus=4, quantum_cycles=2000, background_load=3, background_footprint=4096), "DB", 1),
    (Machine(n_cpus=8, scheduler="static", placement="neighbours", background_load=4, quantum_cycles=1000,
             background_footprint=4096), "R", 4),
    (Machine(n_cpus=4, scheduler="static", switch_cycles=50.0), "S", 4),
]


@pytest.mark.parametrize("case", range(len(QUALIFYING)))
@pytest.mark.parametrize("hierarchy", [SMALL, SMALL_TLB], ids=["no-tlb", "tlb"])
def test_recost_equals_full_simulation_on_qualifying_runs(case, hierarchy):
    """Seeded random latencies, TLB penalties, cost weights, clocks and time slices: re-costing the run of one
    draw gives every count of a simulation of the other exactly and its cycles to rounding. Fails if
    recost_run leaves out the writes' first-level latency (``memory = memory + (... WRITE_HITS ...)``)."""
    machine, mapping, n = QUALIFYING[case]
    rng = np.random.default_rng(case)
    trace = written_trace(12, 10, seed=case)
    placed = place_layout(get_layout("compact"), trace)
    distribution = get_mapping(mapping).build(trace.width, trace.height, n)
    assert fixed_schedule(distribution, machine)
    first_hierarchy, first_cost = random_costs(rng, hierarchy)
    stored = simulate_run(trace, distribution, first_hierarchy, placed, first_cost, machine)
    assert stored.miss_counts.fixed_schedule
    for _ in range(3):
        new_hierarchy, new_cost = random_costs(rng, hierarchy)
        new_machine = replace(machine, quantum_cycles=float(rng.uniform(500, 5000)))
        full = simulate_run(trace, distribution, new_hierarchy, placed, new_cost, new_machine)
        recosted = recost_run(stored, new_hierarchy, new_cost)
        assert list(recosted.processes.columns) == list(full.processes.columns)
        counts = [c for c in full.processes.columns if c not in COUNT_COLUMNS_EXCLUDED]
        assert recosted.processes[counts].equals(full.processes[counts])
        for column in CYCLE_COLUMNS:
            if column in full.processes:
                np.testing.assert_allclose(recosted.processes[column], full.processes[column], rtol=1e-12,
                                           err_msg=column)
        assert recosted.real_cycles == pytest.approx(full.real_cycles, rel=1e-12)
        np.testing.assert_array_equal(recosted.task_owner, full.task_owner)


def test_recost_of_a_tiny_run_by_hand():
    """One pixel reads one sphere record twice and writes it once: the first read misses both levels (memory),
    the second hits L1, the write hits L1. Under latencies 3 / 11 / memory 70 that is 70 + 3 + 3 memory
    cycles; compute is the ray's and the sphere test's weights times their counters. Fails if recost_run
    prices read misses at the last level's latency instead of memory's."""
    record = pack([RecordKind.SPHERE], [0])[0]
    records = np.array([record, record, record | np.uint32(WRITE_FLAG)], dtype=np.uint32)
    counters = np.zeros((1, len(COUNTER_NAMES)), dtype=np.int64)
    counters[0, COUNTER_NAMES.index("primary_rays")] = 1
    counters[0, COUNTER_NAMES.index("tests_sphere")] = 2
    trace = AccessTrace(np.array([0, 3], dtype=np.int64), records, counters, 1, 1, {})
    placed = place_layout(get_layout("compact"), trace)
    distribution = get_mapping("S").build(1, 1, 1)
    stored = simulate_run(trace, distribution, SMALL, placed, CostModel(), Machine(n_cpus=1))
    levels = (CacheLevel("L1", 512, 32, 1, latency=3), CacheLevel("L2", 3072, 64, 3, latency=11))
    cost = CostModel(ray=100.0, test_sphere=7.0, clock_hz=1e6)
    recosted = recost_run(stored, Hierarchy(levels, memory_latency=70), cost)
    row = recosted.processes.iloc[0]
    assert row["memory_cycles"] == 70 + 3 + 3
    assert row["compute_cycles"] == 100 + 2 * 7
    assert row["user_cycles"] == row["finish_cycles"] == recosted.real_cycles == 70 + 3 + 3 + 114
    assert row["user_seconds"] == pytest.approx(190 / 1e6)


def test_which_runs_have_a_fixed_schedule():
    """The rule by hand. Fails if fixed_schedule ignores the background (``n + background_load``) or lets
    DB with several processes through."""
    def build(mapping, n):
        return get_mapping(mapping).build(16, 16, n)

    idle = Machine(n_cpus=8)
    assert fixed_schedule(build("S", 8), idle)
    assert fixed_schedule(build("DB", 1), idle)
    assert not fixed_schedule(build("DB", 2), idle)
    assert not fixed_schedule(build("S", 9), idle)
    assert not fixed_schedule(build("S", 8), replace(idle, background_load=1))
    assert fixed_schedule(build("S", 7), replace(idle, background_load=1))
    assert not fixed_schedule(build("DB", 8), replace(idle, background_load=2))
    static = Machine(n_cpus=8, scheduler="static")
    assert fixed_schedule(build("B", 4), replace(static, background_load=4))  # background on CPUs 4-7
    assert not fixed_schedule(build("B", 4), replace(static, background_load=5))  # the fifth on CPU 0
    assert not fixed_schedule(build("B", 9), replace(static, placement="neighbours"))


def test_study_recosts_qualifying_runs_and_resimulates_db_with_background():
    """Two studies of one trace that differ only in costs share a store: the one-process runs (which fit the
    CPUs beside two background processes) are re-costed, the 8-process S and DB runs (background
    time-slices with them) are simulated again, and every result equals a study without a store. A third,
    identical study reuses the two it simulated and re-costs the others again. Fails if fixed_schedule returns True for every run (DB at 8 is then
    re-costed and the counts of simulated runs change)."""
    trace = written_trace(128, 64, seed=3)  # eight DB blocks
    machine = Machine(n_cpus=8, quantum_cycles=2000, background_load=2, background_footprint=2048)
    store = RunStore()
    rng = np.random.default_rng(7)
    setups = [random_costs(rng, SMALL_TLB) for _ in range(2)]

    def run(hierarchy, cost, execution):
        return study(trace, ["S", "DB"], [1, 8], hierarchy=hierarchy, cost=cost, machine=machine, progress=False,
                     execution=execution)

    run(*setups[0], Execution(store=store))
    assert (store.simulated, store.re_costed, store.reused) == (4, 0, 0)
    second = run(*setups[1], Execution(store=store))
    assert (store.simulated, store.re_costed, store.reused) == (6, 2, 0)
    fresh = run(*setups[1], None)
    columns = [c for c in fresh.runs.columns if pd.api.types.is_numeric_dtype(fresh.runs[c])]
    np.testing.assert_allclose(second.runs[columns].to_numpy(np.float64), fresh.runs[columns].to_numpy(np.float64),
                               rtol=1e-12)
    run(*setups[1], Execution(store=store))
    assert (store.simulated, store.re_costed, store.reused) == (6, 4, 2)  # the simulated two are reused
    with pytest.raises(ValueError, match="another trace"):
        run(*setups[1], Execution(store=_bound_elsewhere()))


def test_store_serves_fixed_runs_whatever_the_other_users():
    """A run with a fixed schedule does not depend on the other users (they run on CPUs of their own) but for
    the CPU ours starts on, and without other users their footprint does nothing: a study with five instead
    of two background processes reuses the one-process runs (and simulates the 8-process ones), and two
    studies without any that differ only in the footprint share every run; each equals a study without a
    store, cpu column included. Fails if the store serves a run with its stored cpu column (``return run``
    in RunStore.serve; the one-process runs then start on CPU 2, not 5) (checked)."""
    trace = written_trace(128, 64, seed=3)
    machine = Machine(n_cpus=8, quantum_cycles=2000, background_load=2, background_footprint=2048)
    store = RunStore()
    hierarchy, cost = random_costs(np.random.default_rng(11), SMALL_TLB)

    def run(machine, execution):
        return study(trace, ["S", "DB"], [1, 8], hierarchy=hierarchy, cost=cost, machine=machine, progress=False,
                     execution=execution)

    run(machine, Execution(store=store))
    expected = [(4, 0, 0), (6, 0, 2), (8, 0, 4), (8, 0, 8)]
    for machine, paths in zip([replace(machine, background_load=5, background_footprint=4096),
                               replace(machine, background_load=0, background_footprint=8192),
                               replace(machine, background_load=0, background_footprint=1 << 20)], expected[1:]):
        served = run(machine, Execution(store=store))
        assert (store.simulated, store.re_costed, store.reused) == paths
        fresh = run(machine, None)
        pd.testing.assert_frame_equal(served.processes, fresh.processes)
        pd.testing.assert_frame_equal(served.runs, fresh.runs)
    assert served.processes["cpu"].iloc[0] == 0


def _bound_elsewhere() -> RunStore:
    store = RunStore()
    store.bind(random_trace())
    return store


def test_store_keeps_pixel_lines_per_placement():
    """The store's pixel lines equal pixel_lines' for every placement, are worked out once per placement (an
    equal placement built again is served the kept result), and two placements whose page tables alone
    differ get their own. Fails if the key leaves out the page table (``placed.pages.frame``): the random
    placement is then served the contiguous one's lines."""
    from coherence.page_placement import PagePlacement
    from coherence.pixel_lines import pixel_lines

    trace = written_trace(16, 12, seed=5)
    store = RunStore()

    def placed(policy, seed):
        return place_layout(get_layout("compact"), trace).with_pages(PagePlacement(policy, page_size=512, seed=seed),
                                                                     SMALL)

    kept = {}
    for policy, seed in (("contiguous", 0), ("random", 1), ("random", 2)):
        kept[seed] = store.pixel_lines(trace, placed(policy, seed), 32)
        expected = pixel_lines(trace, placed(policy, seed), 32)
        for name in ("line_offsets", "addresses", "writes", "pixel_writes"):
            np.testing.assert_array_equal(getattr(kept[seed], name), getattr(expected, name))
        assert store.pixel_lines(trace, placed(policy, seed), 32) is kept[seed]
    assert not np.array_equal(kept[1].addresses, kept[2].addresses)


def _stream_calls(trace, store):
    """Six studies of one trace sharing ``store``: costs changed (re-costed), repeated (reused), other users
    added (fixed runs served, the rest simulated), pages placed elsewhere (all simulated, new line
    addresses), then back to the first placement."""
    from coherence.page_placement import PagePlacement
    from coherence.studies import StudyCall

    machine = Machine(n_cpus=8, quantum_cycles=2000, background_load=0, background_footprint=2048)
    rng = np.random.default_rng(21)
    first, second, third = (random_costs(rng, SMALL_TLB) for _ in range(3))
    elsewhere = replace(machine, page_placement=PagePlacement("random", page_size=512, seed=3))
    setups = [(first, machine), (second, machine), (second, machine),
              (first, replace(machine, background_load=3)), (second, elsewhere), (third, machine)]
    return [StudyCall(trace, ("S", "B", "DB"), (1, 4), hierarchy=hierarchy, cost=cost, machine=machine,
                      execution=Execution(store=store)) for (hierarchy, cost), machine in setups]


def test_stream_serves_runs_as_studies_one_after_another():
    """Studies through study_stream (several under way at once on two threads) give the tables of the same
    studies made one after another, exactly, and their store takes the same paths (simulated, re-costed,
    reused). Fails if _StudyPlan does not put the futures of its runs in the store (drop the
    ``self.store.add(..., future)`` loop): later studies, planned before earlier ones finish, then simulate
    what one after another re-costs or reuses (checked)."""
    from coherence.studies import study_stream

    trace = written_trace(128, 64, seed=3)
    one_by_one = RunStore()
    expected = [study(call.trace, call.mappings, call.n_processes, hierarchy=call.hierarchy, cost=call.cost,
                      machine=call.machine, progress=False, execution=call.execution)
                for call in _stream_calls(trace, one_by_one)]
    streamed = RunStore()
    results = list(study_stream(_stream_calls(trace, streamed), n_jobs=2, window=3))
    assert len(results) == len(expected)
    for got, want in zip(results, expected):
        pd.testing.assert_frame_equal(got.runs, want.runs)
        pd.testing.assert_frame_equal(got.processes, want.processes)
        assert got.parameters == want.parameters
    paths = (one_by_one.simulated, one_by_one.re_costed, one_by_one.reused)
    assert (streamed.simulated, streamed.re_costed, streamed.reused) == paths
    assert min(paths) > 0  # every path is taken


def test_stream_holds_no_more_placements_than_one_study_after_another(monkeypatch):
    """While study_stream works out a placement's line addresses, no more than LINES_KEPT - 1 others are
    held anywhere (runs slowed so that several studies are under way). Fails if study_stream does not
    wait for the studies under way that use other line addresses (drop its ``_wait_for(...)`` call): the
    studies under way then hold three placements (checked)."""
    import gc
    import time
    import weakref

    import coherence.pixel_lines as pixel_lines_module
    import coherence.studies as studies
    from coherence.page_placement import PagePlacement
    from coherence.recost import LINES_KEPT
    from coherence.studies import StudyCall, study_stream

    made, held = [], []
    real_lines, real_run = pixel_lines_module.pixel_lines, studies.simulate_run

    def tracked_lines(*args, **kwargs):  # each placement's addresses followed by a weak reference to an array
        gc.collect()
        held.append(sum(ref() is not None for ref in made))
        lines = real_lines(*args, **kwargs)
        made.append(weakref.ref(lines.addresses))
        return lines

    def slow_run(*args, **kwargs):
        time.sleep(0.05)
        return real_run(*args, **kwargs)

    monkeypatch.setattr(pixel_lines_module, "pixel_lines", tracked_lines)
    monkeypatch.setattr(studies, "simulate_run", slow_run)
    trace = written_trace(32, 16, seed=4)
    store = RunStore()
    calls = [StudyCall(trace, ("S", "B", "DB"), (1, 4), hierarchy=SMALL, execution=Execution(store=store),
                       machine=Machine(n_cpus=8, page_placement=PagePlacement("random", page_size=512, seed=seed)))
             for seed in range(6)]
    results = list(study_stream(calls, n_jobs=2, window=4))
    assert len(results) == 6 and len(made) == 6
    assert max(held) <= LINES_KEPT - 1


def test_store_places_each_layout_once_and_keys_lines_alike():
    """The store's placed layouts equal place_layout's for every memory image (the heap's included), are
    worked out once per layout and scene while kept (the least recently used of PLACED_KEPT + 1 goes), and
    the line key the store makes from a kept placement's digest is the one made from scratch, page placement
    included; the same layout without the scene is placed again. Fails if placed_layout keys on the scene
    alone (``key = id(scene)``): every image is then served the first one's addresses (checked), or on the
    layout alone without checking the kept scene (``key = repr(layout)`` and ``if kept is None:``: the last
    assert, checked)."""
    from coherence.page_placement import PagePlacement
    from coherence.recost import PLACED_KEPT, _lines_key
    from tracer.rendering.render import RenderOptions, render
    from scene_factory import random_scene

    scene = random_scene(n=30, seed=2)
    trace = render(scene, options=RenderOptions(size=8)).trace
    store = RunStore()
    layouts = [get_layout(name) for name in ("compact", "alpha1997", "malloc1997")]
    layouts.append(layouts[0].scaled(2))
    assert len(layouts) == PLACED_KEPT + 1
    kept = []
    for layout in layouts:
        placed = store.placed_layout(trace, layout, scene)
        expected = place_layout(layout, trace, scene)
        for name in ("record_start", "record_size", "kind_first"):
            np.testing.assert_array_equal(getattr(placed, name), getattr(expected, name))
        assert placed.end == expected.end
        assert store.placed_layout(trace, layout, scene) is placed
        paged = placed.with_pages(PagePlacement("random", page_size=512, seed=3), SMALL)
        assert store._lines_key(paged, 32, None, None) == _lines_key(paged, 32, None, None)
        kept.append(placed)
    assert store.placed_layout(trace, layouts[-1], scene) is kept[-1]
    assert store.placed_layout(trace, layouts[0], scene) is not kept[0]  # the least recently used went
    # without the scene, polygons and patches get 4 vertices each: a placement of its own
    assert store.placed_layout(trace, layouts[0], None) is not store.placed_layout(trace, layouts[0], scene)


def test_store_works_out_compute_cycles_and_replay_keys_once_per_input():
    """The store's compute cycles equal the cost model's for each set of weights and are worked out once per
    set (a clock change alone is served the kept ones); a mapping's replay is worked out once per mapping
    object and process count. Fails if RunStore.compute_cycles keys on the clock instead of the weights
    (``key = cost.clock_hz``): the second weights are then served the first's cycles (checked)."""
    from coherence.recost import compute_digest

    trace = written_trace(16, 12, seed=6)
    store = RunStore()
    rng = np.random.default_rng(5)
    _, first = random_costs(rng, SMALL)
    _, second = random_costs(rng, SMALL)
    second = replace(second, clock_hz=first.clock_hz)
    for cost in (first, second):
        compute, digest = store.compute_cycles(trace, cost)
        np.testing.assert_array_equal(compute, cost.compute_cycles(trace.counters, COUNTER_NAMES))
        assert digest == compute_digest(compute)
    kept = store.compute_cycles(trace, replace(first, clock_hz=2 * first.clock_hz))[0]
    assert kept is store.compute_cycles(trace, first)[0]
    calls = []

    def work_out():
        calls.append(1)
        return len(calls)

    strip, block = get_mapping("S"), get_mapping("B")
    assert [store.replay_of(trace, mapping, n, work_out) for mapping, n in
            ((strip, 1), (strip, 1), (strip, 4), (block, 4), (strip, 4))] == [1, 1, 2, 3, 2]


def test_a_failed_study_leaves_no_run_for_others_to_wait_on(monkeypatch):
    """A study that fails while working out its line addresses has put its runs in the store as futures;
    they fail with its error, so the next study on the store simulates them and finishes (with the runs
    of a fresh store). Fails (the second study waits for ever; here: times out) if _StudyPlan.start stops
    failing the futures of runs it did not submit."""
    import threading

    import coherence.pixel_lines as pixel_lines_module

    trace = written_trace(32, 16, seed=4)
    store = RunStore()
    real = pixel_lines_module.pixel_lines

    def fail(*args, **kwargs):
        raise MemoryError("no room for line addresses")

    monkeypatch.setattr(pixel_lines_module, "pixel_lines", fail)
    with pytest.raises(MemoryError):
        study(trace, ("S", "B"), (1, 4), hierarchy=SMALL, execution=Execution(store=store), progress=False)
    monkeypatch.setattr(pixel_lines_module, "pixel_lines", real)
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("runs", study(
        trace, ("S", "B"), (1, 4), hierarchy=SMALL, execution=Execution(store=store), progress=False).runs),
        daemon=True)
    thread.start()
    thread.join(120)
    assert "runs" in result, "the second study is still waiting for the first one's runs"
    fresh = study(trace, ("S", "B"), (1, 4), hierarchy=SMALL, execution=Execution(store=RunStore()),
                  progress=False).runs
    pd.testing.assert_frame_equal(result["runs"], fresh)
