"""The factors of the robustness study: unknowns as unit coordinates, and one sample as the simulation's objects.

Every factor is an entry of :data:`coherence.unknowns.UNKNOWNS` whose
mechanism the toolkit has. The samplers of SALib draw points of the unit
hypercube; :func:`factor_value` turns a coordinate ``u`` in [0, 1] into the
unknown's value by its documented distribution:

- ``uniform``: ``low + u (high - low)``;
- ``log-uniform``: ``low (high / low) ** u``;
- ``integer``: ``low + floor(u (high - low + 1))``, ``u = 1`` giving ``high``;
- ``categorical``: ``choices[floor(u k)]`` of ``k`` choices, ``u = 1`` giving
  the last.

:func:`sample_setup` makes one sample's :class:`~analyses.experiment.Experiment`
(scene and image size from the base, the rest replaced with
:func:`dataclasses.replace`), its machine (time slice, seeds), cache hierarchy
(latencies, data TLB) and cost model. Every mapping of a sample is simulated
with these objects, so the mappings share every sampled value, the seeds of
the page placement and of the other users' streams included.

The cost model of a sample: the sampled sphere test, triangle test, light
read, ray, node visit and square root, every other operation (polygon, patch
and cone tests, shading, index reads) following the sphere test by the one
rule the prior fit uses too (:data:`coherence.calibration.SPHERE_TEST_TIES`,
the routines' floating-point operation counts).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from coherence.unknowns import UNKNOWNS
from rtcommon.validate import InputError

__all__ = ["LEFT_OUT", "FACTORS", "SampleSetup", "factor_value", "factor_values", "sample_setup",
           "morris_design", "morris_indices", "sobol_design", "sobol_indices"]

#: Unknowns of :data:`coherence.unknowns.UNKNOWNS` the study does not vary,
#: with the reason (each is kept at the base experiment's value); none now.
LEFT_OUT = {}

#: The unknowns the study varies, in the order of :data:`coherence.unknowns.UNKNOWNS`.
FACTORS = tuple(entry for entry in UNKNOWNS if entry.name not in LEFT_OUT)

#: Morris grid levels (even, as Morris's design needs): the six levels 0,
#: 0.2, ..., 1 reach every choice of a categorical factor of up to five
#: choices (the tree variants) and both ends of every range.
MORRIS_LEVELS = 6


def factor_value(entry, u: float):
    """The value of unknown ``entry`` at unit coordinate ``u`` (see the module's docstring).

    Raises
    ------
    ValueError
        If ``u`` is not a number in [0, 1].
    """
    u = float(u)
    if not 0.0 <= u <= 1.0:
        raise InputError(f"unit coordinate of {entry.name} must lie in [0, 1], got {u!r}")
    if entry.distribution == "categorical":
        count = len(entry.choices)
        return entry.choices[min(int(math.floor(u * count)), count - 1)]
    if entry.distribution == "integer":
        low, high = int(entry.low), int(entry.high)
        return min(low + int(math.floor(u * (high - low + 1))), high)
    if entry.distribution == "log-uniform":
        return float(entry.low * (entry.high / entry.low) ** u)
    return float(entry.low + u * (entry.high - entry.low))


def factor_values(unit_row, factors=FACTORS) -> dict:
    """Unknown name -> value of one sample, from its unit coordinates ``unit_row`` (len(factors),)."""
    unit_row = np.asarray(unit_row, dtype=np.float64)
    if unit_row.shape != (len(factors),):
        raise InputError(f"a sample needs {len(factors)} unit coordinates, got shape {unit_row.shape}")
    return {entry.name: factor_value(entry, u) for entry, u in zip(factors, unit_row)}


@dataclass(frozen=True)
class SampleSetup:
    """What one sample simulates.

    Attributes
    ----------
    experiment : analyses.experiment.Experiment
        Scene, size, workload, mappings, process counts, memory image,
        page placement and its seed, other users' count and footprint,
        hierarchy and cost model of the sample.
    machine : coherence.simulation.Machine
        ``experiment.machine()`` with the sampled time slice and the
        sample's seed for the other users' streams.
    values : dict
        Unknown name -> sampled value.
    """

    experiment: object
    machine: object
    values: dict


def sample_setup(base, values: dict, seed: int) -> SampleSetup:
    """One sample's objects: ``base`` (an Experiment) with the sampled ``values`` and ``seed``.

    Parameters
    ----------
    base : analyses.experiment.Experiment
    values : dict
        Unknown name -> value, every name of :data:`FACTORS`
        (:func:`factor_values`).
    seed : int
        Seed of the page placement and of the other users' streams, >= 0.
    """
    missing = sorted({entry.name for entry in FACTORS} - set(values))
    if missing:
        raise InputError(f"sample_setup: no value for {', '.join(missing)}")
    experiment = replace(base, hierarchy=_hierarchy(values), cost=_cost(values), layout=values["memory_image"],
                         tree_variant=values["tree_variant"],
                         page_placement=values["page_placement"], page_seed=int(seed),
                         background=int(values["background_load"]),
                         background_footprint=int(round(values["background_footprint"])))
    machine = replace(experiment.machine(), quantum_cycles=float(values["quantum_cycles"]),
                      background_seed=int(seed))
    return SampleSetup(experiment, machine, dict(values))


def _hierarchy(values: dict):
    from cachesim.config import alpha21164, alpha21164_with_dtb

    hierarchy = alpha21164_with_dtb() if values["data_tlb"] == "on" else alpha21164()
    levels = list(hierarchy.levels)
    levels[2] = replace(levels[2], latency=float(values["bcache_latency"]))
    tlb = None if hierarchy.tlb is None else replace(hierarchy.tlb, miss_cycles=float(values["dtb_miss_cycles"]))
    return replace(hierarchy, levels=tuple(levels), memory_latency=float(values["memory_latency"]), tlb=tlb,
                   name=f"{hierarchy.name}-sampled")


def _cost(values: dict):
    from coherence.calibration import tied_costs
    from coherence.cost import CLOCK_HZ, CostModel

    costs = tied_costs(float(values["cost_test_sphere"]),
                       own={"test_triangle": float(values["cost_test_triangle"]),
                            "light_read": float(values["cost_light_read"])})
    return CostModel(ray=float(values["cost_ray"]), node_visit=float(values["cost_node_visit"]),
                     test_root=float(values["square_root_cycles"]), clock_hz=CLOCK_HZ, name="sampled", **costs)


# --------------------------------------------------------------------------
# the designs and indices of SALib, over the unit hypercube


def _problem(names) -> dict:
    names = list(names)
    return {"num_vars": len(names), "names": names, "bounds": [[0.0, 1.0]] * len(names)}


def morris_design(names, trajectories: int, seed: int) -> np.ndarray:
    """Morris trajectories over the unit hypercube: float64 (trajectories * (k + 1), k) for k ``names``."""
    from SALib.sample import morris

    return np.asarray(morris.sample(_problem(names), int(trajectories), num_levels=MORRIS_LEVELS,
                                    seed=int(seed)), dtype=np.float64)


def morris_indices(names, design: np.ndarray, outputs: np.ndarray, seed: int) -> dict:
    """Morris ``mu_star``, ``mu``, ``sigma`` per name (dict of name -> float) from ``outputs`` (n,)."""
    from SALib.analyze import morris

    result = morris.analyze(_problem(names), np.asarray(design), np.asarray(outputs, dtype=np.float64),
                            num_levels=MORRIS_LEVELS, num_resamples=100, seed=int(seed))
    return {key: dict(zip(result["names"], (float(v) for v in result[key]))) for key in ("mu_star", "mu", "sigma")}


def sobol_design(names, base_samples: int, seed: int) -> np.ndarray:
    """Saltelli's design for first-order and total indices: float64 (N (k + 2), k), N a power of two."""
    from SALib.sample import sobol

    return np.asarray(sobol.sample(_problem(names), int(base_samples), calc_second_order=False, seed=int(seed)),
                      dtype=np.float64)


def sobol_indices(names, outputs: np.ndarray, seed: int) -> dict:
    """First-order ``S1`` and total ``ST`` indices per name (dict of name -> float)."""
    from SALib.analyze import sobol

    result = sobol.analyze(_problem(names), np.asarray(outputs, dtype=np.float64), calc_second_order=False,
                           seed=int(seed))
    return {key: dict(zip(list(names), (float(v) for v in result[key]))) for key in ("S1", "ST")}
