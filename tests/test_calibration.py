"""Bounded, tied cost fits against a slow general-purpose minimiser and hand-made cases."""
import numpy as np
import pandas as pd
import pytest
from scipy.optimize import minimize

from coherence.calibration import (OPERATION_FLOPS, STUDY1997_COSTS, CostStructure, FittedCost, fit_costs,
                                   fitted_values, leave_one_out, rms)
from coherence.cost import OPERATIONS

CLOCK = 1e6
COUNTERS = ("primary_rays", "shadow_rays", "node_visits", "index_reads", "tests_sphere", "tests_triangle",
            "shading", "light_reads")


def _runs(n_runs, seed):
    rng = np.random.default_rng(seed)
    return pd.DataFrame(rng.integers(1_000, 100_000, size=(n_runs, len(COUNTERS))), columns=COUNTERS,
                        index=[f"run{i}" for i in range(n_runs)])


def _seconds(runs, model, memory):
    return (model.compute_cycles(runs[list(COUNTERS)], COUNTERS) + memory) / CLOCK


def test_recovers_costs_that_obey_the_structure():
    runs = _runs(6, 1)
    memory = np.linspace(1e6, 3e6, 6)
    truth = STUDY1997_COSTS.model([220.0, 900.0, 40.0], clock_hz=CLOCK, name="truth")
    measured = runs.assign(seconds=_seconds(runs, truth, memory), memory_cycles=memory)
    model, residuals = fit_costs(measured, clock_hz=CLOCK)
    assert fitted_values(model, STUDY1997_COSTS) == pytest.approx({"test": 220.0, "ray": 900.0, "node_visit": 40.0})
    # ties: every operation is its flop ratio times the sphere test
    for operation, flops in OPERATION_FLOPS.items():
        assert getattr(model, operation) == pytest.approx(220.0 * flops / OPERATION_FLOPS["test_sphere"])
    assert np.abs(residuals["relative_error"]).max() < 1e-9
    assert residuals["memory_share"].to_numpy() == pytest.approx(memory / (_seconds(runs, truth, memory) * CLOCK))


def test_matches_a_slow_bounded_minimiser_and_respects_bounds():
    runs = _runs(5, 2)
    rng = np.random.default_rng(3)
    measured = runs.assign(seconds=rng.uniform(50, 400, 5), memory_cycles=rng.uniform(0, 1e7, 5))
    model, residuals = fit_costs(measured, clock_hz=CLOCK)
    values = np.array(list(fitted_values(model, STUDY1997_COSTS).values()))
    low, high = STUDY1997_COSTS.fitted[0].bounds
    assert np.all(values >= low - 1e-9) and np.all(values <= high + 1e-9)

    def objective(x):
        trial = STUDY1997_COSTS.model(x, clock_hz=CLOCK, name="trial")
        predicted = _seconds(runs, trial, measured["memory_cycles"].to_numpy())
        return float(np.sum(((predicted - measured["seconds"]) / measured["seconds"]) ** 2))

    best = min((minimize(objective, start, bounds=[(low, high)] * 3, method="L-BFGS-B",
                         options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10_000})
                for start in ([100, 100, 100], [10, 4000, 10], [4000, 10, 2000])), key=lambda r: r.fun)
    assert objective(values) <= best.fun * (1 + 1e-6) + 1e-12
    assert rms(residuals["relative_error"]) == pytest.approx(np.sqrt(objective(values) / 5))


def test_a_cost_the_data_wants_negative_stops_at_its_lower_bound():
    # two runs that differ only in node visits, the one with more of them faster: node_visit wants < 0
    runs = pd.DataFrame({"primary_rays": [1000, 1000], "node_visits": [0, 100_000], "tests_sphere": [5000, 5000]})
    structure = CostStructure(fitted=(FittedCost("test", {"test_sphere": 1.0}), FittedCost("node", {"node_visit": 1.0})),
                              fixed={op: 1.0 for op in OPERATIONS if op not in ("test_sphere", "node_visit")})
    measured = runs.assign(seconds=[1.0, 0.9])
    model, _ = fit_costs(measured, structure, clock_hz=CLOCK)
    assert model.node_visit == pytest.approx(5.0)


def test_leave_one_out_predicts_each_run_from_the_others():
    runs = _runs(5, 4)
    rng = np.random.default_rng(5)
    measured = runs.assign(seconds=rng.uniform(50, 400, 5), memory_cycles=rng.uniform(0, 1e7, 5))
    table = leave_one_out(measured, clock_hz=CLOCK)
    assert list(table.index) == list(measured.index)
    for name in measured.index:
        model, _ = fit_costs(measured.drop(index=name), clock_hz=CLOCK)
        row = measured.loc[[name]]
        cycles = model.compute_cycles(row[list(COUNTERS)], COUNTERS)[0] + row["memory_cycles"].iloc[0]
        assert table.loc[name, "predicted_seconds"] == pytest.approx(cycles / CLOCK)
        assert table.loc[name, "test"] == pytest.approx(fitted_values(model, STUDY1997_COSTS)["test"])


def test_exact_data_is_predicted_exactly_when_left_out():
    runs = _runs(5, 6)
    truth = STUDY1997_COSTS.model([100.0, 500.0, 30.0], clock_hz=CLOCK, name="truth")
    measured = runs.assign(seconds=_seconds(runs, truth, 0.0))
    assert np.abs(leave_one_out(measured, clock_hz=CLOCK)["relative_error"]).max() < 1e-9


@pytest.mark.parametrize("make, message", [
    (lambda: FittedCost("t", {}), "at least one"),
    (lambda: FittedCost("t", {"warp": 1.0}), "unknown operation"),
    (lambda: FittedCost("t", {"ray": 0.0}), "must be > 0"),
    (lambda: FittedCost("t", {"ray": 1.0}, bounds=(10, 5)), "bounds"),
    (lambda: CostStructure(fitted=(FittedCost("a", {"ray": 1.0}), FittedCost("b", {"ray": 2.0}))), "both"),
    (lambda: CostStructure(fitted=(FittedCost("a", {"ray": 1.0}),)), "neither fitted nor fixed"),
    (lambda: CostStructure(fitted=(FittedCost("a", {"ray": 1.0}),), fixed={op: 1.0 for op in OPERATIONS}),
     "both fitted and fixed"),
    (lambda: CostStructure(fitted=()), "at least one"),
])
def test_structures_are_validated(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_fit_errors_name_the_problem():
    runs = _runs(3, 7)
    with pytest.raises(ValueError, match="'seconds'"):
        fit_costs(runs)
    with pytest.raises(ValueError, match="> 0"):
        fit_costs(runs.assign(seconds=[1.0, 0.0, 2.0]))
    with pytest.raises(ValueError, match="at least two"):
        leave_one_out(runs.assign(seconds=1.0).iloc[:1])


def test_study_structure_fits_three_costs_and_fixes_nothing_to_zero():
    assert len(STUDY1997_COSTS.fitted) == 3
    model = STUDY1997_COSTS.model([5.0, 5.0, 5.0], clock_hz=CLOCK, name="lowest")
    assert all(getattr(model, op) > 0 for op in OPERATIONS)
