"""One run's choices, held together: what ``report``, ``paper`` and ``whatif`` are asked to do.

>>> from dataclasses import replace
>>> from analyses.experiment import Experiment
>>> base = Experiment(scene="tetra", size=128)
>>> busier = replace(base, background=8)         # a study varies one choice
>>> busier.as_parameters()["background_load"]
8

An :class:`Experiment` is checked once, when it is made: every field that
is wrong raises ``ValueError`` naming the field and what it may be, before
any trace is rendered. Its defaults are the report's; the paper's and the
what-if studies' bases are replacements of it
(:data:`analyses.paper_study.PAPER_EXPERIMENT`,
:data:`analyses.whatif.WHATIF_EXPERIMENT`). Every output records the
choices its results depend on through :meth:`Experiment.as_parameters`;
where the results are kept, how many runs share the memory and whether
progress is shown change no result, so they are left out of it.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

from analyses.memory_budget import DEFAULT_MEMORY_BUDGET, MIN_MEMORY_BUDGET
from cachesim.config import DEFAULT_HIERARCHY
from coherence.cost import DEFAULT_COST_MODEL
from coherence.layout import DEFAULT_LAYOUT
from coherence.mappings import DEFAULT_MAPPINGS
from coherence.page_placement import PAGE_PLACEMENTS
from coherence.shared_run import DEFAULT_INTERLEAVE_CYCLES
from coherence.simulation import DEFAULT_BACKGROUND_FOOTPRINT, STUDY_CPUS
from rtcommon.validate import InputError, require_bool, require_int
from tracer.rendering.tree_variants import STUDY_TREE_VARIANT
from tracer.scenes.model import MAX_DEPTH

__all__ = ["Experiment", "REPORT_PROCESSES"]

#: Process counts of a report unless told otherwise: 1..16, the study's range.
REPORT_PROCESSES = tuple(range(1, 17))


@dataclass(frozen=True)
class Experiment:
    """The choices of one run of the toolkit, checked once.

    Parameters
    ----------
    scene : str or os.PathLike
        A study scene's name or a .nff/.obj file (a :class:`pathlib.Path` is
        always a file).
    size : int
        Image width and height in pixels, >= 1.
    workload : str
        The tracer imitated (:data:`tracer.rendering.workload.WORKLOADS`).
    tree_variant : str
        The study-era tree rule, by name
        (:data:`tracer.rendering.tree_variants.TREE_VARIANTS`); the default,
        the study's own rule, is the only one a workload other than
        ``study1997`` or a ``kd`` builder other than its median takes.
    kd : str, optional
        kd-tree builder (:data:`tracer.kd.tree.BUILDERS`); None: the
        workload's.
    max_depth : int, optional
        Ray-tree depth, primary = 1, in [1, :data:`tracer.scenes.model.MAX_DEPTH`]; None:
        the scene's. For the ``pathtrace`` workload, the most rays a path
        has besides its shadow rays.
    spp : int
        Samples per pixel of the ``pathtrace`` workload, in [1,
        :data:`tracer.rendering.render.MAX_SPP`]; 1 for the others.
    seed : int
        Key of the ``pathtrace`` workload's random numbers, >= 0.
    mappings : tuple of str or coherence.mappings.Mapping
        Mappings compared, distinct, at least one.
    n_processes : tuple of int
        Process counts, each >= 1; kept sorted without repeats.
    hierarchy : str, path or cachesim.Hierarchy
        Cache hierarchy: a preset, a .toml/.json file or an object.
    layout : str or coherence.layout.MemoryLayout
        Memory layout of the scene's records.
    cost : str or coherence.cost.CostModel
        Cycles per operation and clock rate.
    n_cpus : int
        CPUs of the simulated machine, >= 1.
    background : int
        Always-runnable processes of other users, for real time, >= 0.
    background_footprint : int
        Bytes one time slice of another user's process streams through its
        CPU's caches, >= 0 (:class:`coherence.simulation.Machine`).
    page_placement : str
        How the operating system places the scene's pages in physical
        memory, one of :data:`coherence.page_placement.PAGE_PLACEMENTS`.
    page_seed : int
        Seed of the page placement's colours, >= 0.
    cache_dir : str or os.PathLike, optional
        Trace cache folder (:func:`analyses.traces.cached_trace`).
    dask : str or distributed.Client, optional
        Simulate the runs on that Dask scheduler (:mod:`analyses.cluster`).
    memory_budget : int
        Bytes the whole process may take
        (:mod:`analyses.memory_budget`), at least
        :data:`analyses.memory_budget.MIN_MEMORY_BUDGET`.
    progress : bool
        Progress bars on stderr.
    platform : str or coherence.platforms.Platform, optional
        A machine of today (:data:`coherence.platforms.PLATFORMS`): it sets
        the hierarchy, the cost model and the CPUs (one a hardware thread),
        so ``hierarchy``, ``cost`` and ``n_cpus`` must stay at their
        defaults. The study's runs are simulated on its shared levels,
        processes on its hardware threads interleaving every
        ``interleave_cycles`` (:meth:`study_hierarchy`,
        :mod:`coherence.shared_schedule`); ``page_placement`` must stay
        ``contiguous``. A report's miss map and texture section and a
        what-if's texture columns are runs on those levels too. Its
        process counts are
        :meth:`~coherence.platforms.Platform.default_processes` when a
        caller takes them from it. Under a platform, the trace logs the
        tracer's per-ray data and frame-buffer writes (:meth:`logs_ray_data`).
        None: the study's machine.
    frame_buffer_bytes : int, optional
        Bytes of a frame-buffer pixel, one of
        :data:`coherence.layout.FRAME_BUFFER_BYTES` (3, 4, 16)
        (:meth:`coherence.layout.MemoryLayout.with_frame_buffer`); None: the
        layout's own (12 in ``compact``, 3 in ``alpha1997``).
    interleave_cycles : int
        Under a platform, ``Q`` >= 1: the cycles a hardware thread runs
        before the thread whose clock is lowest takes over
        (:mod:`coherence.shared_schedule`); default
        :data:`coherence.shared_run.DEFAULT_INTERLEAVE_CYCLES`. Without a
        platform it must stay at its default.

    Raises
    ------
    ValueError
        Naming the first field that is wrong (``Experiment.size must be an
        integer >= 1, got 0``).
    """

    scene: object = "balls"
    size: int = 512
    workload: str = "modern"
    tree_variant: str = STUDY_TREE_VARIANT
    kd: str | None = None
    max_depth: int | None = None
    spp: int = 1
    seed: int = 0
    mappings: tuple = tuple(DEFAULT_MAPPINGS)
    n_processes: tuple = REPORT_PROCESSES
    hierarchy: object = DEFAULT_HIERARCHY
    layout: object = DEFAULT_LAYOUT
    cost: object = DEFAULT_COST_MODEL
    n_cpus: int = STUDY_CPUS
    background: int = 4
    background_footprint: int = DEFAULT_BACKGROUND_FOOTPRINT
    page_placement: str = "contiguous"
    page_seed: int = 0
    cache_dir: object = None
    dask: object = None
    memory_budget: int = DEFAULT_MEMORY_BUDGET
    progress: bool = True
    platform: object = None
    frame_buffer_bytes: int | None = None
    interleave_cycles: int = DEFAULT_INTERLEAVE_CYCLES

    def __post_init__(self):
        from coherence.mappings import get_mapping
        from tracer.kd.tree import BUILDERS
        from tracer.rendering.tree_variants import TREE_VARIANTS, workload_with_tree
        from tracer.rendering.workload import WORKLOADS

        if not isinstance(self.scene, (str, os.PathLike)) or not os.fspath(self.scene):
            raise InputError(f"Experiment.scene must be a scene name or a .nff/.obj path, got {self.scene!r}")
        require_int("Experiment.size", self.size, 1)
        _choose("workload", self.workload, WORKLOADS)
        if self.kd is not None:
            _choose("kd", self.kd, BUILDERS)
        _choose("tree_variant", self.tree_variant, TREE_VARIANTS)
        try:
            workload_with_tree(self.workload, self.tree_variant)
        except ValueError as error:
            raise InputError(f"Experiment.tree_variant: {error}") from None
        variant = TREE_VARIANTS[self.tree_variant]
        if self.tree_variant != STUDY_TREE_VARIANT and self.kd_builder() != variant.builder:
            raise InputError(f"Experiment.kd must be None or {variant.builder} for tree_variant {self.tree_variant}, "
                             f"got {self.kd!r}")
        if self.max_depth is not None:
            require_int("Experiment.max_depth", self.max_depth, 1, MAX_DEPTH)
        from tracer.rendering.render import MAX_SPP

        require_int("Experiment.spp", self.spp, 1, MAX_SPP)
        require_int("Experiment.seed", self.seed, 0, 2**63 - 1)
        if self.spp != 1 and WORKLOADS[self.workload].renderer != "pathtrace":
            raise InputError(f"Experiment.spp must be 1 for the {self.workload!r} workload (one sample a pixel), "
                             f"got {self.spp}")
        mappings = (self.mappings,) if isinstance(self.mappings, str) else tuple(self.mappings)
        names = []
        for mapping in mappings:
            try:
                names.append(get_mapping(mapping).name)
            except ValueError as error:
                raise InputError(f"Experiment.mappings: {error}") from None
        if not names or len(set(names)) != len(names):
            raise InputError(f"Experiment.mappings must name at least one mapping, each once; got {names}")
        object.__setattr__(self, "mappings", mappings)
        counts = (self.n_processes,) if isinstance(self.n_processes, int) else tuple(self.n_processes)
        counts = tuple(sorted({require_int("Experiment.n_processes", n, 1) for n in counts}))
        if not counts:
            raise InputError("Experiment.n_processes must hold at least one process count >= 1")
        object.__setattr__(self, "n_processes", counts)
        for name, resolve in (("hierarchy", _hierarchy), ("layout", _layout), ("cost", _cost)):
            try:
                resolve(getattr(self, name))
            except (ValueError, OSError) as error:
                raise InputError(f"Experiment.{name}: {error}") from None
        require_int("Experiment.n_cpus", self.n_cpus, 1)
        require_int("Experiment.interleave_cycles", self.interleave_cycles, 1)
        if self.platform is not None:
            _check_platform(self)
        elif self.interleave_cycles != DEFAULT_INTERLEAVE_CYCLES:
            raise InputError(f"Experiment.interleave_cycles={self.interleave_cycles} applies to a platform's shared "
                             "levels only; give a platform or leave it at its default")
        if self.frame_buffer_bytes is not None:
            from coherence.layout import FRAME_BUFFER_BYTES

            if isinstance(self.frame_buffer_bytes, bool) or self.frame_buffer_bytes not in FRAME_BUFFER_BYTES:
                raise InputError(f"Experiment.frame_buffer_bytes must be None or one of "
                                 f"{', '.join(map(str, FRAME_BUFFER_BYTES))}, got {self.frame_buffer_bytes!r}")
        require_int("Experiment.background", self.background, 0)
        require_int("Experiment.background_footprint", self.background_footprint, 0)
        _choose("page_placement", self.page_placement, PAGE_PLACEMENTS)
        require_int("Experiment.page_seed", self.page_seed, 0)
        if self.cache_dir is not None and not isinstance(self.cache_dir, (str, os.PathLike)):
            raise InputError(f"Experiment.cache_dir must be a folder path or None, got {self.cache_dir!r}")
        if isinstance(self.dask, str) and not self.dask.strip():
            raise InputError("Experiment.dask must be a scheduler address (tcp://host:8786), a Client or None")
        require_int("Experiment.memory_budget", self.memory_budget, MIN_MEMORY_BUDGET)
        require_bool("Experiment.progress", self.progress)

    # the choices as the simulation's objects

    def mapping_objects(self) -> list:
        """The mappings as :class:`coherence.mappings.Mapping` objects, in order."""
        from coherence.mappings import get_mapping

        return [get_mapping(mapping) for mapping in self.mappings]

    def mapping_names(self) -> list[str]:
        return [mapping.name for mapping in self.mapping_objects()]

    def platform_object(self):
        """The :class:`coherence.platforms.Platform`, or None."""
        from coherence.platforms import get_platform

        return None if self.platform is None else get_platform(self.platform)

    def hierarchy_object(self):
        """The :class:`cachesim.Hierarchy` (a preset or file is read again each call); under a
        platform, one hardware thread's view of its levels."""
        platform = self.platform_object()
        return _hierarchy(self.hierarchy) if platform is None else platform.thread_view()

    def recorded_hierarchy(self):
        """The levels a result records as its hierarchy: :meth:`hierarchy_object`, or under a platform the
        levels one hardware thread reaches at their full sizes (which threads share each one is in the
        platform's parameters, :func:`platform_parameters`), not the thread view's cut shares."""
        platform = self.platform_object()
        return self.hierarchy_object() if platform is None else platform.hierarchy.hierarchy

    def study_hierarchy(self):
        """What :func:`coherence.studies.study` simulates on: :meth:`hierarchy_object`, or under a platform its
        shared levels (:class:`coherence.shared_run.SharedLevels` with ``interleave_cycles``)."""
        from coherence.shared_run import SharedLevels

        platform = self.platform_object()
        if platform is None:
            return self.hierarchy_object()
        return SharedLevels(platform.hierarchy, int(self.interleave_cycles))

    def layout_object(self):
        """The :class:`coherence.layout.MemoryLayout`, its frame-buffer pixels ``frame_buffer_bytes`` when set."""
        layout = _layout(self.layout)
        return layout if self.frame_buffer_bytes is None else layout.with_frame_buffer(self.frame_buffer_bytes)

    def logs_ray_data(self) -> bool:
        """Whether the trace logs the tracer's per-ray data and frame buffer: when the workload does
        (``study1997``), or under a platform with Whitted's renderer (the path tracer logs none)."""
        from tracer.rendering.workload import WORKLOADS

        return not isinstance(self.trace_workload(), str) or WORKLOADS[self.workload].log_ray_data

    def trace_workload(self):
        """The workload as :func:`analyses.traces.cached_trace` takes it: its name, or under a platform the
        preset made to log its per-ray data (:func:`analyses.traces.with_ray_data`) when it does not."""
        from analyses.traces import with_ray_data
        from tracer.rendering.workload import WORKLOADS

        preset = WORKLOADS[self.workload]
        logged = with_ray_data(preset, self.platform is not None)
        return self.workload if logged is preset else logged

    def cost_model(self):
        """The :class:`coherence.cost.CostModel` (the platform's under one)."""
        platform = self.platform_object()
        return _cost(self.cost) if platform is None else platform.cost

    def cpus(self) -> int:
        """CPUs of the simulated machine: ``n_cpus``, or the platform's hardware threads."""
        platform = self.platform_object()
        return int(self.n_cpus) if platform is None else platform.n_threads

    def machine(self):
        """The simulated :class:`coherence.simulation.Machine`: ``n_cpus`` CPUs, ``background`` load of
        ``background_footprint`` bytes a slice, pages placed by ``page_placement``."""
        from coherence.page_placement import PagePlacement
        from coherence.simulation import Machine

        return Machine(n_cpus=self.cpus(), background_load=self.background,
                       background_footprint=self.background_footprint,
                       page_placement=PagePlacement(self.page_placement, seed=self.page_seed))

    def kd_builder(self) -> str:
        """``kd``, else the workload's builder."""
        from tracer.rendering.workload import get_workload

        return self.kd or get_workload(self.workload).kd_config.builder

    def tree_variant_used(self) -> str | None:
        """``tree_variant`` when it names the tree built (the ``study1997`` workload's own builder), else None."""
        from tracer.rendering.tree_variants import TREE_VARIANT_WORKLOADS, TREE_VARIANTS

        builds = self.workload in TREE_VARIANT_WORKLOADS and self.kd_builder() == TREE_VARIANTS[self.tree_variant].builder
        return self.tree_variant if builds else None

    def as_parameters(self) -> dict:
        """The choices that decide the results, as plain JSON data.

        ``scene`` (as given), ``size``, ``workload``, ``kd`` (the builder
        used), ``max_depth`` (None: the scene's), ``mappings`` (names),
        ``n_processes``, ``hierarchy`` and ``cost`` (their fields, so a file
        or a custom object is recorded too), ``layout`` (its name),
        ``n_cpus``, ``background_load``, ``background_footprint``,
        ``page_placement``, ``page_seed`` and ``tree_variant``
        (:meth:`tree_variant_used`: None where no variant is built); for a
        path-traced workload also ``spp`` and ``seed``.
        ``cache_dir``, ``dask``, ``memory_budget`` and ``progress`` are
        left out: no result depends on them. Under a platform, ``platform``
        too (:func:`platform_parameters`); without one there is no such key.
        ``frame_buffer_bytes`` only when set.
        """
        platform = self.platform_object()
        extra = {} if platform is None else {"platform": platform_parameters(platform, self.interleave_cycles)}
        if self.frame_buffer_bytes is not None:
            extra["frame_buffer_bytes"] = int(self.frame_buffer_bytes)
        return {"scene": os.fspath(self.scene), "size": int(self.size), "workload": self.workload,
                "kd": self.kd_builder(), "max_depth": self.max_depth, "mappings": self.mapping_names(),
                "n_processes": list(self.n_processes), "hierarchy": self.recorded_hierarchy().to_dict(),
                "layout": self.layout_object().name, "cost": self.cost_model().to_dict(),
                "n_cpus": self.cpus(), "background_load": int(self.background),
                "background_footprint": int(self.background_footprint), "page_placement": self.page_placement,
                "page_seed": int(self.page_seed), "tree_variant": self.tree_variant_used(), **extra,
                **self.path_sampling()}

    def path_sampling(self) -> dict:
        """``{"spp": ..., "seed": ...}`` for a path-traced workload, else empty."""
        from tracer.rendering.workload import WORKLOADS

        if WORKLOADS[self.workload].renderer != "pathtrace":
            return {}
        return {"spp": int(self.spp), "seed": int(self.seed)}


def platform_parameters(platform, interleave_cycles: int = DEFAULT_INTERLEAVE_CYCLES) -> dict:
    """What a run records of its platform: name, machine, clock, source, how shared levels were simulated and
    the interleaving granularity ``Q`` (``interleave_cycles``)."""
    from coherence.platforms import SHARED_LEVELS_NOTE

    machine = platform.hierarchy
    return {"name": platform.name, "n_cores": machine.n_cores, "smt": machine.smt,
            "cores_per_complex": machine.cores_per_complex, "shared_by": list(machine.shared_by),
            "clock_hz": platform.clock_hz, "source": platform.source, "shared_levels": SHARED_LEVELS_NOTE,
            "interleave_cycles": int(interleave_cycles)}


def _check_platform(experiment) -> None:
    """The platform exists and ``hierarchy``, ``cost`` and ``n_cpus`` were left to it."""
    try:
        platform = experiment.platform_object()
    except ValueError as error:
        raise InputError(f"Experiment.platform: {error}") from None
    for field, default in (("hierarchy", DEFAULT_HIERARCHY), ("cost", DEFAULT_COST_MODEL), ("n_cpus", STUDY_CPUS)):
        if getattr(experiment, field) != default:
            raise InputError(f"Experiment.platform {platform.name} sets the hierarchy, the cost and the CPUs: "
                             f"leave Experiment.{field} at its default ({default}), got {getattr(experiment, field)!r}")
    if experiment.page_placement != "contiguous":
        raise InputError(f"Experiment.page_placement={experiment.page_placement!r}: runs on platform "
                         f"{platform.name}'s shared levels take virtual addresses; use contiguous")



def _choose(name: str, value, allowed) -> None:
    if not isinstance(value, str) or value not in allowed:
        raise InputError(f"Experiment.{name} must be one of {', '.join(allowed)}, got {value!r}")


def _hierarchy(value):
    from cachesim import get_hierarchy

    hierarchy = get_hierarchy(value)
    if hierarchy.prefetches:
        raise InputError(f"Experiment.hierarchy: {value} has prefetchers, which the schedule simulation does not "
                         "model yet; use a hierarchy without them ('coherence cachesim' runs them on addresses)")
    return hierarchy


def _layout(value):
    from coherence.layout import get_layout

    return get_layout(value)


def _cost(value):
    from coherence.cost import get_cost_model

    return get_cost_model(value)
