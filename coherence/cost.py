"""Cycles per operation: from a pixel's counters and cache outcomes to time.

A pixel's time in CPU cycles is its *compute* cycles, a weighted sum of its
operation counters (rays, kd-node visits, index reads, intersection tests by
primitive type, shading operations), plus its *memory* cycles: every access
costs the hit latency of the cache level that served it, or the memory
latency. Latencies belong to the :class:`cachesim.Hierarchy`, so a what-if on
latency changes one place.

``CostModel.calibrate`` fits the per-operation cycles by non-negative least
squares to measured times, as the study's sequential times
(:data:`tracer.scenes.study.STUDY_SCENES`) can be fitted with traces of the five scenes.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from rtcommon.resident import drop_pages, mapping_of
from rtcommon.validate import InputError, require_number

#: rows of counters :meth:`CostModel.compute_cycles` converts at a time (6.5 MB of float64 for 25 counters)
COMPUTE_ROWS = 1 << 15

#: Clock rate of the study's machine: the AlphaServer 8400's 21164 CPUs ran at 300 MHz.
CLOCK_HZ = 300e6

#: The cost model every run uses unless told otherwise: the study's machine (:func:`alpha8400`).
DEFAULT_COST_MODEL = "alpha8400"

# Cost fields and the trace counters each one multiplies.
OPERATIONS = {
    "ray": ("primary_rays", "shadow_rays", "reflection_rays", "refraction_rays"),
    "node_visit": ("node_visits",),
    "index_read": ("index_reads",),
    "test_sphere": ("tests_sphere",),
    "test_triangle": ("tests_triangle",),
    "test_polygon": ("tests_polygon",),
    "test_patch": ("tests_patch",),
    "test_cone": ("tests_cone",),
    "shading": ("shading",),
    "light_read": ("light_reads",),
    "test_root": ("root_tests",),
}

#: Cycles of one double-precision square root on the Alpha 21164, charged on
#: top of a test that takes one (``test_root``). The 21164 has no
#: square-root instruction (SQRTT came with the 21264's FIX extension), so
#: a root is a library call. The GNU C library's Alpha routine written for
#: EV4/EV5 (a table-seeded Newton-Raphson iteration) runs a chain of 18
#: dependent floating-point operations of the 21164's 4-cycle result latency
#: (72 cycles) after a table load and two moves between the register files
#: through memory (the 21164 has no direct move): about 90 cycles with the
#: call. A fact of the machine, fixed in advance, never fitted.
SQUARE_ROOT_CYCLES_21164 = 90.0


#: Cycles per key and per pass of the radix sort a ray order sorts rays with
#: (:func:`ray_sort_cycles`). A least-significant-digit radix sort of 8-bit
#: digits makes, per key and pass, one histogram increment (a load, an add, a
#: store: about 2 cycles pipelined) and one scatter of the key and its ray id
#: (a histogram load and increment, two stores: about 4 cycles). Fixed by
#: that count, never fitted.
RADIX_SORT_CYCLES_PER_PASS = 6.0
#: Bits of a radix sort's digit: one pass per 8 bits of the key.
RADIX_SORT_DIGIT_BITS = 8


def ray_sort_cycles(n_rays: int, key_bits: int) -> float:
    """Cycles to sort ``n_rays`` rays by keys of ``key_bits`` significant bits.

    ``ceil(key_bits / RADIX_SORT_DIGIT_BITS)`` passes of
    :data:`RADIX_SORT_CYCLES_PER_PASS` cycles per ray; nothing for fewer than two rays.
    """
    if n_rays < 2 or key_bits <= 0:
        return 0.0
    passes = -(-int(key_bits) // RADIX_SORT_DIGIT_BITS)
    return float(n_rays) * passes * RADIX_SORT_CYCLES_PER_PASS


@dataclass(frozen=True)
class CostModel:
    """Cycles per operation and the clock rate.

    Parameters
    ----------
    ray : float
        Cycles to set up and finish one ray of any type.
    node_visit, index_read : float
        Cycles per kd-node visit and per leaf primitive-index read.
    test_sphere, test_triangle, test_polygon, test_patch, test_cone : float
        Cycles per intersection test of each primitive type.
    shading : float
        Cycles per shading operation (one hit shaded; in the stock presets
        with all its lights).
    light_read : float
        Cycles per light of a shaded hit, on top of ``shading`` (0 in the
        stock presets, which count lights in ``shading``; fitted models tie
        it to the other costs, see :mod:`coherence.calibration`).
    test_root : float
        Cycles added to an intersection test that takes a square root (a
        sphere or cone with real roots): what a machine without a
        square-root instruction pays on that path
        (:data:`SQUARE_ROOT_CYCLES_21164`; 0 by default and in ``modern``,
        whose test costs are averages over both paths).
    clock_hz : float
        CPU clock rate, to turn cycles into seconds.
    name : str
    """

    ray: float = 400.0
    node_visit: float = 60.0
    index_read: float = 10.0
    test_sphere: float = 300.0
    test_triangle: float = 350.0
    test_polygon: float = 450.0
    test_patch: float = 500.0
    test_cone: float = 500.0
    shading: float = 1500.0
    light_read: float = 0.0
    test_root: float = 0.0
    clock_hz: float = CLOCK_HZ
    name: str = "custom"

    def __post_init__(self):
        for name in (*OPERATIONS, "clock_hz"):
            require_number(f"CostModel.{name}", getattr(self, name), 0)
        if self.clock_hz <= 0:
            raise InputError(f"CostModel.clock_hz must be > 0, got {self.clock_hz}")

    def weights(self, counter_names) -> np.ndarray:
        """Cycles per unit of each counter, float64 (K,), in ``counter_names`` order."""
        weights = np.zeros(len(counter_names), dtype=np.float64)
        column = {name: index for index, name in enumerate(counter_names)}
        for operation, counters in OPERATIONS.items():
            for counter in counters:
                if counter in column:
                    weights[column[counter]] = getattr(self, operation)
        return weights

    def compute_cycles(self, counters, counter_names) -> np.ndarray:
        """Compute cycles per row of ``counters`` (int, (P, K)) -> float64 (P,).

        Rows are converted in chunks of :data:`COMPUTE_ROWS`: a trace's
        memory-mapped counters (0.8 GB at 2048²) are never copied whole, and
        their pages leave the resident set as they are read.
        """
        counters = np.asarray(counters)
        weights = self.weights(counter_names)
        cycles = np.empty(counters.shape[0])
        mapped = mapping_of(counters)
        for start in range(0, counters.shape[0], COMPUTE_ROWS):
            if mapped is not None:
                drop_pages(mapped)
            rows = slice(start, start + COMPUTE_ROWS)
            cycles[rows] = np.asarray(counters[rows], dtype=np.float64) @ weights
        return cycles

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def calibrate(cls, measurements: pd.DataFrame, *, clock_hz: float = CLOCK_HZ, name: str = "calibrated",
                  fixed: dict | None = None):
        """Fit cycles per operation to measured times by non-negative least squares.

        Parameters
        ----------
        measurements : DataFrame
            One row per measured run: ``seconds`` (measured time), optional
            ``memory_cycles`` (simulated memory cycles, subtracted first) and
            one column per operation counter (``primary_rays``,
            ``node_visits``, ``tests_sphere``, ...; missing ones count 0).
        clock_hz : float
            Clock rate of the measured machine.
        fixed : dict of str to float, optional
            Operations held at a given cost instead of fitted (useful when
            fewer runs than operations are measured).

        Returns
        -------
        model : CostModel
        residuals : DataFrame
            Per run: measured and fitted seconds, residual and relative error.
        """
        if "seconds" not in measurements:
            raise InputError("calibrate: measurements need a 'seconds' column")
        fixed = dict(fixed or {})
        unknown = sorted(set(fixed) - set(OPERATIONS))
        if unknown:
            raise InputError(f"calibrate: unknown operations in fixed: {unknown}; use {sorted(OPERATIONS)}")
        seconds = measurements["seconds"].to_numpy(dtype=np.float64)
        if np.any(~np.isfinite(seconds)) or np.any(seconds <= 0):
            raise InputError("calibrate: 'seconds' must be finite and > 0")
        target = seconds * clock_hz
        if "memory_cycles" in measurements:
            target = target - measurements["memory_cycles"].to_numpy(dtype=np.float64)
        columns = {}
        for operation, counters in OPERATIONS.items():
            present = [counter for counter in counters if counter in measurements]
            total = measurements[present].to_numpy(dtype=np.float64).sum(axis=1) if present \
                else np.zeros(len(measurements))
            if operation in fixed:
                target = target - fixed[operation] * total
            elif total.any():
                columns[operation] = total
        if not columns:
            raise InputError("calibrate: no operation counters to fit (all missing, zero or fixed)")
        from scipy.optimize import nnls

        matrix = np.column_stack(list(columns.values()))
        scale = matrix.max(axis=0)
        solution, _ = nnls(matrix / scale, target)
        fitted = dict(zip(columns, solution / scale))
        model = replace(cls(clock_hz=clock_hz, name=name), **fixed, **fitted)
        predicted = (matrix @ (solution / scale) + (seconds * clock_hz - target)) / clock_hz
        residuals = pd.DataFrame({
            "measured_seconds": seconds,
            "fitted_seconds": predicted,
            "residual_seconds": predicted - seconds,
            "relative_error": (predicted - seconds) / seconds,
        }, index=measurements.index)
        return model, residuals


def alpha8400() -> CostModel:
    """The study's AlphaServer 8400 at 300 MHz.

    Cycle counts are first guesses scaled to the study's slow tracer (about
    500 cycles per intersection test all told); refit them with
    :meth:`CostModel.calibrate` against the study's sequential times
    (:data:`tracer.scenes.study.STUDY_SCENES`).
    A test that takes a square root pays the 21164's software root on top
    (:data:`SQUARE_ROOT_CYCLES_21164`).
    """
    return CostModel(test_root=SQUARE_ROOT_CYCLES_21164, name="alpha8400")


def modern() -> CostModel:
    """A current 3 GHz core running a tuned tracer (tens of cycles per test)."""
    return CostModel(ray=80.0, node_visit=8.0, index_read=2.0, test_sphere=25.0, test_triangle=30.0,
                     test_polygon=45.0, test_patch=55.0, test_cone=50.0, shading=200.0, clock_hz=3e9,
                     name="modern")


#: Cycles per operation of this project's own tracer, measured once on one machine by
#: ``benchmarks/bench_platform_costs.py`` (the paper scenes at 256x256, both tree builders, depth 1 and
#: the scene's, CPU time of one core at the 2.6 GHz clock of the machine; docs/platforms.md gives the
#: machine, the renders and the fit). A zero is an operation the fit could not separate from others
#: (its cost is inside theirs); patches and cones, in no paper scene, cost a polygon test.
MEASURED_CYCLES = {"ray": 317.34, "node_visit": 13.85, "index_read": 0.0, "test_sphere": 9.2,
                   "test_triangle": 0.0, "test_polygon": 30.01, "test_patch": 30.01, "test_cone": 30.01,
                   "shading": 0.0, "light_read": 0.0, "test_root": 5.11}


def measured(name: str, clock_hz: float) -> CostModel:
    """:data:`MEASURED_CYCLES` at ``clock_hz``: the same cycles per operation on another core's clock."""
    return CostModel(**MEASURED_CYCLES, clock_hz=clock_hz, name=name)


def zen4_7950x() -> CostModel:
    """The measured cycles on an AMD Ryzen 9 7950X's 5.7 GHz clock (:mod:`coherence.platforms`)."""
    return measured("zen4-7950x", 5.7e9)


def xeon_8480() -> CostModel:
    """The measured cycles on an Intel Xeon Platinum 8480's 3.8 GHz clock (:mod:`coherence.platforms`)."""
    return measured("xeon-8480", 3.8e9)


def apple_m1() -> CostModel:
    """The measured cycles on an Apple M1 performance core's 3.2 GHz clock (:mod:`coherence.platforms`)."""
    return measured("apple-m1", 3.2e9)


COST_MODELS = {"alpha8400": alpha8400, "modern": modern, "zen4-7950x": zen4_7950x, "xeon-8480": xeon_8480,
               "apple-m1": apple_m1}


def get_cost_model(name_or_model) -> CostModel:
    """A preset by name (:data:`COST_MODELS`) or a CostModel."""
    if isinstance(name_or_model, CostModel):
        return name_or_model
    try:
        return COST_MODELS[str(name_or_model)]()
    except KeyError:
        raise InputError(f"unknown cost model {name_or_model!r}: use one of {', '.join(COST_MODELS)}") from None

