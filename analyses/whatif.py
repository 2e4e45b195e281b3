"""What-if studies: where would coherence start to matter more than balance?

A study (:class:`WhatIf`) is a base :class:`~analyses.experiment.Experiment`
(scene, image size, workload, mappings, one process count, hierarchy, layout,
cost model, machine, trace cache, Dask scheduler, memory budget) and a grid of
parameters to vary.
Every grid point is an independent task: the trace is rendered once (or
taken from the trace cache) and each task replays it under the point's
configuration. Tasks run in a local process pool, or on a Dask cluster with
the same results.

Grid parameters (names as in flags and TOML files):

====================== ========================================================
``memory_latency``     cycles of a memory access
``<level>.size``       bytes of a cache level (``L1.size``; ``96KB``, ``4MB``)
``<level>.line_size``  line size of one level; ``line_size`` sets every level
``<level>.assoc``      ways (or ``full``); ``<level>.latency`` hit cycles
``hierarchy``          a preset (``alpha21164``, ``modern``) or a file
``compute_scale``      factor on every cost model cycle count
``cost``               a cost preset (``alpha8400``, ``modern``)
``layout``             a memory layout preset (``compact``, ``alpha1997``)
``texture_layout``     texel order: ``linear``, ``tiled<k>``, ``morton``,
                       ``blocked<k>x<s>`` (:mod:`coherence.texture_layout`)
``scene_size``         SPD size factor of the scene (balls, tetra, shell only)
``n_processes``        processes; ``n_cpus``, ``background`` the machine
``frame_buffer_bytes`` bytes of a frame-buffer pixel: 3, 4 or 16
====================== ========================================================

Under a platform (base ``platform``), its variants
(:meth:`coherence.platforms.Platform.variant`):

====================== ========================================================
``cores``              cores of the machine (complexes keep their size)
``smt``                ``on`` (the platform's SMT), ``off`` (one thread a
                       core) or threads per core
``l3_size``            bytes of the whole shared L3 (``16MB``)
``prefetch``           ``on`` / ``off``: the prefetchers of
                       :data:`coherence.platforms.PREFETCHERS_ON`
====================== ========================================================

Under a platform every point's runs are simulated on the variant's shared
levels (:func:`shared_levels`), the point's level changes applied to whole
levels, interleaved every ``interleave_cycles`` of the base; each row then
also gives the run's times (:data:`PLATFORM_TIMES`) and, per level, the
machine's coherence and false-sharing misses, and the prefetches issued,
useful and useless (0 at points without prefetchers). The texture columns take the variant's thread view
(:meth:`coherence.platforms.Platform.thread_view`: each level cut to one
thread's share, no prefetchers), not the shared levels.

Each row of the result says, for one point, mapping and process count, how
much efficiency was lost to imbalance and to coherence and which was larger
(``verdict``: ``"balance"`` or ``"coherence"``). On a textured scene each
row also says, per cache level, how often a texel read missed
(``texel_<level>_misses_per_access``) and what share of the level's misses
were texels (``texture_<level>_miss_share``), from each process's pixels on
a cold hierarchy of its own (:mod:`coherence.kind_misses`).
"""
from __future__ import annotations

import itertools
import os
import re
import sys
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from cachesim import Hierarchy, get_hierarchy
from analyses.experiment import Experiment
from coherence.metrics import DECOMPOSITION_COLUMNS
from rtcommon.files import read_text_file, remove_stale_temporaries
from rtcommon.validate import InputError, require_int, require_number

LEVEL_FIELDS = ("size", "line_size", "assoc", "latency", "policy")
SIMPLE = ("memory_latency", "hierarchy", "compute_scale", "cost", "layout", "texture_layout", "scene_size",
          "n_processes", "n_cpus", "background", "line_size", "frame_buffer_bytes")
#: Grid parameters that vary the base's platform (:meth:`coherence.platforms.Platform.variant`).
PLATFORM_VARIANTS = ("cores", "smt", "l3_size", "prefetch")
_SWITCHES = {"on": True, "true": True, "off": False, "false": False}
_UNITS = {"": 1, "B": 1, "KB": 1024, "K": 1024, "MB": 1024**2, "M": 1024**2, "GB": 1024**3, "G": 1024**3}


#: The base of a what-if study unless told otherwise: the report's choices at
#: 128x128 (every grid point is a full replay), 8 processes on 8 idle CPUs.
WHATIF_EXPERIMENT = Experiment(size=128, n_processes=(8,), background=0)

#: Fields of the base :class:`~analyses.experiment.Experiment` a study file or
#: :meth:`WhatIf.of` may set.
BASE_FIELDS = ("scene", "size", "workload", "tree_variant", "kd", "max_depth", "mappings", "n_processes", "hierarchy",
               "layout", "cost", "n_cpus", "background", "memory_budget", "platform", "frame_buffer_bytes")

#: Ends of the per-level prefetch columns of a row under a platform with prefetchers
#: (:data:`coherence.shared_run.PREFETCH_RUN_COLUMNS`); 0 at points without them.
PREFETCH_SUFFIXES = ("_prefetches_issued", "_prefetches_useful", "_prefetches_useless")

#: Columns a row under a platform adds beside the efficiency decomposition: the slowest process's user
#: seconds, the run's real seconds and its memory cycles summed over processes.
PLATFORM_TIMES = ("user_seconds_max", "real_seconds", "memory_cycles")

#: Grid parameters a platform sets, so a study under one may not vary them.
PLATFORM_PARAMETERS = ("hierarchy", "cost", "n_cpus")


@dataclass(frozen=True)
class WhatIf:
    """A what-if study: a base experiment and a grid over parameters.

    Parameters
    ----------
    name : str
    experiment : analyses.experiment.Experiment
        The base configuration (scene, size, workload, mappings, one process
        count, caches, layout, cost model, machine, trace cache, Dask
        scheduler, memory budget); default :data:`WHATIF_EXPERIMENT`.
        Every grid point varies it. ``scene``, ``size``, ``mappings``,
        ``n_processes`` (the one count, an int), ``hierarchy``, ``cost``,
        ``layout``, ``n_cpus`` and ``background`` read through to it;
        under a platform, ``hierarchy`` names its shared hierarchy, ``cost`` its
        cost model and ``n_cpus`` its hardware threads, and the grid may
        not vary them (:data:`PLATFORM_PARAMETERS`).
    grid : dict of str to list
        Values per parameter; the study runs every combination.

    Raises
    ------
    ValueError
        An empty grid, an unknown parameter, a point that makes no valid
        configuration, or a base with other than one process count (vary it
        with ``grid n_processes``).
    """

    name: str = "custom"
    experiment: Experiment = WHATIF_EXPERIMENT
    grid: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.experiment, Experiment):
            raise InputError(f"WhatIf.experiment must be an analyses.experiment.Experiment, got "
                             f"{type(self.experiment).__name__}")
        if len(self.experiment.n_processes) != 1:
            raise InputError(f"WhatIf.experiment.n_processes must be one process count (vary it with the grid's "
                             f"n_processes), got {list(self.experiment.n_processes)}")
        if not self.grid:
            raise InputError("WhatIf.grid must vary at least one parameter")
        for key, values in self.grid.items():
            _check_parameter(key)
            if not isinstance(values, (list, tuple)) or not values:
                raise InputError(f"grid[{key!r}] must be a non-empty list of values")
            if key in PLATFORM_PARAMETERS and self.experiment.platform is not None:
                raise InputError(f"grid[{key!r}]: the platform {self.experiment.platform_object().name} sets the "
                                 f"hierarchy, the cost and the CPUs; vary them without a platform")
            if key in PLATFORM_VARIANTS and self.experiment.platform is None:
                raise InputError(f"grid[{key!r}] varies a platform: give the base one (--platform NAME, "
                                 f"platform = \"NAME\" in a study file)")
        base = self.base_hierarchy()
        for point in self.points():  # every point must make a valid configuration
            configure(self, point, base)

    @classmethod
    def of(cls, name: str, grid: dict, **choices) -> WhatIf:
        """A study whose base is :data:`WHATIF_EXPERIMENT` with ``choices`` (fields of :data:`BASE_FIELDS`)."""
        unknown = sorted(set(choices) - set(BASE_FIELDS))
        if unknown:
            raise InputError(f"unknown what-if base keys {unknown}; allowed: {list(BASE_FIELDS)}")
        return cls(name=name, experiment=replace(WHATIF_EXPERIMENT, **choices), grid=grid)

    # the base's choices, read through
    scene = property(lambda self: self.experiment.scene)
    size = property(lambda self: self.experiment.size)
    mappings = property(lambda self: self.experiment.mappings)
    n_processes = property(lambda self: self.experiment.n_processes[0])
    layout = property(lambda self: self.experiment.layout)
    n_cpus = property(lambda self: self.experiment.cpus())
    background = property(lambda self: self.experiment.background)

    @property
    def hierarchy(self):
        """The base's hierarchy as given, or the name of its platform's shared hierarchy (what the runs simulate)."""
        platform = self.experiment.platform_object()
        return self.experiment.hierarchy if platform is None else platform.hierarchy.name

    @property
    def cost(self):
        """The base's cost model as given, or its platform's cost model's name."""
        platform = self.experiment.platform_object()
        return self.experiment.cost if platform is None else platform.cost.name

    def base_hierarchy(self) -> Hierarchy:
        return self.experiment.hierarchy_object()

    def points(self) -> list[dict]:
        """Every combination of the grid's values, in grid order."""
        keys = list(self.grid)
        return [dict(zip(keys, values)) for values in itertools.product(*(self.grid[k] for k in keys))]


def _check_parameter(key: str) -> None:
    if key in SIMPLE or key in PLATFORM_VARIANTS:
        return
    level, _, attribute = key.partition(".")
    if attribute in LEVEL_FIELDS and level:
        return
    raise InputError(f"unknown what-if parameter {key!r}: use one of {', '.join(SIMPLE + PLATFORM_VARIANTS)} or "
                     f"<level>.{{{','.join(LEVEL_FIELDS)}}}")


def parse_value(text: str):
    """A grid value from text: ``4MB`` -> 4194304, ``full``, ``0.5``, ``alpha21164``."""
    text = text.strip()
    match = re.fullmatch(r"([0-9]+(?:\.[0-9]+)?)\s*([KMG]?B?)", text, re.IGNORECASE)
    if match:
        number, unit = match.groups()
        value = float(number) * _UNITS[unit.upper()]
        return int(value) if value.is_integer() else value
    return text


def parse_grid_flag(flag: str) -> tuple[str, list]:
    """``"L3.size=1MB,4MB"`` -> ``("L3.size", [1048576, 4194304])``."""
    key, sep, values = flag.partition("=")
    if not sep or not values.strip():
        raise InputError(f"--grid {flag!r}: expected NAME=VALUE[,VALUE...], e.g. L3.size=1MB,4MB")
    key = key.strip()
    _check_parameter(key)
    return key, [parse_value(value) for value in values.split(",")]


def load_study_file(path) -> WhatIf:
    """A study from a TOML file (UTF-8, a byte-order mark skipped): top-level base keys and a ``[grid]`` table."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such what-if file")
    text = read_text_file(path, "a TOML what-if study")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"{path}: not valid TOML: {error}") from None
    grid = data.pop("grid", None)
    if not isinstance(grid, dict):
        raise InputError(f"{path}: needs a [grid] table of parameter = [values]")
    grid = {key: [parse_value(v) if isinstance(v, str) else v for v in values] if isinstance(values, list)
            else values for key, values in grid.items()}
    known = {"name", *BASE_FIELDS}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"{path}: unknown keys {unknown}; allowed: {sorted(known)} and [grid]")
    if isinstance(data.get("mappings"), list):
        data["mappings"] = tuple(data["mappings"])
    try:
        return WhatIf.of(data.pop("name", "custom"), grid, **data)
    except (ValueError, TypeError) as error:
        raise InputError(f"{path}: {error}") from None


def configure(study: WhatIf, point: dict, base: Hierarchy | None = None):
    """The (hierarchy, layout, cost, machine, n_processes) of one grid point."""
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.simulation import Machine

    platform = platform_variant(study, point)
    if platform is not None:  # a grid may not vary the hierarchy under a platform
        hierarchy = platform.thread_view()
    elif "hierarchy" in point:
        hierarchy = get_hierarchy(point["hierarchy"])
    else:
        hierarchy = base or study.base_hierarchy()
    hierarchy = _point_levels(hierarchy, point)
    cost = get_cost_model(point.get("cost", study.cost))
    scale = require_number("compute_scale", point.get("compute_scale", 1.0), 0)
    if scale == 0:
        raise InputError("compute_scale must be a finite number > 0, got 0")
    if scale != 1.0:
        from coherence.cost import OPERATIONS

        cost = replace(cost, **{name: getattr(cost, name) * scale for name in OPERATIONS})
    layout = get_layout(point.get("layout", study.layout))
    pixel_bytes = point.get("frame_buffer_bytes", study.experiment.frame_buffer_bytes)
    if pixel_bytes is not None:
        layout = layout.with_frame_buffer(pixel_bytes)
    if "texture_layout" in point:
        from coherence.texture_layout import TextureLayout

        layout = layout.with_texels(TextureLayout.from_label(point["texture_layout"]))
    n_cpus = platform.n_threads if platform is not None else int(point.get("n_cpus", study.n_cpus))
    machine = Machine(n_cpus=n_cpus,
                      background_load=int(point.get("background", study.background)))
    n_processes = int(point.get("n_processes", study.n_processes))
    return hierarchy, layout, cost, machine, n_processes


def _point_levels(hierarchy: Hierarchy, point: dict) -> Hierarchy:
    """``hierarchy`` with the point's ``line_size``, ``<level>.<field>`` and ``memory_latency``."""
    levels = {level.name: level for level in hierarchy.levels}
    updates: dict[str, dict] = {}
    for key, value in point.items():
        if key == "line_size":
            for name in levels:
                updates.setdefault(name, {})["line_size"] = value
        elif "." in key:
            name, attribute = key.split(".", 1)
            if name not in levels:
                raise InputError(f"what-if parameter {key!r}: the hierarchy has levels {list(levels)}")
            updates.setdefault(name, {})[attribute] = value
    try:
        if updates:
            hierarchy = replace(hierarchy, levels=tuple(replace(level, **updates.get(level.name, {}))
                                                        for level in hierarchy.levels))
        if "memory_latency" in point:
            hierarchy = replace(hierarchy, memory_latency=point["memory_latency"])
    except ValueError as error:
        raise InputError(f"what-if point {point}: {error}") from None
    return hierarchy


def shared_levels(study: WhatIf, point: dict):
    """Under a platform, what a point's runs simulate on: the point's platform variant's shared levels, with the
    point's level changes applied to the whole levels (an ``L3.size`` is the size of one L3), interleaved at the
    base's ``interleave_cycles`` (:class:`coherence.shared_run.SharedLevels`); None without a platform."""
    from coherence.shared_run import SharedLevels

    platform = platform_variant(study, point)
    if platform is None:
        return None
    machine = platform.hierarchy
    try:
        machine = replace(machine, hierarchy=_point_levels(machine.hierarchy, point))
    except ValueError as error:
        raise InputError(f"what-if point {point}: {error}") from None
    return SharedLevels(machine, study.experiment.interleave_cycles)


def platform_variant(study: WhatIf, point: dict):
    """The base's platform changed by the point's :data:`PLATFORM_VARIANTS` (None without a platform).

    ``smt`` and ``prefetch`` take ``on``/``off`` (or True/False); ``smt`` also a count of threads per core.
    """
    platform = study.experiment.platform_object()
    if platform is None:
        return None
    choices = {}
    for key in PLATFORM_VARIANTS:
        if key not in point:
            continue
        value = point[key]
        if key in ("smt", "prefetch") and isinstance(value, str):
            if value.lower() not in _SWITCHES:
                raise InputError(f"what-if parameter {key} must be on or off"
                                 f"{' or threads per core' if key == 'smt' else ''}, got {value!r}")
            value = _SWITCHES[value.lower()]
        choices[key] = value
    try:
        return platform.variant(**choices)
    except ValueError as error:
        raise InputError(f"what-if point {point}: {error}") from None


def evaluate_point(study: WhatIf, point: dict, trace_folder: str) -> pd.DataFrame:
    """Simulate one grid point on a stored trace; one row per mapping at the point's n."""
    from coherence.studies import Execution, study as run_study
    from tracer.scenes.catalog import load
    from tracer.trace.access import AccessTrace

    hierarchy, layout, cost, machine, n_processes = configure(study, point)
    trace = AccessTrace.load(Path(trace_folder))
    # The scene gives polygons their true sizes in the layout; SPD scenes at
    # other size factors have none.
    scene = load(study.scene) if "scene_size" not in point else None
    caches = shared_levels(study, point) or hierarchy  # under a platform, its shared levels
    result = run_study(trace, study.mappings, [n_processes], hierarchy=caches, layout=layout, cost=cost,
                       machine=machine, scene=scene, progress=False, execution=Execution(n_jobs=1))
    runs = result.runs[result.runs["n_processes"] == n_processes]
    level_columns = [c for c in runs.columns
                     if c.endswith(("_hit_rate", "_misses_per_ray", "_coherence_misses", "_false_sharing_misses",
                                    *PREFETCH_SUFFIXES))]
    # under a platform also the run's times, so that variants (prefetch on and off, say) compare in seconds
    timing = list(PLATFORM_TIMES) if study.experiment.platform is not None else []
    table = runs[["mapping", "n_processes", *DECOMPOSITION_COLUMNS, *timing, *level_columns]].copy()
    if trace.metadata.get("textures"):
        texture = pd.DataFrame([_texture_columns(trace, scene, mapping, n_processes, hierarchy, layout, cost)
                                for mapping in table["mapping"]], index=table.index)
        table = pd.concat([table, texture], axis=1)
    for key, value in reversed(list(point.items())):
        table.insert(0, key, value if not isinstance(value, (list, dict)) else str(value))
    table["verdict"] = np.where(table["coherence_loss"] > table["imbalance_loss"], "coherence", "balance")
    return table.reset_index(drop=True)


def _texture_columns(trace, scene, mapping, n_processes, hierarchy, layout, cost) -> dict:
    """Texel miss rates and shares per level of one mapping (see the module docstring)."""
    from coherence.kind_misses import dedicated_task_owners, misses_by_kind, texture_summary
    from coherence.mappings import get_mapping
    from coherence.studies import place_layout

    placed = place_layout(layout, trace, scene)
    distribution = get_mapping(mapping).build(trace.width, trace.height, n_processes)
    owner = dedicated_task_owners(trace, distribution, hierarchy, placed, cost)
    return texture_summary(misses_by_kind(trace, placed, hierarchy, distribution, owner))


def run_whatif(study: WhatIf, *, n_jobs: int | None = None, **choices) -> pd.DataFrame:
    """Run every grid point; a wide table, one row per (point, mapping).

    The trace cache, the Dask scheduler (default: a local process pool) and
    the progress bars are the base experiment's.

    Parameters
    ----------
    study : WhatIf
    n_jobs : int, optional
        Local worker processes (default: CPUs).
    **choices
        Fields of ``study.experiment`` to replace (``cache_dir=...``,
        ``dask=...``, ``progress=False``), a shorthand for
        :func:`dataclasses.replace`.
    """
    from tqdm.auto import tqdm

    if choices:
        study = replace(study, experiment=replace(study.experiment, **choices))
    experiment = study.experiment
    cache_dir, dask, progress = experiment.cache_dir, experiment.dask, experiment.progress
    study = replace(study, experiment=replace(experiment, dask=None))  # what travels with each task
    points = study.points()
    folders = _traces_for(study, points, cache_dir, progress)
    tasks = [(study, point, folders[_scene_key(point)]) for point in points]
    if dask is not None:
        frames = _run_dask(tasks, dask, progress)
    else:
        workers = n_jobs or os.cpu_count() or 1
        if workers == 1 or len(tasks) == 1:
            frames = [evaluate_point(*task) for task in tqdm(tasks, desc=study.name, disable=not progress,
                                                               leave=False, file=sys.stderr)]
        else:
            from concurrent.futures import ProcessPoolExecutor
            import multiprocessing

            with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
                futures = [pool.submit(evaluate_point, *task) for task in tasks]
                frames = [future.result() for future in tqdm(futures, desc=study.name, disable=not progress,
                                                             leave=False, file=sys.stderr)]
    table = pd.concat(frames, ignore_index=True)
    prefetched = [column for column in table.columns if column.endswith(PREFETCH_SUFFIXES)]
    if prefetched:  # a point without prefetchers issued none
        table[prefetched] = table[prefetched].fillna(0).astype(np.int64)
    return table


def exact_lru_curves(study: WhatIf, *, progress: bool = False, **choices) -> pd.DataFrame | None:
    """Exact misses of fully associative LRU caches at the grid's level sizes.

    For every ``<level>.size`` in the grid, one reuse-distance pass per
    process stream (each mapping at ``study.n_processes``, cold caches, that
    level's line size) gives the misses of a fully associative LRU cache of
    every size at once: the exact answer for that idealised cache, beside the
    full simulation of the real (direct-mapped, set-associative) ones.
    Returns None when the grid varies no level size.

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
    from tracer.trace.access import AccessTrace

    if choices:  # fields of the base experiment to replace, as in run_whatif
        study = replace(study, experiment=replace(study.experiment, **choices))
    sized = {key.split(".")[0]: values for key, values in study.grid.items() if key.endswith(".size")}
    if not sized or "scene_size" in study.grid:
        return None
    folder = _traces_for(study, [{}], study.experiment.cache_dir, progress)[None]
    trace = AccessTrace.load(Path(folder))
    from tracer.scenes.catalog import load

    placed = place_layout(get_layout(study.layout), trace, load(study.scene))
    levels = {level.name: level for level in study.base_hierarchy().levels}
    rows = []
    for name in study.mappings:
        distribution = get_mapping(name).build(trace.width, trace.height, study.n_processes)
        owner = np.repeat(np.arange(distribution.n_tasks), np.diff(distribution.task_offsets))
        streams = []
        for process in range(study.n_processes):
            if distribution.dynamic:  # DB: take the blocks in hand-out order round robin
                tasks = np.arange(process, distribution.n_tasks, study.n_processes)
                pixels = distribution.task_pixels[np.isin(owner, tasks)]
            else:
                pixels = distribution.process_pixels(process)
            starts, stops = trace.pixel_offsets[pixels], trace.pixel_offsets[pixels + 1]
            index = np.concatenate([np.arange(a, b) for a, b in zip(starts, stops)]) if len(pixels) else \
                np.zeros(0, dtype=np.int64)
            streams.append(np.asarray(trace.records)[index])
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


def long_form(table: pd.DataFrame, study: WhatIf) -> pd.DataFrame:
    """One row per (point, mapping, n_processes, metric): the tidy CSV form."""
    keys = [*study.grid, "mapping", "n_processes"]
    keys = list(dict.fromkeys(keys))
    values = [column for column in table.columns if column not in keys and column != "verdict"]
    long = table.melt(id_vars=keys, value_vars=values, var_name="metric", value_name="value")
    return long.sort_values(keys + ["metric"], kind="stable").reset_index(drop=True)


def _run_dask(tasks, address, progress):
    from analyses.cluster import dask_executor

    with dask_executor(address) as executor:
        futures = [executor.submit(evaluate_point, *task) for task in tasks]
        return [future.result() for future in futures]


def _scene_key(point: dict):
    return point.get("scene_size")


def _traces_for(study: WhatIf, points, cache_dir, progress) -> dict:
    """Trace folder per distinct scene of the grid (rendered once each)."""
    from analyses.traces import cached_trace

    from analyses.memory_budget import memory_shares

    base = study.experiment
    records_budget = memory_shares(base.memory_budget, base.size * base.size)["render_records"]
    folders = {}
    for key in dict.fromkeys(_scene_key(point) for point in points):
        scene = study.scene if key is None else _sized_scene_file(study.scene, key, cache_dir)
        _, _, info = cached_trace(scene, study.size, cache_dir=cache_dir, kd=base.kd, max_depth=base.max_depth,
                                  progress=progress, workload=base.trace_workload(), memory_budget=records_budget,
                                  tree_variant=base.tree_variant)
        folders[key] = str(Path(info["path"]) / "trace")
    return folders


def _sized_scene_file(name: str, size_factor, cache_dir) -> str:
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


# Built-in studies at a small image size: each answers one question.
BUILTIN = {
    "latency": WhatIf.of("latency", {"memory_latency": [40, 80, 160, 320, 640, 1280],
                                     "compute_scale": [0.03125, 0.125, 0.5, 1.0]}),
    "caches": WhatIf.of("caches", {"L3.size": [262144, 1048576, 4194304, 16777216],
                                   "L2.size": [24576, 98304, 393216]}),
    "lines": WhatIf.of("lines", {"line_size": [16, 32, 64, 128]}, hierarchy="alpha21164"),
    "assoc": WhatIf.of("assoc", {"L1.assoc": [1, 2, 4, 8, "full"]}),
    "scene-size": WhatIf.of("scene-size", {"scene_size": [2, 3, 4], "L3.size": [262144, 1048576, 4194304]}),
    "modern": WhatIf.of("modern", {"hierarchy": ["alpha21164", "modern"], "cost": ["alpha8400", "modern"]}),
    # the study's future work: texel order x image split x first-level cache size, on a textured scene
    "texture": WhatIf.of("texture", {"texture_layout": ["linear", "tiled4", "morton", "blocked4x8"],
                                     "L1.size": [8192, 32768, 131072]},
                         scene="balls-textured", mappings=("S", "P", "R", "B", "DB", "hilbert")),
}


# the writing lives in its own module; its names are importable from here
from analyses.whatif_output import lru_csv_path, save_whatif  # noqa: E402
