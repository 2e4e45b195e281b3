"""The traces a what-if grid replays: one per distinct scene of the grid, rendered once (or taken from the cache).

A grid that varies ``scene_size`` replays the trace of the SPD scene at each
size factor, generated as an NFF file in the cache folder
(:func:`sized_scene_file`); one that varies ``tree_variant`` the trace of
each variant's tree; every other parameter replays the base's trace.
"""
from __future__ import annotations

import os
from pathlib import Path

from rtcommon.files import remove_stale_temporaries
from rtcommon.validate import InputError, require_int

__all__ = ["TRACE_PARAMETERS", "scene_key", "traces_for", "sized_scene_file"]


#: Grid parameters that decide a point's trace: each value renders a trace of its own.
TRACE_PARAMETERS = ("scene_size", "tree_variant")


def scene_key(point: dict) -> tuple:
    """What decides the trace of a grid point: its :data:`TRACE_PARAMETERS` (None where the base's holds)."""
    return tuple(point.get(key) for key in TRACE_PARAMETERS)


def traces_for(study, points, cache_dir, progress) -> dict:
    """Trace folder per distinct scene of the grid (rendered once each), by :func:`scene_key`.

    ``study`` is an :class:`analyses.whatif.WhatIf`; ``points`` its points (dicts).
    """
    from analyses.memory_budget import memory_shares
    from analyses.traces import cached_trace

    base = study.experiment
    records_budget = memory_shares(base.memory_budget, base.size * base.size)["render_records"]
    folders = {}
    for key in dict.fromkeys(scene_key(point) for point in points):
        size_factor, tree_variant = key
        scene = study.scene if size_factor is None else sized_scene_file(study.scene, size_factor, cache_dir)
        _, _, info = cached_trace(scene, study.size, cache_dir=cache_dir, kd=base.kd, max_depth=base.max_depth,
                                  progress=progress, workload=base.trace_workload(), memory_budget=records_budget,
                                  tree_variant=tree_variant or base.tree_variant)
        folders[key] = str(Path(info["path"]) / "trace")
    return folders


def sized_scene_file(name: str, size_factor, cache_dir) -> str:
    """An NFF file of an SPD scene at another size factor (in the cache folder)."""
    from analyses.traces import cache_root
    from tracer.scenes import spd
    from tracer.scenes.nff import format_nff, write_nff
    from tracer.scenes.study import PAPER_DEPTH, canonical_scene_name

    generators = {"balls": spd.balls, "tetra": spd.tetra, "shell": spd.shells}
    key = canonical_scene_name(name)
    if key not in generators:
        raise InputError(f"scene_size applies to the SPD scenes {sorted(generators)}, not {name!r}")
    size_factor = require_int("scene_size (an SPD size factor)", size_factor, 1)
    scene = generators[key](size_factor)
    scene.max_depth = PAPER_DEPTH[key]
    folder = cache_root(cache_dir) / "scenes"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except PermissionError:  # a read-only cache: generate the scene for this process only
        import tempfile

        folder = Path(tempfile.gettempdir()) / f"coherence-scenes-{os.getuid()}"
        folder.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(folder)  # a killed run's half-written scene files
    path = folder / f"{name}-size{size_factor}.nff"
    # the generator decides every byte: a file that differs (damaged, edited) is written again, or the
    # traces keyed by its content would be of another scene
    if not path.is_file() or path.read_bytes() != format_nff(scene).encode("utf-8"):
        write_nff(scene, path)
    return str(path)
