"""study(): speed-ups, the efficiency decomposition and invariants over mappings."""
import numpy as np
import pytest

from coherence.distribution import Distribution
from coherence.mappings import Mapping
from coherence.metrics import DECOMPOSITION_COLUMNS, EFFICIENCY_FACTORS, LOSS_COLUMNS
from coherence.simulation import Machine
from coherence.studies import Execution, study
from trace_factory import SMALL, random_trace
from tracer.trace.access import COUNTER_NAMES


@pytest.fixture(scope="module")
def result():
    trace = random_trace(width=32, height=16, seed=5)
    return trace, study(trace, ["S", "P", "R", "B", "DB"], [2, 4, 8], hierarchy=SMALL,
                        machine=Machine(n_cpus=4, quantum_cycles=20000), progress=False)


def test_one_process_strip_pixel_row_share_one_stream(result):
    _, outcome = result
    one = outcome.runs[outcome.runs["n_processes"] == 1].set_index("mapping")
    for column in ("user_cycles_max", "L1_accesses", "memory_accesses"):
        assert one.loc["S", column] == one.loc["P", column] == one.loc["R", column]
    assert (one["speedup_user"] == 1).all()


class _RowTasks(Mapping):
    """Rows round-robin like R, but one task per row: at one process the same stream as S, cut into
    as many tasks as there are rows."""

    name = "row-tasks"

    def _build(self, width, height, n_processes):
        offsets = np.arange(height + 1, dtype=np.int64) * width
        return Distribution(self.name, width, height, n_processes, offsets, np.arange(width * height),
                            np.arange(height) % n_processes)


def test_shared_runs_equal_their_own_simulation():
    # S, P, R and row-tasks at one process replay one stream, simulated once; each run must equal
    # its own simulation, its tasks column included.
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.metrics import run_summary
    from coherence.simulation import simulate_run
    from coherence.studies import _replay_key, place_layout

    trace = random_trace(width=16, height=8, seed=9)
    machine = Machine(n_cpus=2, quantum_cycles=5000)
    mappings = {"S": "S", "P": "P", "R": "R", "DB": "DB", "row-tasks": _RowTasks()}
    outcome = study(trace, list(mappings.values()), [1, 2], hierarchy=SMALL, machine=machine, progress=False)
    placed = place_layout(get_layout("compact"), trace)
    cost = get_cost_model("alpha8400")
    one = [get_mapping(name).build(16, 8, 1) for name in ("S", "P", "R")] + [_RowTasks().build(16, 8, 1)]
    assert len({_replay_key(d) for d in one}) == 1  # the case the sharing exists for
    assert _replay_key(get_mapping("S").build(16, 8, 2)) != _replay_key(get_mapping("R").build(16, 8, 2))
    for (name, n), frame in outcome.processes.groupby(["mapping", "n_processes"], sort=False):
        run = simulate_run(trace, get_mapping(mappings[name]).build(16, 8, n), SMALL, placed, cost, machine)
        mine = frame.drop(columns=["mapping", "n_processes"]).reset_index(drop=True)
        assert mine.equals(run.processes), (name, n)
        row = outcome.runs.query("mapping == @name and n_processes == @n").iloc[0]
        assert row["real_cycles"] == run.real_cycles
        assert row["user_cycles_max"] == run_summary(run.processes, SMALL.level_names, cost.clock_hz,
                                                     run.real_cycles)["user_cycles_max"]


def test_shared_lines_budget_changes_no_result():
    # With no budget every run converts its pixels itself; with room, the runs share the line addresses.
    trace = random_trace(width=16, height=8, seed=4)
    machine = Machine(n_cpus=2, quantum_cycles=5000)
    frames = [study(trace, ["S", "P", "B"], [1, 3], hierarchy=SMALL, machine=machine, progress=False,
                    execution=Execution(shared_lines_budget=budget)) for budget in (0, 1 << 20)]
    assert frames[0].runs.equals(frames[1].runs)
    assert frames[0].processes.equals(frames[1].processes)
    with pytest.raises(ValueError, match="shared_lines_budget"):
        Execution(shared_lines_budget=-1)


def test_factors_multiply_to_efficiency(result):
    _, outcome = result
    runs = outcome.runs
    product = runs["load_balance"] * runs["coherence_factor"] * runs["dispatch_factor"]
    np.testing.assert_allclose(product, runs["efficiency"], rtol=1e-12)
    assert (runs.loc[runs["mapping"] != "DB", "dispatch_factor"] == 1).all()
    db = runs[runs["mapping"] == "DB"].set_index("n_processes")
    assert db.loc[1, "dispatch_factor"] == pytest.approx(1) and db.loc[1, "coherence_factor"] == pytest.approx(1)
    assert (db["dispatch_share"] > 0).all()
    one = runs[runs["n_processes"] == 1].set_index("mapping")
    assert one.loc["DB", "speedup_user_vs_best"] < 1


def test_decomposition_columns_name_the_factors(result):
    """The one list of decomposition columns names what the runs carry: its
    factors multiply to the efficiency and each loss is one minus its factor;
    ``coherence simulate --help`` spells the same product. Fails if
    ``"coherence_factor"`` is dropped from ``EFFICIENCY_FACTORS``."""
    from analyses.commands.simulate import EPILOG

    _, outcome = result
    runs = outcome.runs
    assert set(DECOMPOSITION_COLUMNS) <= set(runs.columns)
    product = np.prod([runs[column].to_numpy() for column in EFFICIENCY_FACTORS], axis=0)
    np.testing.assert_allclose(product, runs["efficiency"], rtol=1e-12)
    assert (runs["coherence_factor"] != 1).any() and (runs["load_balance"] != 1).any()
    for factor, loss in zip(EFFICIENCY_FACTORS, LOSS_COLUMNS, strict=True):
        np.testing.assert_allclose(runs[loss], 1 - runs[factor], rtol=0, atol=1e-15)
    assert "efficiency = speedup / n = " + " x ".join(EFFICIENCY_FACTORS) in " ".join(EPILOG.split())


def test_per_process_sums_equal_trace_totals(result):
    trace, outcome = result
    totals = np.asarray(trace.counters).sum(axis=0)
    for (mapping, n), group in outcome.processes.groupby(["mapping", "n_processes"]):
        assert len(group) == n
        assert group["pixels"].sum() == trace.width * trace.height
        for column, name in enumerate(COUNTER_NAMES):
            assert group[name].sum() == totals[column], (mapping, n, name)
        # Every access is counted at L1.
        assert group["L1_accesses"].sum() == outcome.runs.query(
            "mapping == @mapping and n_processes == @n")["L1_accesses"].item()


def test_more_processes_than_cpus_share_caches(result):
    _, outcome = result
    eight = outcome.processes.query("n_processes == 8")
    assert sorted(eight["cpu"].unique()) == [0, 1, 2, 3]
    runs = outcome.runs.set_index(["mapping", "n_processes"])
    # Real time on 4 CPUs cannot beat the total work spread over 4 CPUs.
    assert (runs.xs(8, level="n_processes")["real_cycles"]
            >= runs.xs(8, level="n_processes")["work_cycles"] / 4 - 1e-6).all()


def test_bad_arguments(result):
    trace, _ = result
    with pytest.raises(ValueError, match="n_processes"):
        study(trace, ["S"], [0], progress=False)
    with pytest.raises(ValueError, match="distinct names"):
        study(trace, ["S", "S"], [2], progress=False)


def test_shared_study_keeps_pixel_misses_of_the_asked_counts():
    """On shared levels, Execution.pixel_misses_at=(1, 2) keeps each run's misses per pixel at 1 and 2
    processes, equal to simulate_shared_run's (record pixel_misses) of that mapping and count; S and P at one
    process, simulated once, share theirs; nothing at 3; refused on private caches and for a count < 1.
    Mutation: ``simulated[self.first_of[key]]`` -> ``simulated[self.first_of[self.keys[0]]]`` in
    _StudyPlan.result (every map then the first run's): fails."""
    from cachesim import CacheLevel, Hierarchy
    from cachesim.sharing import SharedHierarchy
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.shared_run import SharedLevels, simulate_shared_run
    from coherence.studies import place_layout

    trace = random_trace(width=12, height=8, seed=3)
    levels = Hierarchy((CacheLevel("L1", 256, 32, 2, "lru", latency=1), CacheLevel("L2", 2048, 32, 4, "lru",
                                                                                    latency=6)),
                       memory_latency=40, name="tiny")
    shared = SharedLevels(SharedHierarchy(levels, n_cores=2, smt=1, shared_by=("thread", "machine")), 50)
    machine = Machine(n_cpus=2, quantum_cycles=3000)
    outcome = study(trace, ["S", "P", "DB"], [1, 2, 3], hierarchy=shared, machine=machine, progress=False,
                    execution=Execution(pixel_misses_at=(1, 2)))
    assert set(outcome.pixel_misses) == {(name, n) for name in ("S", "P", "DB") for n in (1, 2)}
    placed = place_layout(get_layout("compact"), trace)
    for (name, n), kept in outcome.pixel_misses.items():
        run = simulate_shared_run(trace, get_mapping(name).build(12, 8, n), shared.machine, placed,
                                  get_cost_model("alpha8400"), machine, interleave_cycles=50,
                                  record=("pixel_misses",)).run
        np.testing.assert_array_equal(kept, run.pixel_misses, err_msg=f"{name} at {n}")
    assert outcome.pixel_misses[("S", 1)] is outcome.pixel_misses[("P", 1)]
    assert not np.array_equal(outcome.pixel_misses[("S", 2)], outcome.pixel_misses[("P", 2)])
    with pytest.raises(ValueError, match="pixel_misses_at keeps the misses per pixel of runs on shared levels"):
        study(trace, ["S"], [2], hierarchy=SMALL, progress=False, execution=Execution(pixel_misses_at=(2,)))
    with pytest.raises(ValueError, match="Execution.pixel_misses_at"):
        Execution(pixel_misses_at=(0,))
    with pytest.raises(ValueError, match="Execution.pixel_misses_at must be a tuple"):
        Execution(pixel_misses_at=2)
