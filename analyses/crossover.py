"""When would coherence have won? The boundary where a fine mapping's coherence loss meets S's imbalance.

The study found that load balance, not cache coherence, decided the speed-up.
This study asks how far the machine or the scene would have to move before
that flips. For one scene at ``n_processes`` (the study's 8), it scales

- the bytes of every scene record by an integer factor ``k``
  (:meth:`coherence.layout.MemoryLayout.scaled`: a fatter node, a richer
  object), and
- the memory latency by a factor ``m`` (the hierarchy's ``memory_latency``),

and for every ``(k, m)`` simulates S (coarse strips: coherent but badly
balanced) and the fine mappings P and R (balanced but incoherent), with the
same calibrated cost model. Where P's or R's coherence loss exceeds S's
imbalance loss, a fine mapping loses more to coherence than the coarse one
loses to balance: coherence would have mattered more.

:func:`crossover_boundary` finds, for each ``k``, the smallest ``m`` where
that happens, interpolating the loss difference linearly in ``log m``
between grid points; :func:`plot_crossover` draws the boundary.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from analyses.verdict import VERDICT_PROCESSES
from cachesim.config import DEFAULT_HIERARCHY
from coherence.layout import DEFAULT_LAYOUT
from rtcommon.validate import InputError, require_int

#: Default grid: record bytes x1 .. x64, memory latency x1 .. x64; the fine mappings held against S.
RECORD_SCALES = (1, 4, 16, 64)
LATENCY_SCALES = (1, 4, 16, 64)
FINE_MAPPINGS = ("P", "R")


def _scales(name: str, values) -> list:
    values = [float(v) for v in values]
    if not values or any(not np.isfinite(v) or v < 1 for v in values) or values != sorted(set(values)):
        raise InputError(f"{name} must be increasing numbers >= 1, got {values}")
    return values


def crossover_study(trace, *, cost, hierarchy=DEFAULT_HIERARCHY, layout=DEFAULT_LAYOUT, scene=None,
                    n_processes: int = VERDICT_PROCESSES,
                    machine=None, record_scales=RECORD_SCALES, latency_scales=LATENCY_SCALES,
                    execution=None) -> pd.DataFrame:
    """Losses of S and the fine mappings (:data:`FINE_MAPPINGS`) at every (record scale, latency scale).

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
    cost : coherence.cost.CostModel or str
        The cost model (``coherence paper`` passes its calibrated one).
    hierarchy, layout : preset name or object
        The machine and memory image at scale (1, 1).
    scene : tracer.scenes.model.Scene, optional
        For exact polygon sizes in the layout.
    n_processes : int
    machine : coherence.simulation.Machine, optional
    record_scales : sequence of int
        Factors ``k`` on every record's bytes, increasing, >= 1.
    latency_scales : sequence of float
        Factors ``m`` on the memory latency, increasing, >= 1.
    execution : coherence.studies.Execution, optional
        Where the runs are simulated (see :func:`coherence.studies.study`).

    Returns
    -------
    DataFrame
        One row per (record_scale, latency_scale, mapping): ``record_scale``,
        ``latency_scale``, ``memory_latency``, ``mapping``, ``n_processes``,
        ``speedup_user``, ``imbalance_loss``, ``coherence_loss``.
    """
    from cachesim import get_hierarchy
    from coherence.layout import get_layout
    from coherence.studies import study

    n_processes = require_int("n_processes", n_processes, 2)
    record_scales = [int(k) for k in _scales("record_scales", record_scales)]
    latency_scales = _scales("latency_scales", latency_scales)
    hierarchy = get_hierarchy(hierarchy)
    layout = get_layout(layout)
    mappings = ["S", *FINE_MAPPINGS]
    frames = []
    for k in record_scales:
        scaled = layout.scaled(k)
        for m in latency_scales:
            slower = replace(hierarchy, memory_latency=hierarchy.memory_latency * m)
            result = study(trace, mappings, [n_processes], hierarchy=slower, layout=scaled, cost=cost,
                           machine=machine, scene=scene, progress=False, execution=execution)
            runs = result.runs[result.runs["n_processes"] == n_processes]
            frames.append(runs[["mapping", "n_processes", "speedup_user", "imbalance_loss", "coherence_loss"]]
                          .assign(record_scale=k, latency_scale=m, memory_latency=slower.memory_latency))
    table = pd.concat(frames, ignore_index=True)
    first = ["record_scale", "latency_scale", "memory_latency"]
    return table[first + [c for c in table.columns if c not in first]]


def crossover_boundary(table: pd.DataFrame) -> pd.DataFrame:
    """Per record scale and fine mapping, the latency scale where its coherence loss meets S's imbalance loss.

    Parameters
    ----------
    table : DataFrame
        :func:`crossover_study`'s rows (optionally with a ``scene`` column:
        one boundary per scene).

    Returns
    -------
    DataFrame
        ``[scene,] mapping, record_scale, latency_scale``: the smallest
        latency factor at which ``coherence_loss(mapping) >=
        imbalance_loss(S)``, interpolated linearly in ``log m`` between grid
        points; 1.0 or below means coherence already mattered more at that
        record scale; NaN means not within the grid. Also ``gap_at_1``:
        coherence loss minus S's imbalance loss at ``m = 1``.
    """
    groups = ["scene"] if "scene" in table else []
    rows = []
    for key, part in (table.groupby(groups, sort=False) if groups else [((), table)]):
        key = key if isinstance(key, tuple) else (key,)
        strips = part[part["mapping"] == "S"].set_index(["record_scale", "latency_scale"])["imbalance_loss"]
        for mapping in dict.fromkeys(part.loc[part["mapping"] != "S", "mapping"]):
            fine = part[part["mapping"] == mapping].set_index(["record_scale", "latency_scale"])["coherence_loss"]
            for k in dict.fromkeys(fine.index.get_level_values(0)):
                gap = (fine.loc[k] - strips.loc[k]).sort_index()
                rows.append({**dict(zip(groups, key)), "mapping": mapping, "record_scale": k,
                             "latency_scale": _first_crossing(gap.index.to_numpy(float), gap.to_numpy(float)),
                             "gap_at_1": float(gap.iloc[0])})
    return pd.DataFrame(rows)


def _first_crossing(scales: np.ndarray, gap: np.ndarray) -> float:
    if gap[0] >= 0:
        return float(scales[0])
    for i in range(1, len(gap)):
        if gap[i] >= 0:
            a, b = np.log(scales[i - 1]), np.log(scales[i])
            fraction = -gap[i - 1] / (gap[i] - gap[i - 1])
            return float(np.exp(a + fraction * (b - a)))
    return float("nan")


def plot_crossover(boundary: pd.DataFrame, ax=None):
    """Draw :func:`crossover_boundary`'s table: latency factor against record-size factor, one line per scene and mapping.

    Above a line, that fine mapping loses more to coherence than S loses to
    imbalance. Points off the grid (NaN) are left out; the study's machine
    is (1, 1).
    """
    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.gca()
    groups = ["scene", "mapping"] if "scene" in boundary else ["mapping"]
    for key, part in boundary.groupby(groups, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        found = part.dropna(subset=["latency_scale"])
        ax.plot(found["record_scale"], found["latency_scale"], marker="o", label=" ".join(map(str, key)))
    ax.plot([1], [1], marker="*", markersize=12, color="black", linestyle="none", label="the study's machine")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log", base=2)
    ax.set_xlabel("record bytes x k")
    ax.set_ylabel("memory latency x m where coherence loss = S's imbalance loss")
    ax.legend(fontsize="small")
    return ax
