"""What-if studies: where would coherence start to matter more than balance?

A study (:class:`WhatIf`) is a base :class:`~analyses.experiment.Experiment`
(scene, image size, workload, mappings, one process count, hierarchy, layout,
cost model, machine, trace cache, Dask scheduler, memory budget) and a grid of
parameters to vary (their names and values: :mod:`analyses.whatif_grid`;
under a platform also its variants: :mod:`analyses.whatif_platform`).
Every grid point is an independent task: the trace is rendered once (or
taken from the trace cache, :mod:`analyses.whatif_traces`) and each task
replays it under the point's configuration. Tasks run in a local process
pool, or on a Dask cluster with the same results. For grids over level
sizes, :func:`exact_lru_curves` (:mod:`analyses.whatif_lru`) adds the exact
misses of fully associative LRU caches; :func:`save_whatif`
(:mod:`analyses.whatif_output`) writes a study's files.

Each row of the result says, for one point, mapping and process count, how
much efficiency was lost to imbalance and to coherence and which was larger
(``verdict``: ``"balance"`` or ``"coherence"``). On a textured scene each
row also says, per cache level, how often a texel read missed
(``texel_<level>_misses_per_access``) and what share of the level's misses
were texels (``texture_<level>_miss_share``): on private caches from each
process's pixels on a cold hierarchy of its own (:mod:`coherence.kind_misses`);
under a platform from the point's own runs on its shared levels, each level's
texel counts summed over its instances (:func:`shared_texture_columns`).
"""
from __future__ import annotations

import itertools
import os
import sys
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from cachesim import Hierarchy, get_hierarchy
from analyses.experiment import Experiment
from analyses.whatif_grid import (LEVEL_FIELDS, PLATFORM_PARAMETERS, PLATFORM_VARIANTS, SIMPLE,  # noqa: F401
                                  check_parameter, parse_grid_flag, parse_value, point_experiment, point_levels)
from analyses.whatif_lru import exact_lru_curves  # noqa: F401
from analyses.whatif_platform import PLATFORM_TIMES, PREFETCH_SUFFIXES, platform_variant, shared_levels
from analyses.whatif_traces import scene_key, sized_scene_file, traces_for
from coherence.metrics import DECOMPOSITION_COLUMNS
from rtcommon.files import read_text_file
from rtcommon.validate import InputError, require_number

#: The base of a what-if study unless told otherwise: the report's choices at
#: 128x128 (every grid point is a full replay), 8 processes on 8 idle CPUs.
WHATIF_EXPERIMENT = Experiment(size=128, n_processes=(8,), background=0)

#: Fields of the base :class:`~analyses.experiment.Experiment` a study file or
#: :meth:`WhatIf.of` may set.
BASE_FIELDS = ("scene", "size", "workload", "tree_variant", "kd", "max_depth", "mappings", "n_processes", "hierarchy",
               "layout", "cost", "n_cpus", "background", "background_footprint", "page_placement", "page_seed",
               "memory_budget", "platform", "frame_buffer_bytes")

# private names analyses.order_whatif and tests import from this module
_point_levels, _sized_scene_file, _traces_for = point_levels, sized_scene_file, traces_for


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
            check_parameter(key)
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
    """The (hierarchy, layout, cost, machine, n_processes) of one grid point.

    ``hierarchy`` is a :class:`cachesim.Hierarchy`, or under a platform the point's shared levels
    (:func:`analyses.whatif_platform.shared_levels`, a :class:`coherence.shared_run.SharedLevels`): what the
    point's runs simulate on, either way.
    """
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.page_placement import PagePlacement
    from coherence.simulation import Machine

    experiment = point_experiment(study.experiment, point)
    platform = platform_variant(study, point)
    if platform is not None:  # a grid may not vary the hierarchy under a platform
        hierarchy = shared_levels(study, point)
    else:
        hierarchy = point_levels(get_hierarchy(point["hierarchy"]) if "hierarchy" in point
                                 else base or study.base_hierarchy(), point)
    cost = get_cost_model(point.get("cost", study.cost))
    scale = require_number("compute_scale", point.get("compute_scale", 1.0), 0)
    if scale == 0:
        raise InputError("compute_scale must be a finite number > 0, got 0")
    if scale != 1.0:
        from coherence.cost import OPERATIONS

        cost = replace(cost, **{name: getattr(cost, name) * scale for name in OPERATIONS})
    layout = get_layout(point.get("layout", experiment.layout))
    pixel_bytes = point.get("frame_buffer_bytes", study.experiment.frame_buffer_bytes)
    if pixel_bytes is not None:
        layout = layout.with_frame_buffer(pixel_bytes)
    if "texture_layout" in point:
        from coherence.texture_layout import TextureLayout

        layout = layout.with_texels(TextureLayout.from_label(point["texture_layout"]))
    n_cpus = platform.n_threads if platform is not None else int(point.get("n_cpus", study.n_cpus))
    machine = Machine(n_cpus=n_cpus, background_load=int(point.get("background", study.background)),
                      background_footprint=experiment.background_footprint,
                      page_placement=PagePlacement(experiment.page_placement, seed=experiment.page_seed))
    n_processes = int(point.get("n_processes", study.n_processes))
    return hierarchy, layout, cost, machine, n_processes


def evaluate_point(study: WhatIf, point: dict, trace_folder: str) -> pd.DataFrame:
    """Simulate one grid point on a stored trace; one row per mapping at the point's n."""
    from coherence.studies import Execution, study as run_study
    from tracer.scenes.catalog import load
    from tracer.trace.access import AccessTrace

    caches, layout, cost, machine, n_processes = configure(study, point)  # under a platform, its shared levels
    trace = AccessTrace.load(Path(trace_folder))
    # The scene gives polygons their true sizes in the layout; SPD scenes at
    # other size factors have none.
    scene = load(study.scene) if "scene_size" not in point else None
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
        if result.kinds is None:
            texture = [_texture_columns(trace, scene, mapping, n_processes, caches, layout, cost)
                       for mapping in table["mapping"]]
        else:
            texture = [shared_texture_columns(result, mapping, n_processes) for mapping in table["mapping"]]
        table = pd.concat([table, pd.DataFrame(texture, index=table.index)], axis=1)
    for key, value in reversed(list(point.items())):
        table.insert(0, key, value if not isinstance(value, (list, dict)) else str(value))
    table["verdict"] = np.where(table["coherence_loss"] > table["imbalance_loss"], "coherence", "balance")
    return table.reset_index(drop=True)


def _texture_columns(trace, scene, mapping, n_processes, hierarchy, layout, cost) -> dict:
    """Texel miss rates and shares per level of one mapping on private caches (see the module docstring)."""
    from coherence.kind_misses import dedicated_task_owners, misses_by_kind, texture_summary
    from coherence.mappings import get_mapping
    from coherence.studies import place_layout

    placed = place_layout(layout, trace, scene)
    distribution = get_mapping(mapping).build(trace.width, trace.height, n_processes)
    owner = dedicated_task_owners(trace, distribution, hierarchy, placed, cost)
    return texture_summary(misses_by_kind(trace, placed, hierarchy, distribution, owner))


def shared_texture_columns(result, mapping: str, n_processes: int) -> dict:
    """Texel miss rates and shares per level of one run of a study on shared levels, from its own counts.

    Parameters
    ----------
    result : coherence.studies.StudyResult
        Of a study on shared levels (``result.kinds`` not None).
    mapping : str
    n_processes : int

    Returns
    -------
    dict
        :func:`coherence.kind_misses.texture_summary` of the run's per-kind counts (texel reads and misses
        summed over each level's instances), a level's misses the processes' own (the run's
        ``<level>_misses`` summed: background reads left out), as the report's texture section counts them.
    """
    from coherence.kind_misses import texture_summary

    kinds, processes = result.kinds, result.processes
    by_kind = kinds[(kinds["mapping"] == mapping) & (kinds["n_processes"] == n_processes)]
    own = processes[(processes["mapping"] == mapping) & (processes["n_processes"] == n_processes)]
    return texture_summary(by_kind, {level: own[f"{level}_misses"].sum() for level in by_kind["level"].unique()})


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
    folders = traces_for(study, points, cache_dir, progress)
    tasks = [(study, point, folders[scene_key(point)]) for point in points]
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
