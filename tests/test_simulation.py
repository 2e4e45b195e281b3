"""The schedule simulation against plain replays through cachesim.simulate."""
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cachesim import CacheState, Hierarchy, alpha21164, simulate
from coherence.cost import CostModel
from coherence.layout import get_layout
from coherence.distribution import Distribution
from coherence.mappings import get_mapping
from coherence.metrics import add_speedups, run_summary
from coherence.simulation import Machine, simulate_run
from tracer.trace.access import COUNTER_NAMES, RecordKind

from trace_factory import SMALL, random_trace


def placed_for(trace):
    return get_layout("alpha1997").place({kind: 60 for kind in RecordKind}, textures=[[(60, 1)]])


def distribution(trace, owner_of_task, tasks, n, dynamic=False, dispatch=0.0):
    offsets = np.concatenate(([0], np.cumsum([len(t) for t in tasks]))).astype(np.int64)
    return Distribution("test", trace.width, trace.height, n, offsets,
                        np.concatenate(tasks).astype(np.int64),
                        None if dynamic else np.asarray(owner_of_task, dtype=np.int64), dispatch)


def replay(trace, placed, pixels, state, hierarchy, cost):
    """Reference: one pixel at a time through cachesim.simulate on ``state``."""
    compute = cost.compute_cycles(trace.counters, COUNTER_NAMES)
    line = min(level.line_size for level in hierarchy.levels)
    latency = [level.latency for level in hierarchy.levels]
    total_compute = total_memory = 0.0
    for pixel in pixels:
        records = trace.records[trace.pixel_offsets[pixel]:trace.pixel_offsets[pixel + 1]]
        result = simulate(placed.addresses(records, line), state)
        total_memory += float(np.dot(result.hits, latency) + result.misses[-1] * hierarchy.memory_latency)
        total_compute += compute[pixel]
    return total_compute, total_memory


@pytest.mark.parametrize("hierarchy", [SMALL, alpha21164(),
                                       Hierarchy(SMALL.levels, memory_latency=50, inclusion="inclusive")])
def test_static_run_equals_per_process_replay(hierarchy):
    trace = random_trace()
    placed = placed_for(trace)
    cost = CostModel(ray=3, node_visit=1, test_sphere=5, shading=11)
    rng = np.random.default_rng(1)
    pixels = rng.permutation(trace.width * trace.height)
    tasks = np.array_split(pixels, 7)
    owner = [0, 1, 2, 0, 1, 2, 2]
    run = simulate_run(trace, distribution(trace, owner, tasks, 3), hierarchy, placed, cost, Machine(n_cpus=4))
    for process in range(3):
        mine = np.concatenate([task for task, who in zip(tasks, owner) if who == process])
        state = CacheState(hierarchy)
        compute, memory = replay(trace, placed, mine, state, hierarchy, cost)
        row = run.processes.iloc[process]
        assert row["pixels"] == mine.size
        assert row["compute_cycles"] == pytest.approx(compute)
        assert row["memory_cycles"] == pytest.approx(memory)
        totals = state.totals()
        for index, level in enumerate(hierarchy.levels):
            assert row[f"{level.name}_hits"] == totals.hits[index]
            assert row[f"{level.name}_misses"] == totals.misses[index]
        assert row["user_cycles"] == pytest.approx(compute + memory)
        assert row["tests_sphere"] == trace.counters[mine, COUNTER_NAMES.index("tests_sphere")].sum()
    assert run.task_owner.tolist() == owner


def test_infinite_quantum_runs_processes_one_after_another():
    trace = random_trace(seed=2)
    placed = placed_for(trace)
    cost = CostModel()
    halves = np.array_split(np.arange(trace.width * trace.height), 2)
    run = simulate_run(trace, distribution(trace, [0, 1], halves, 2), SMALL, placed, cost,
                       Machine(n_cpus=1, quantum_cycles=0))
    state = CacheState(SMALL)
    first = sum(replay(trace, placed, halves[0], state, SMALL, cost))
    second = sum(replay(trace, placed, halves[1], state, SMALL, cost))
    assert run.processes["user_cycles"].tolist() == pytest.approx([first, second])
    assert run.processes["finish_cycles"].tolist() == pytest.approx([first, first + second])


def test_time_slices_alternate_on_a_shared_cpu():
    trace = random_trace(seed=3)
    placed = placed_for(trace)
    cost = CostModel()
    halves = np.array_split(np.arange(trace.width * trace.height), 2)
    quantum = 5000.0
    run = simulate_run(trace, distribution(trace, [0, 1], halves, 2), SMALL, placed, cost,
                       Machine(n_cpus=1, quantum_cycles=quantum))
    # Reference: run pixels of the current process until its slice reaches
    # the quantum, then switch; one cache state for the CPU.
    state = CacheState(SMALL)
    queues = [list(halves[0]), list(halves[1])]
    user = [0.0, 0.0]
    current, used = 0, 0.0
    while queues[0] or queues[1]:
        if not queues[current] or (used >= quantum and queues[1 - current]):
            current, used = 1 - current, 0.0
        pixel = queues[current].pop(0)
        cycles = sum(replay(trace, placed, [pixel], state, SMALL, cost))
        user[current] += cycles
        used += cycles
    assert run.processes["user_cycles"].tolist() == pytest.approx(user)


def test_forced_dynamic_order_equals_the_static_assignment():
    trace = random_trace(width=12, height=8, seed=4)
    placed = placed_for(trace)
    cost = CostModel()
    tasks = np.array_split(np.arange(trace.width * trace.height), 12)
    dynamic = simulate_run(trace, distribution(trace, None, tasks, 3, dynamic=True, dispatch=100.0),
                           SMALL, placed, cost, Machine(n_cpus=3))
    assert sorted(set(dynamic.task_owner.tolist())) == [0, 1, 2]
    static = simulate_run(trace, distribution(trace, dynamic.task_owner, tasks, 3), SMALL, placed, cost,
                          Machine(n_cpus=3))
    columns = ["pixels", "tasks", "compute_cycles", "memory_cycles", "L1_hits", "L2_misses"]
    assert dynamic.processes[columns].equals(static.processes[columns])
    assert dynamic.processes["dispatch_cycles"].tolist() == (100.0 * dynamic.processes["tasks"]).tolist()
    # The next free process takes the next task: the first three go to 0, 1, 2.
    assert dynamic.task_owner[:3].tolist() == [0, 1, 2]


def test_machine_validation_and_placement():
    assert Machine(n_cpus=4).cpu_of(8).tolist() == [0, 1, 2, 3, 0, 1, 2, 3]
    assert Machine(n_cpus=4, scheduler="static", placement="neighbours").cpu_of(8).tolist() == [0, 0, 1, 1, 2, 2,
                                                                                               3, 3]
    with pytest.raises(ValueError, match="Machine.n_cpus"):
        Machine(n_cpus=0)
    with pytest.raises(ValueError, match="Machine.placement"):
        Machine(placement="random")


# --------------------------------------------------------------------------
# Processes with no work (issue 13): a legal run, never a crash.

IDLE_SCRIPT = """
import sys, warnings
sys.path.insert(0, {tests!r})
from trace_factory import random_trace
from coherence.mappings import get_mapping
from coherence.layout import get_layout
from coherence.cost import CostModel
from coherence.simulation import Machine, simulate_run
from tracer.trace.access import RecordKind
from trace_factory import SMALL
warnings.simplefilter("ignore")
trace = random_trace(width=8, height=4, seed=5)
placed = get_layout("compact").place({{kind: 60 for kind in RecordKind}}, textures=[[(60, 1)]])
for name, n in (("S", 6), ("R", 7), ("P", 40), ("B", 33), ("DB", 3), ("S", 33)):
    run = simulate_run(trace, get_mapping(name).build(8, 4, n), SMALL, placed, CostModel(), Machine(n_cpus=4))
    print(name, n, int(run.processes["pixels"].sum()))
"""


def test_processes_without_work_do_not_crash_the_kernel(tmp_path):
    """In a subprocess, so that a segfault fails this test instead of killing pytest."""
    script = tmp_path / "idle.py"
    script.write_text(IDLE_SCRIPT.format(tests=str(Path(__file__).parent)))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert done.returncode not in (-signal.SIGSEGV, 128 + signal.SIGSEGV), "segfault: " + done.stderr[-2000:]
    assert done.returncode == 0, done.stderr[-2000:]
    # Every pixel rendered exactly once in every run.
    assert [line.split()[-1] for line in done.stdout.split("\n") if line] == ["32"] * 6


@pytest.mark.parametrize("machine", [Machine(n_cpus=8), Machine(n_cpus=2, quantum_cycles=5000.0)])
def test_idle_processes_have_zero_user_time_and_the_worst_process_decides(machine):
    trace = random_trace(width=8, height=4, seed=6)
    placed = placed_for(trace)
    cost = CostModel(ray=3, node_visit=1, test_sphere=5, shading=11)
    rows = [np.arange(row * 8, row * 8 + 8) for row in range(4)]
    with pytest.warns(UserWarning, match="2 of 6 processes get no pixels of the 8x4 image"):
        run = simulate_run(trace, get_mapping("S").build(8, 4, 6), SMALL, placed, cost, machine)
    user = run.processes["user_cycles"].to_numpy()
    assert run.processes["pixels"].tolist() == [8, 8, 8, 8, 0, 0]
    assert user[4:].tolist() == [0.0, 0.0]
    assert run.processes["tasks"].sum() == 6  # the empty strips are handed out, and render nothing
    if machine.n_cpus >= 6:  # every process alone on a CPU: each equals a cold replay of its row
        for process, row in enumerate(rows):
            assert user[process] == pytest.approx(sum(replay(trace, placed, row, CacheState(SMALL), SMALL, cost)))
    one = simulate_run(trace, get_mapping("S").build(8, 4, 1), SMALL, placed, cost, machine)
    runs = add_speedups(pd.DataFrame([
        {"mapping": "S", **run_summary(frame, SMALL.level_names, cost.clock_hz, real)}
        for frame, real in ((one.processes, one.real_cycles), (run.processes, run.real_cycles))]))
    assert runs["speedup_user"].iloc[1] == pytest.approx(one.processes["user_cycles"][0] / user.max())
    assert runs["load_balance"].iloc[1] == pytest.approx(user.mean() / user.max())


def test_pixel_mapping_with_more_processes_than_pixels():
    trace = random_trace(width=3, height=2, seed=7)
    placed = placed_for(trace)
    cost = CostModel()
    with pytest.warns(UserWarning, match="4 of 10 processes get no pixels"):
        run = simulate_run(trace, get_mapping("P").build(3, 2, 10), SMALL, placed, cost, Machine(n_cpus=16))
    assert run.processes["pixels"].tolist() == [1] * 6 + [0] * 4
    for pixel in range(6):
        assert run.processes["user_cycles"][pixel] == pytest.approx(
            sum(replay(trace, placed, [pixel], CacheState(SMALL), SMALL, cost)))


def test_dynamic_blocks_fewer_than_processes_warn():
    trace = random_trace(width=8, height=8, seed=8)
    with pytest.warns(UserWarning, match="1 non-empty tasks for 3 processes .* cannot exceed 1"):
        run = simulate_run(trace, get_mapping("DB").build(8, 8, 3), SMALL, placed_for(trace), CostModel(),
                           Machine(n_cpus=4))
    assert run.processes["pixels"].tolist() == [64, 0, 0]
    assert run.processes["user_cycles"][1:].tolist() == [0.0, 0.0]


def test_counters_by_process_equal_a_sum_per_owner():
    from coherence.simulation import _counters_by_process

    # by hand: pixels 0 and 2 are process 1's, pixel 1 process 0's
    counters = np.array([[1, 2], [10, 20], [100, 200]], dtype=np.int64)
    assert _counters_by_process(counters, np.array([1, 0, 1]), 3).tolist() == [[10, 20], [101, 202], [0, 0]]
    rng = np.random.default_rng(8)
    for n_processes in (1, 3, 16):
        counters = rng.integers(0, 1 << 40, (500, 7))
        owner = rng.integers(0, n_processes, 500)
        expected = [[int(counters[owner == p, c].sum()) for c in range(7)] for p in range(n_processes)]
        assert _counters_by_process(counters, owner, n_processes).tolist() == expected
