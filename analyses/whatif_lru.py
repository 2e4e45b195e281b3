"""Exact miss curves of fully associative LRU caches at a what-if grid's level sizes, from reuse distances.

Beside the full simulation of the real (direct-mapped, set-associative)
caches at every grid point, one reuse-distance pass per process stream gives
the misses of a fully associative LRU cache of every size at once: the exact
answer for that idealised cache (:func:`cachesim.reuse_profile`).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from analyses.whatif_traces import TRACE_PARAMETERS, traces_for
from rtcommon.validate import InputError

__all__ = ["exact_lru_curves"]


def exact_lru_curves(study, *, progress: bool = False, **choices) -> pd.DataFrame | None:
    """Exact misses of fully associative LRU caches at the grid's level sizes.

    For every ``<level>.size`` in the grid, one reuse-distance pass per
    process stream (each mapping at ``study.n_processes``, cold caches, that
    level's line size) gives the misses of a fully associative LRU cache of
    every size at once: the exact answer for that idealised cache, beside the
    full simulation of the real (direct-mapped, set-associative) ones.
    Returns None when the grid varies no level size, or varies the trace
    (:data:`analyses.whatif_traces.TRACE_PARAMETERS`) or the memory image
    (``layout``, ``memory_image``).

    Parameters
    ----------
    study : analyses.whatif.WhatIf
    progress : bool
        Progress bars while the trace is rendered.
    **choices
        Fields of ``study.experiment`` to replace, as in :func:`analyses.whatif.run_whatif`.

    Returns
    -------
    DataFrame
        mapping, n_processes, level, line_size, size, accesses, misses,
        miss_ratio (summed over the processes).
    """
    from cachesim import reuse_profile
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.studies import place_layout
    from tracer.scenes.catalog import load
    from tracer.trace.access import AccessTrace

    if choices:  # fields of the base experiment to replace, as in run_whatif
        study = replace(study, experiment=replace(study.experiment, **choices))
    sized = {key.split(".")[0]: values for key, values in study.grid.items() if key.endswith(".size")}
    # one curve stands for every point, so none when the points differ in trace or memory image
    if not sized or any(key in study.grid for key in (*TRACE_PARAMETERS, "layout", "memory_image")):
        return None
    folder = next(iter(traces_for(study, [{}], study.experiment.cache_dir, progress).values()))
    trace = AccessTrace.load(Path(folder))
    placed = place_layout(get_layout(study.layout), trace, load(study.scene))
    levels = {level.name: level for level in study.base_hierarchy().levels}
    rows = []
    for name in study.mappings:
        distribution = get_mapping(name).build(trace.width, trace.height, study.n_processes)
        streams = [_process_records(trace, distribution, process, study.n_processes)
                   for process in range(study.n_processes)]
        for level_name, sizes in sized.items():
            if level_name not in levels:
                raise InputError(f"what-if parameter {level_name}.size: the hierarchy has levels {list(levels)}")
            line_size = levels[level_name].line_size
            accesses = 0
            misses = np.zeros(len(sizes), dtype=np.int64)
            for records in streams:
                addresses = placed.addresses(records, line_size)
                accesses += addresses.size
                misses += reuse_profile(addresses, line_size).misses(np.asarray(sizes, dtype=np.int64) // line_size)
            for size, count in zip(sizes, misses):
                rows.append({"mapping": name, "n_processes": study.n_processes, "level": level_name,
                             "line_size": line_size, "size": int(size), "accesses": int(accesses),
                             "misses": int(count), "miss_ratio": count / accesses if accesses else float("nan")})
    return pd.DataFrame(rows)


def _process_records(trace, distribution, process: int, n_processes: int) -> np.ndarray:
    """The records one process reads, in its order; a dynamic mapping's blocks taken in hand-out order round
    robin (DB)."""
    if distribution.dynamic:
        owner = np.repeat(np.arange(distribution.n_tasks), np.diff(distribution.task_offsets))
        tasks = np.arange(process, distribution.n_tasks, n_processes)
        pixels = distribution.task_pixels[np.isin(owner, tasks)]
    else:
        pixels = distribution.process_pixels(process)
    starts, stops = trace.pixel_offsets[pixels], trace.pixel_offsets[pixels + 1]
    index = np.concatenate([np.arange(a, b) for a, b in zip(starts, stops)]) if len(pixels) else \
        np.zeros(0, dtype=np.int64)
    return np.asarray(trace.records)[index]
