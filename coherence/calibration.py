"""Fitting a few physical costs to measured times: bounded, tied, and checked by leaving a run out.

A :class:`CostStructure` says which cycles per operation are fitted and how
the others follow: every :data:`coherence.cost.OPERATIONS` entry is either
*fixed* (cycles given in advance) or *tied* to one :class:`FittedCost` by a
multiple fixed in advance. A fitted cost is the cycles of its reference
operation (multiple 1.0); it is bounded, so no operation that happens
millions of times can be fitted to 0 cycles or to an absurd cost.

:func:`fit_costs` solves the bounded least squares of *relative* errors (each
run weighs the same, whatever its length), after taking each run's simulated
memory cycles and fixed operations off its measured time.
:func:`leave_one_out` fits on all runs but one and predicts the one left out,
for every run: the honest error of a model fitted to few measurements.

:data:`STUDY1997_COSTS` is the structure used for the study's five sequential
Strip times: three fitted costs (per intersection test, per ray, per kd-node
visit); every other operation is tied to the test cost by the ratio of
floating-point operations in its routine (:data:`OPERATION_FLOPS`, counted by
hand in ``tracer/rendering/geometry.py`` and ``tracer/rendering/whitted.py``), except the square
root a sphere or cone test takes when its quadratic has real roots: the
21164 has no square-root instruction, so that path pays a fixed
:data:`coherence.cost.SQUARE_ROOT_CYCLES_21164` on top. The share of tests
taking it differs fiftyfold between the study's scenes (about half of
shell's sphere tests, 1% of balls'), so no per-test ratio can stand for it.

:data:`STUDY1997_PRIOR_COSTS`, the default of ``coherence paper``, fits the
same three costs, each within its prior range of :data:`coherence.unknowns.UNKNOWNS`
(counted from the routines' instructions on the 21164, each spanning 4x)
instead of within :data:`STUDY_BOUNDS`. An operation that has a prior of its
own (the triangle test, a light of a shaded hit) stays tied to the sphere
test (:data:`SPHERE_TEST_TIES`, the one rule of ties, which the robustness
study's samples follow too), by the ratio of the low ends of the two priors (the routines'
dependent chains, from which the ranges were counted) instead of by the
flop ratio: since every prior spans the same factor over its chain, the
tied cost lies inside its own prior exactly when the sphere test lies
inside its own. The flop ratio misses the divide and the software square
root that dominate those two chains. What the model cannot explain with
every cost inside its prior is left as the fit's residual
(``unexplained_seconds``) rather than absorbed by one cost. The reason for
this rule is written in ``docs/design.md`` (calibration section).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from coherence.cost import CLOCK_HZ, OPERATIONS, SQUARE_ROOT_CYCLES_21164, CostModel
from coherence.unknowns import unknown
from rtcommon.validate import InputError

#: Floating-point operations (``+``, ``-``, ``*``, ``/``, sqrt and compares each count one)
#: on the full path of each routine, counted by hand in this project's code.
#: Only their ratios are used: they tie the other costs to the sphere test.
#:
#: - sphere test (``hit_sphere``): offset 3, b 5, c 7, discriminant 2,
#:   sqrt 1, root 2, compares 2: 22. (The 21164 computes the square root
#:   in software: a test that takes one also pays the fixed
#:   ``test_root`` cost, see :data:`STUDY1997_COSTS`.)
#: - triangle test (``hit_triangle``, Moller-Trumbore): p 9, det 5, 1/det 1,
#:   s 3, u 6, q 9, v 6, t 6, compares 7: 52.
#: - polygon and patch test (``hit_convex``): plane 5 + 9, compares 2, hit
#:   point 6, then 21 per edge (edge 3, offset 3, triple product 14,
#:   compare 1) for 4 vertices (the layouts' assumption too): 106.
#: - cone test (``hit_cone``): axis projections 18, quadratic 27, root 10,
#:   range checks 15: 70.
#: - shading one hit, before its lights (normal, material, ambient): 20.
#: - one light of a shaded hit (direction and its length 13, N.L 5, Phong
#:   R.V 12, power 1, colour 12, compares 2): 45.
#: - one leaf index entry read (a load and the loop's add and compare): 2.
OPERATION_FLOPS = {
    "test_sphere": 22, "test_triangle": 52, "test_polygon": 106, "test_patch": 106, "test_cone": 70,
    "shading": 20, "light_read": 45, "index_read": 2,
}

#: Bounds of every fitted cost in the study's structure, cycles of its
#: reference operation: no operation is free, and none takes longer than a
#: few hundred memory misses.
STUDY_BOUNDS = (5.0, 5000.0)


@dataclass(frozen=True)
class FittedCost:
    """One fitted cost and the operations tied to it.

    Parameters
    ----------
    name : str
        What the cost is (``"test"``, ``"ray"``, ...).
    multiples : dict of str to float
        Operation name (a :data:`coherence.cost.OPERATIONS` key) to its cost
        as a multiple of the fitted one; the reference operation has 1.0.
    bounds : (float, float)
        Lowest and highest cycles of the reference operation.
    """

    name: str
    multiples: dict
    bounds: tuple = STUDY_BOUNDS

    def __post_init__(self):
        if not self.multiples:
            raise InputError(f"FittedCost {self.name!r}: multiples must name at least one operation")
        for operation, multiple in self.multiples.items():
            if operation not in OPERATIONS:
                raise InputError(f"FittedCost {self.name!r}: unknown operation {operation!r}; "
                                 f"use {sorted(OPERATIONS)}")
            if not (np.isfinite(multiple) and multiple > 0):
                raise InputError(f"FittedCost {self.name!r}: multiple of {operation} must be > 0, got {multiple!r}")
        low, high = (float(b) for b in self.bounds)
        if not (np.isfinite(low) and np.isfinite(high) and 0 <= low < high):
            raise InputError(f"FittedCost {self.name!r}: bounds must be finite with 0 <= low < high, "
                             f"got {self.bounds!r}")
        object.__setattr__(self, "bounds", (low, high))


@dataclass(frozen=True)
class CostStructure:
    """Which costs are fitted, how the rest follow, and what is fixed.

    Parameters
    ----------
    fitted : tuple of FittedCost
        The fitted costs; each operation is tied to at most one.
    fixed : dict of str to float
        Cycles of the operations not tied to a fitted cost. Every operation
        must be fitted, tied or fixed.
    name : str
    """

    fitted: tuple
    fixed: dict = field(default_factory=dict)
    name: str = "custom"

    def __post_init__(self):
        object.__setattr__(self, "fitted", tuple(self.fitted))
        if not self.fitted:
            raise InputError("CostStructure.fitted must hold at least one FittedCost")
        seen = {}
        for cost in self.fitted:
            for operation in cost.multiples:
                if operation in seen:
                    raise InputError(f"CostStructure: {operation} is tied to both {seen[operation]!r} "
                                     f"and {cost.name!r}")
                seen[operation] = cost.name
        both = sorted(set(seen) & set(self.fixed))
        if both:
            raise InputError(f"CostStructure: {both} are both fitted and fixed")
        missing = sorted(set(OPERATIONS) - set(seen) - set(self.fixed))
        if missing:
            raise InputError(f"CostStructure: operations {missing} are neither fitted nor fixed")
        for operation, cycles in self.fixed.items():
            if operation not in OPERATIONS or not (np.isfinite(cycles) and cycles >= 0):
                raise InputError(f"CostStructure.fixed: {operation!r} must be an operation with cycles >= 0")

    def model(self, values, *, clock_hz: float, name: str) -> CostModel:
        """The cost model with fitted cost ``values[i]`` for ``self.fitted[i]``."""
        costs = dict(self.fixed)
        for cost, value in zip(self.fitted, values):
            for operation, multiple in cost.multiples.items():
                costs[operation] = float(value) * multiple
        return CostModel(clock_hz=clock_hz, name=name, **costs)

    def to_dict(self) -> dict:
        return {"name": self.name, "fixed": dict(self.fixed),
                "fitted": [{"name": c.name, "multiples": dict(c.multiples), "bounds": list(c.bounds)}
                           for c in self.fitted]}


def _study1997() -> CostStructure:
    flops = OPERATION_FLOPS
    work = {operation: n / flops["test_sphere"] for operation, n in flops.items()}
    return CostStructure(name="study1997", fitted=(
        FittedCost("test", work),
        FittedCost("ray", {"ray": 1.0}),
        FittedCost("node_visit", {"node_visit": 1.0}),
    ), fixed={"test_root": SQUARE_ROOT_CYCLES_21164})


#: The structure fitted to the study's sequential Strip times within :data:`STUDY_BOUNDS`
#: (``--fit study-bounds``, see module docstring).
STUDY1997_COSTS = _study1997()

#: Operation to the name of its prior range in :data:`coherence.unknowns.UNKNOWNS`.
PRIOR_UNKNOWNS = {"test_sphere": "cost_test_sphere", "test_triangle": "cost_test_triangle",
                  "light_read": "cost_light_read", "ray": "cost_ray", "node_visit": "cost_node_visit"}


def prior_range(operation: str) -> tuple[float, float]:
    """Lowest and highest cycles of ``operation`` in its prior (:data:`PRIOR_UNKNOWNS`)."""
    if operation not in PRIOR_UNKNOWNS:
        raise InputError(f"no prior range for operation {operation!r}; priors exist for {sorted(PRIOR_UNKNOWNS)}")
    entry = unknown(PRIOR_UNKNOWNS[operation])
    return float(entry.low), float(entry.high)


@dataclass(frozen=True)
class CostTie:
    """How one operation's cycles follow the sphere test's.

    Attributes
    ----------
    multiple : float
        Cycles of the operation per cycle of the sphere test.
    source : str
        Where the multiple comes from.
    """

    multiple: float
    source: str


def _sphere_test_ties() -> dict:
    flops = OPERATION_FLOPS
    reference_low = prior_range("test_sphere")[0]
    ties = {}
    for operation, n in flops.items():
        if operation == "test_sphere":
            continue
        if operation in PRIOR_UNKNOWNS:
            ties[operation] = CostTie(prior_range(operation)[0] / reference_low,
                                      "ratio of the low ends of its prior and the sphere test's "
                                      "(the routines' dependent chains on the 21164, coherence.unknowns)")
        else:
            ties[operation] = CostTie(n / flops["test_sphere"],
                                      "ratio of floating-point operations of the routines (OPERATION_FLOPS)")
    return ties


#: The one rule by which operation costs follow the sphere test's, operation
#: -> :class:`CostTie`: an operation with a prior range of its own (the
#: triangle test, one light of a shaded hit) by the ratio of the low ends of
#: the two priors, every other one (polygon, patch and cone tests, shading,
#: an index read) by its routine's flop ratio. The prior fit
#: (:data:`STUDY1997_PRIOR_COSTS`) ties every one of them; a sample of the
#: robustness study (:func:`tied_costs`) samples the operations with priors
#: of their own and ties the rest.
SPHERE_TEST_TIES = _sphere_test_ties()


def tied_costs(test_sphere: float, own=None) -> dict:
    """Cycles of every operation of :data:`SPHERE_TEST_TIES` for a sphere test of ``test_sphere`` cycles.

    Parameters
    ----------
    test_sphere : float
        Cycles of the sphere test, > 0.
    own : dict, optional
        Operation -> cycles of the operations given their own value instead
        of their tie (each a key of :data:`SPHERE_TEST_TIES`).

    Returns
    -------
    dict
        Operation -> cycles, the sphere test included.
    """
    own = dict(own or {})
    unknown_operations = sorted(set(own) - set(SPHERE_TEST_TIES))
    if unknown_operations:
        raise InputError(f"tied_costs: {unknown_operations} are not tied to the sphere test; "
                         f"use {sorted(SPHERE_TEST_TIES)}")
    if not (np.isfinite(test_sphere) and test_sphere > 0):
        raise InputError(f"tied_costs: test_sphere must be > 0 cycles, got {test_sphere!r}")
    costs = {"test_sphere": float(test_sphere)}
    for operation, tie in SPHERE_TEST_TIES.items():
        costs[operation] = float(own[operation]) if operation in own else float(test_sphere) * tie.multiple
    return costs


def _study1997_priors() -> CostStructure:
    # the sphere test first: a FittedCost's first operation is its reference
    work = {"test_sphere": 1.0, **{operation: tie.multiple for operation, tie in SPHERE_TEST_TIES.items()}}
    # the sphere test's range, narrowed (if ever needed) so every tied cost with a prior stays inside it
    low = max(prior_range(op)[0] / m for op, m in work.items() if op in PRIOR_UNKNOWNS)
    high = min(prior_range(op)[1] / m for op, m in work.items() if op in PRIOR_UNKNOWNS)
    return CostStructure(name="study1997-priors", fitted=(
        FittedCost("test", work, bounds=(low, high)),
        FittedCost("ray", {"ray": 1.0}, bounds=prior_range("ray")),
        FittedCost("node_visit", {"node_visit": 1.0}, bounds=prior_range("node_visit")),
    ), fixed={"test_root": SQUARE_ROOT_CYCLES_21164})


#: The structure fitted by default: the three costs of :data:`STUDY1997_COSTS`, each within its
#: prior, the triangle test and a light's cost tied inside theirs (see module docstring).
STUDY1997_PRIOR_COSTS = _study1997_priors()

#: The fits ``coherence paper --fit`` offers, by name; the first is the default.
FITS = {"priors": STUDY1997_PRIOR_COSTS, "study-bounds": STUDY1997_COSTS}


def _operation_totals(measurements: pd.DataFrame) -> dict:
    """Per operation, its count in every run (counters summed), float64 (R,)."""
    totals = {}
    for operation, counters in OPERATIONS.items():
        present = [c for c in counters if c in measurements]
        totals[operation] = (measurements[present].to_numpy(dtype=np.float64).sum(axis=1) if present
                             else np.zeros(len(measurements)))
    return totals


def fit_costs(measurements: pd.DataFrame, structure: CostStructure = STUDY1997_COSTS, *,
              clock_hz: float = CLOCK_HZ, name: str = "calibrated") -> tuple[CostModel, pd.DataFrame]:
    """Fit ``structure``'s costs to measured times, by bounded least squares of relative errors.

    Parameters
    ----------
    measurements : DataFrame
        One row per measured run: ``seconds``, optional ``memory_cycles``
        (simulated, taken off first) and the operation counters
        (``primary_rays``, ``node_visits``, ``tests_sphere``, ...; missing
        ones count 0).
    structure : CostStructure
    clock_hz : float
        Clock rate of the measured machine.

    Returns
    -------
    model : CostModel
    residuals : DataFrame
        Per run (the index of ``measurements``): ``measured_seconds``,
        ``fitted_seconds``, ``unexplained_seconds`` (measured minus fitted:
        the time the model, with every cost inside its bounds, does not
        explain), ``relative_error`` (fitted minus measured, over measured),
        ``memory_share`` (simulated memory cycles over fitted cycles).
    """
    from scipy.optimize import lsq_linear

    seconds, memory, matrix, fixed_cycles = _system(measurements, structure, clock_hz)
    target = seconds * clock_hz - memory - fixed_cycles
    weight = 1.0 / (seconds * clock_hz)
    low, high = np.array([c.bounds for c in structure.fitted]).T
    scale = np.where(matrix.max(axis=0) > 0, matrix.max(axis=0), 1.0)
    solution = lsq_linear((matrix / scale) * weight[:, None], target * weight,
                          bounds=(low * scale, high * scale), method="bvls").x / scale
    model = structure.model(solution, clock_hz=clock_hz, name=name)
    return model, _residuals(measurements.index, seconds, memory, fixed_cycles, matrix @ solution, clock_hz)


def _system(measurements: pd.DataFrame, structure: CostStructure, clock_hz: float):
    if "seconds" not in measurements:
        raise InputError("fit_costs: measurements need a 'seconds' column")
    seconds = measurements["seconds"].to_numpy(dtype=np.float64)
    if np.any(~np.isfinite(seconds)) or np.any(seconds <= 0):
        raise InputError("fit_costs: 'seconds' must be finite and > 0")
    if not (np.isfinite(clock_hz) and clock_hz > 0):
        raise InputError(f"fit_costs: clock_hz must be > 0, got {clock_hz!r}")
    memory = (measurements["memory_cycles"].to_numpy(dtype=np.float64) if "memory_cycles" in measurements
              else np.zeros(len(measurements)))
    totals = _operation_totals(measurements)
    matrix = np.column_stack([sum(multiple * totals[op] for op, multiple in cost.multiples.items())
                              for cost in structure.fitted])
    fixed_cycles = sum((cycles * totals[op] for op, cycles in structure.fixed.items()),
                       np.zeros(len(measurements)))
    return seconds, memory, matrix, fixed_cycles


def _residuals(index, seconds, memory, fixed_cycles, fitted_cycles, clock_hz) -> pd.DataFrame:
    total = memory + fixed_cycles + fitted_cycles
    fitted = total / clock_hz
    return pd.DataFrame({
        "measured_seconds": seconds,
        "fitted_seconds": fitted,
        "unexplained_seconds": seconds - fitted,
        "relative_error": (fitted - seconds) / seconds,
        "memory_share": np.divide(memory, total, out=np.zeros_like(total), where=total > 0),
    }, index=index)


def leave_one_out(measurements: pd.DataFrame, structure: CostStructure = STUDY1997_COSTS, *,
                  clock_hz: float = CLOCK_HZ) -> pd.DataFrame:
    """Fit on every run but one and predict the one left out, for each run.

    Returns
    -------
    DataFrame
        Per run (the index of ``measurements``): ``measured_seconds``,
        ``predicted_seconds``, ``relative_error``, and the fitted cost values
        of that fold (one column per :class:`FittedCost`, cycles of its
        reference operation).
    """
    if len(measurements) < 2:
        raise InputError("leave_one_out: needs at least two runs")
    rows = []
    for left_out in range(len(measurements)):
        keep = np.arange(len(measurements)) != left_out
        model, _ = fit_costs(measurements.iloc[keep], structure, clock_hz=clock_hz)
        seconds, memory, matrix, fixed_cycles = _system(measurements.iloc[[left_out]], structure, clock_hz)
        values = fitted_values(model, structure)
        predicted = float((memory + fixed_cycles + matrix @ np.array(list(values.values())))[0] / clock_hz)
        rows.append({"measured_seconds": float(seconds[0]), "predicted_seconds": predicted,
                     "relative_error": (predicted - seconds[0]) / seconds[0],
                     **values})
    return pd.DataFrame(rows, index=measurements.index)


def rms(errors) -> float:
    """Root mean square of relative errors."""
    errors = np.asarray(errors, dtype=np.float64)
    return float(np.sqrt(np.mean(errors ** 2)))


def at_bounds(values: dict, structure: CostStructure) -> dict:
    """Per fitted cost, whether its value (:func:`fitted_values`) sits at its lower or upper bound."""
    out = {}
    for cost in structure.fitted:
        low, high = cost.bounds
        value = values[cost.name]
        out[cost.name] = bool(np.isclose(value, low, rtol=1e-6, atol=0.0) or np.isclose(value, high, rtol=1e-6, atol=0.0))
    return out


def fitted_values(model: CostModel, structure: CostStructure) -> dict:
    """Cycles of each fitted cost's reference operation in ``model``."""
    out = {}
    for cost in structure.fitted:
        operation, multiple = next(iter(cost.multiples.items()))
        out[cost.name] = getattr(model, operation) / multiple
    return out
