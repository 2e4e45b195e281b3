"""The study's unknowns: what the model cannot know about the 1997 machine, each with a plausible range.

Every entry of :data:`UNKNOWNS` names one quantity that a sensitivity study
of the study-era re-creation samples, the option of the toolkit that
carries it, its value today, the range (or set of choices) it is sampled
from and the distribution to sample with. Each range was decided from a
source of the time, or from stated reasoning where no source was found,
before any result of a sensitivity study was looked at. The sources and
the reasoning are in ``docs/unknowns.md``, whose first table holds the same
rows (``tests/test_unknowns.py`` checks the two agree row by row).

Defaults are read from the code, not copied: when a default of the model
moves outside its documented range, the test of this module fails.
A default of ``None`` marks a cost that is fitted to the study's
sequential times (by default within the range given here,
:data:`coherence.calibration.STUDY1997_PRIOR_COSTS`), so it has no value
before a fit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from cachesim.config import alpha21164
from cachesim.tlb_config import DTB_MISS_CYCLES
from coherence.cost import SQUARE_ROOT_CYCLES_21164
from coherence.layout import DEFAULT_LAYOUT
from coherence.simulation import Machine
from tracer.rendering.tree_variants import PLAUSIBLE_TREE_VARIANTS, STUDY_TREE_VARIANT, tree_rule_name
from tracer.rendering.workload import WORKLOADS
from rtcommon.validate import InputError

__all__ = ["DISTRIBUTIONS", "SOURCES", "STUDY_TREE_RULE", "TREE_VARIANTS", "UNKNOWNS", "Unknown", "unknown"]

#: How a range is sampled: ``uniform`` and ``log-uniform`` over ``[low, high]``
#: (log-uniform: uniform in the logarithm, for a quantity known to a factor),
#: ``integer`` uniform over the integers ``low .. high``, ``categorical``
#: uniform over ``choices``.
DISTRIBUTIONS = ("uniform", "log-uniform", "integer", "categorical")

#: Source keys of :attr:`Unknown.source`; the full citations are in
#: ``docs/unknowns.md`` under "Sources", one heading per key.
SOURCES = (
    "alphaserver8400-manual", "alphaserver4100-memory", "alpha21164pc-manual", "digital-unix-vm", "kessler-hill-1992",
    "memory-image-docs", "shared-machine", "unix-quanta", "osfpal-dtbmiss", "alpha-sqrt",
    "instruction-counts", "tree-search",
)

#: The study-era tree rule by its name in ``docs/study_tree_search.csv``.
STUDY_TREE_RULE = STUDY_TREE_VARIANT

#: The tree rules a study samples: the plausible variants of
#: :mod:`tracer.rendering.tree_variants` (tests within 25% of the study's on
#: every SPD scene at 128 x 128), the study's rule first.
TREE_VARIANTS = PLAUSIBLE_TREE_VARIANTS


@dataclass(frozen=True)
class Unknown:
    """One unknown of the study and the range it is sampled from.

    Parameters
    ----------
    name : str
        Identifier (``"memory_latency"``).
    option : str
        Where the toolkit carries it: a field, preset or command-line option.
    default : float, str or None
        Today's value, read from the code; ``None`` for a cost that is
        fitted and has no value before a fit.
    distribution : {"uniform", "log-uniform", "integer", "categorical"}
        How the range is sampled (:data:`DISTRIBUTIONS`).
    low, high : float, optional
        Bounds of a numeric range, ``low < high``; both ``None`` for a
        categorical unknown.
    choices : tuple of str
        The values of a categorical unknown; empty otherwise.
    source : str
        Key of the source behind the range (:data:`SOURCES`).
    unit : str
        Unit of ``default``, ``low`` and ``high`` (``""`` for categorical).
    """

    name: str
    option: str
    default: object
    distribution: str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    source: str = ""
    unit: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise InputError(f"Unknown.name must be an identifier, got {self.name!r}")
        if self.distribution not in DISTRIBUTIONS:
            raise InputError(f"Unknown.distribution of {self.name} must be one of {', '.join(DISTRIBUTIONS)}, "
                             f"got {self.distribution!r}")
        if self.source not in SOURCES:
            raise InputError(f"Unknown.source of {self.name} must be one of {', '.join(SOURCES)}, "
                             f"got {self.source!r}")
        object.__setattr__(self, "choices", tuple(self.choices))
        if self.distribution == "categorical":
            if len(self.choices) < 2 or self.low is not None or self.high is not None:
                raise InputError(f"Unknown.choices of {self.name} must hold at least 2 values, "
                                 "and low and high must be None, for a categorical unknown")
            return
        if self.choices:
            raise InputError(f"Unknown.choices of {self.name} must be empty for a {self.distribution} unknown")
        for bound in ("low", "high"):
            value = getattr(self, bound)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InputError(f"Unknown.{bound} of {self.name} must be a finite number, got {value!r}")
        if not self.low < self.high:
            raise InputError(f"Unknown.low of {self.name} must be < high, got {self.low!r} and {self.high!r}")
        if self.distribution == "log-uniform" and self.low <= 0:
            raise InputError(f"Unknown.low of {self.name} must be > 0 for a log-uniform range, got {self.low!r}")
        if self.distribution == "integer" and (self.low != int(self.low) or self.high != int(self.high)):
            raise InputError(f"Unknown.low and high of {self.name} must be whole numbers for an integer range")

    def contains(self, value) -> bool:
        """Whether ``value`` lies in the range (or is one of the choices)."""
        if self.distribution == "categorical":
            return value in self.choices
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if self.distribution == "integer" and value != int(value):
            return False
        return self.low <= value <= self.high


def _study_tree_rule_name() -> str:
    """The study-era tree rule and shadow rule, spelled as in the tree search's table."""
    study = WORKLOADS["study1997"]
    return tree_rule_name(study.kd_config, study.shadow_nearest)


def _unknowns() -> tuple:
    hierarchy = alpha21164()
    machine = Machine()
    return (
        Unknown("memory_latency", "alpha21164().memory_latency", float(hierarchy.memory_latency),
                "log-uniform", 51.0, 150.0, source="alphaserver8400-manual", unit="cycles"),
        Unknown("bcache_latency", "alpha21164().levels[2].latency", float(hierarchy.levels[2].latency),
                "uniform", 10.0, 20.0, source="alpha21164pc-manual", unit="cycles"),
        Unknown("page_placement", "Machine.page_placement, --page-placement", machine.page_placement.policy,
                "categorical", choices=("contiguous", "colouring", "bin-hopping", "random"),
                source="digital-unix-vm"),
        Unknown("memory_image", "--layout", DEFAULT_LAYOUT, "categorical",
                choices=("compact", "alpha1997", "malloc1997"), source="memory-image-docs"),
        Unknown("background_load", "Machine.background_load, --background", float(machine.background_load),
                "integer", 0.0, 8.0, source="shared-machine", unit="processes"),
        Unknown("background_footprint", "Machine.background_footprint, --background-footprint",
                float(machine.background_footprint), "log-uniform", 98304.0, 4194304.0,
                source="shared-machine", unit="bytes"),
        Unknown("quantum_cycles", "Machine.quantum_cycles, --quantum", float(machine.quantum_cycles),
                "log-uniform", 3e6, 6e7, source="unix-quanta", unit="cycles"),
        Unknown("data_tlb", "Hierarchy.tlb, --hierarchy alpha21164-dtb", "off" if hierarchy.tlb is None else "on",
                "categorical", choices=("off", "on"), source="alpha21164pc-manual"),
        Unknown("dtb_miss_cycles", "Tlb.miss_cycles", float(DTB_MISS_CYCLES), "log-uniform", 21.0, 170.0,
                source="osfpal-dtbmiss", unit="cycles"),
        Unknown("square_root_cycles", "CostModel.test_root", float(SQUARE_ROOT_CYCLES_21164), "log-uniform",
                72.0, 360.0, source="alpha-sqrt", unit="cycles"),
        Unknown("cost_node_visit", "CostModel.node_visit", None, "log-uniform", 15.0, 60.0,
                source="instruction-counts", unit="cycles"),
        Unknown("cost_test_sphere", "CostModel.test_sphere", None, "log-uniform", 30.0, 120.0,
                source="instruction-counts", unit="cycles"),
        Unknown("cost_test_triangle", "CostModel.test_triangle", None, "log-uniform", 50.0, 200.0,
                source="instruction-counts", unit="cycles"),
        Unknown("cost_light_read", "CostModel.light_read", None, "log-uniform", 120.0, 480.0,
                source="instruction-counts", unit="cycles"),
        Unknown("cost_ray", "CostModel.ray", None, "log-uniform", 75.0, 300.0,
                source="instruction-counts", unit="cycles"),
        Unknown("tree_variant", "Experiment.tree_variant, --tree-variant", _study_tree_rule_name(), "categorical",
                choices=TREE_VARIANTS, source="tree-search"),
    )


#: Every unknown of the sensitivity study, in the order of the table in ``docs/unknowns.md``.
UNKNOWNS = _unknowns()


def unknown(name: str) -> Unknown:
    """The entry of :data:`UNKNOWNS` called ``name``."""
    for entry in UNKNOWNS:
        if entry.name == name:
            return entry
    raise InputError(f"no unknown called {name!r}; known: {', '.join(u.name for u in UNKNOWNS)}")
