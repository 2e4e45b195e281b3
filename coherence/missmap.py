"""Per-pixel miss maps: where in the image each cache level misses, under one mapping.

>>> from coherence import miss_map                                   # doctest: +SKIP
>>> misses = miss_map(trace, "P", 8, machine=Machine(background_load=4))
>>> misses.level("L1")            # (H, W) misses of each pixel in the first-level cache
>>> misses.frame()                # tidy: x, y, level, misses

A pixel's misses at a level are those of its own accesses (reads and
writes) on the caches of the CPU its process rendered it on, so they
depend on the mapping, the process count and the machine: what the
process's previous pixels (and, sharing a CPU, other processes) left in
the caches. Summed over a process's pixels they give its
``<level>_misses`` in :func:`coherence.simulation.simulate_run`'s table.

On levels shared by hardware threads (``hierarchy`` a
:class:`coherence.shared_run.SharedLevels`) the run is
:func:`coherence.shared_run.simulate_shared_run`'s: a pixel's misses are
those of its own accesses on the instances its thread reaches, so they also
count what the threads running beside it evicted or invalidated; a dynamic
mapping's task counter accesses belong to no pixel.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cachesim.config import DEFAULT_HIERARCHY
from coherence.cost import DEFAULT_COST_MODEL
from coherence.layout import DEFAULT_LAYOUT
from rtcommon.validate import InputError, require_int

__all__ = ["MissMap", "miss_map"]


@dataclass(frozen=True)
class MissMap:
    """Misses per pixel per cache level of one simulated run.

    Attributes
    ----------
    misses : ndarray of int64, shape (H, W, L)
        Misses of the pixel in row ``y``, column ``x`` at level ``l``
        (row 0 is the image's top row).
    levels : tuple of str
        Names of the L cache levels, first level first.
    scene : str
        Name of the scene (for titles).
    mapping : str
        Name of the mapping the run used.
    n_processes : int
        Processes of the run.
    """

    misses: np.ndarray
    levels: tuple
    scene: str
    mapping: str
    n_processes: int

    def __post_init__(self):
        misses = self.misses
        if not isinstance(misses, np.ndarray) or misses.ndim != 3 or misses.dtype != np.int64:
            raise InputError("MissMap.misses must be an int64 array of shape (H, W, L), got "
                             f"{getattr(misses, 'dtype', type(misses).__name__)} of shape "
                             f"{getattr(misses, 'shape', None)}")
        levels = tuple(self.levels)
        if len(levels) != misses.shape[2] or not all(isinstance(name, str) and name for name in levels) \
                or len(set(levels)) != len(levels):
            raise InputError(f"MissMap.levels must be {misses.shape[2]} distinct non-empty names (one per "
                             f"level of misses), got {self.levels!r}")
        object.__setattr__(self, "levels", levels)
        require_int("MissMap.n_processes", self.n_processes, 1)

    def level(self, name: str) -> np.ndarray:
        """Misses per pixel at level ``name``, int64 (H, W)."""
        if name not in self.levels:
            raise InputError(f"unknown level {name!r}; this miss map has {', '.join(self.levels)}")
        return self.misses[:, :, self.levels.index(name)]

    def frame(self) -> pd.DataFrame:
        """The map in tidy form: one row per (pixel, level).

        Returns
        -------
        DataFrame
            Columns ``x``, ``y`` (int64), ``level`` (str), ``misses``
            (int64); pixels in row-major order within each level, levels in
            order.
        """
        height, width, n_levels = self.misses.shape
        y, x = np.divmod(np.arange(height * width, dtype=np.int64), width)
        return pd.DataFrame({
            "x": np.tile(x, n_levels), "y": np.tile(y, n_levels),
            "level": np.repeat(np.array(self.levels, dtype=object), height * width),
            "misses": np.moveaxis(self.misses, 2, 0).reshape(-1),
        })

    def totals(self) -> pd.DataFrame:
        """Per level: total misses, mean and largest per pixel, and the share of all the level's
        misses made by the 1% of pixels that miss most.

        Returns
        -------
        DataFrame
            Columns ``level``, ``total``, ``mean_per_pixel``,
            ``max_per_pixel``, ``top_1pct_share`` (NaN for a level with no
            misses).
        """
        flat = self.misses.reshape(-1, len(self.levels))
        top = max(1, -(-flat.shape[0] // 100))
        rows = []
        for index, name in enumerate(self.levels):
            column = flat[:, index]
            total = int(column.sum())
            largest = np.sort(column)[::-1][:top]
            rows.append({"level": name, "total": total, "mean_per_pixel": float(column.mean()),
                         "max_per_pixel": int(column.max()),
                         "top_1pct_share": float(largest.sum() / total) if total else float("nan")})
        return pd.DataFrame(rows)


def miss_map(trace, mapping, n_processes: int, *, hierarchy=DEFAULT_HIERARCHY, layout=DEFAULT_LAYOUT,
             cost=DEFAULT_COST_MODEL, machine=None, scene=None) -> MissMap:
    """Simulate one run and return its misses per pixel per cache level.

    Parameters
    ----------
    trace : tracer.trace.access.AccessTrace
        Per-pixel access logs of a W x H image.
    mapping : str or coherence.mappings.Mapping
        The work distribution (a name of :data:`coherence.mappings.MAPPINGS`
        or a mapping object).
    n_processes : int
        Processes to distribute the image among.
    hierarchy, layout, cost : object or preset name
        As for :func:`coherence.study` (``hierarchy`` a
        :class:`coherence.shared_run.SharedLevels`: the run on its shared
        levels; ``machine`` must then have its hardware threads as CPUs).
    machine : coherence.simulation.Machine, optional
        CPUs, scheduler and background load (default ``Machine()``: 8 idle
        CPUs). The same machine as a study's gives that study's run.
    scene : tracer.scenes.model.Scene, optional
        For exact polygon sizes in the layout and the map's scene name
        (default: the name in the trace's metadata).

    Returns
    -------
    MissMap
        ``misses`` (H, W, L), levels in ``hierarchy.levels`` order.
    """
    from cachesim import get_hierarchy
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.shared_run import SharedLevels, simulate_shared_run
    from coherence.simulation import Machine, simulate_run
    from coherence.studies import place_layout

    mapping = get_mapping(mapping)
    n_processes = require_int("n_processes", n_processes, 1)
    shared = hierarchy if isinstance(hierarchy, SharedLevels) else None
    hierarchy = shared.hierarchy if shared is not None else get_hierarchy(hierarchy)
    layout = get_layout(layout)
    cost = get_cost_model(cost)
    machine = Machine() if machine is None else machine
    if not isinstance(machine, Machine):
        raise InputError(f"machine must be a coherence.Machine, got {type(machine).__name__}")
    placed = place_layout(layout, trace, scene)
    distribution = mapping.build(trace.width, trace.height, n_processes)
    if shared is not None:
        run = simulate_shared_run(trace, distribution, shared.machine, placed, cost, machine,
                                  interleave_cycles=shared.interleave_cycles, record=("pixel_misses",)).run
    else:
        run = simulate_run(trace, distribution, hierarchy, placed, cost, machine, pixel_misses=True)
    name = scene.name if scene is not None else str(trace.metadata.get("scene", "trace"))
    return MissMap(run.pixel_misses, tuple(level.name for level in hierarchy.levels), name, mapping.name,
                   n_processes)
