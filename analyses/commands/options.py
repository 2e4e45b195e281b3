"""Options shared by several subcommands, as argparse parent parsers.

An option that several subcommands take is defined once here, with one
meaning and one help text; a subcommand names the parents it needs when it
adds its parser (``parents=[model_options(), ...]``). Where a default must
differ between subcommands (image size, process counts, background load),
the parent takes it as an argument together with the sentence that explains
the difference, so ``--help`` always says why.

Choices come from the registries that define them (hierarchy presets in
:mod:`cachesim.config`, memory layouts and cost models in :mod:`coherence`,
kd-tree builders in :mod:`tracer.kd.tree`, mappings, study scenes) through
:class:`RegistryNames`. Those modules load numba, which takes seconds, so the
names are looked up only when argparse needs them (to check a value or to
print a subcommand's help): ``coherence --help`` stays instant.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from importlib import import_module
from rtcommon.validate import InputError

__all__ = ["RegistryNames", "HelpFormatter", "check_at_least", "scene_options", "hierarchy_options", "model_options",
           "tree_options", "size_options", "cache_options", "mappings_options",
           "machine_options", "dask_options", "SCENES", "MAPPINGS", "DEFAULT_MAPPINGS", "HIERARCHIES", "LAYOUTS", "COST_MODELS", "KD_BUILDERS", "PLACEMENTS", "SCHEDULERS", "PAGE_PLACEMENTS",
           "WORKLOADS", "TREE_VARIANTS", "workload_options", "workload_from_args", "EXPERIMENT_OPTIONS",
           "experiment_from_args", "PLATFORMS", "platform_options", "ExplicitStore", "given", "check_platform_options"]


class RegistryNames(Sequence):
    """The names of a registry, imported on first use.

    Parameters
    ----------
    module : str
        Module that holds the registry, e.g. ``"coherence.layout"``.
    attribute : str
        Its dict or tuple of names, e.g. ``"LAYOUTS"``.

    Notes
    -----
    Usable as argparse ``choices`` (argparse only iterates and tests
    membership) as long as the option has a ``metavar``: without one, argparse
    would list the choices, and so import the registry, when the option is
    added. ``str()`` gives the names comma-separated, for help texts.
    """

    def __init__(self, module: str, attribute: str):
        self.module = module
        self.attribute = attribute
        self._names: tuple[str, ...] | None = None

    @property
    def names(self) -> tuple[str, ...]:
        if self._names is None:
            self._names = tuple(getattr(import_module(self.module), self.attribute))
        return self._names

    def __getitem__(self, index):
        return self.names[index]

    def __len__(self) -> int:
        return len(self.names)

    def __contains__(self, name) -> bool:
        return name in self.names

    def __str__(self) -> str:
        return ", ".join(str(name) for name in self.names)


SCENES = RegistryNames("tracer.scenes.catalog", "NAMED_SCENES")
PAPER_SCENES = RegistryNames("tracer.scenes.catalog", "PAPER_SCENES")
MAPPINGS = RegistryNames("coherence.mappings", "MAPPINGS")
DEFAULT_MAPPINGS = RegistryNames("coherence.mappings", "DEFAULT_MAPPINGS")
HIERARCHIES = RegistryNames("cachesim.config", "PRESETS")
LAYOUTS = RegistryNames("coherence.layout", "LAYOUTS")
COST_MODELS = RegistryNames("coherence.cost", "COST_MODELS")
KD_BUILDERS = RegistryNames("tracer.kd.tree", "BUILDERS")
WORKLOADS = RegistryNames("tracer.rendering.workload", "WORKLOADS")
TREE_VARIANTS = RegistryNames("tracer.rendering.tree_variants", "TREE_VARIANTS")
PLACEMENTS = RegistryNames("coherence.simulation", "PLACEMENTS")
SCHEDULERS = RegistryNames("coherence.simulation", "SCHEDULERS")
PAGE_PLACEMENTS = RegistryNames("coherence.page_placement", "PAGE_PLACEMENTS")
PLATFORMS = RegistryNames("coherence.platforms", "PLATFORMS")
PAPER_PROCESSES = RegistryNames("analyses.paper_study", "DEFAULT_PROCESSES")


class StudyTimes:
    """The study's sequential S times in words (``"Balls 345.8 s, ..."``), read from :mod:`tracer.scenes.study` when printed."""

    def __str__(self) -> str:
        from tracer.scenes.study import STUDY_SCENES

        return ", ".join(f"{scene.name.capitalize()} {scene.sequential_seconds} s" for scene in STUDY_SCENES.values())


STUDY_TIMES = StudyTimes()


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the epilog's layout and lets help texts name registries.

    Besides argparse's own ``%(default)s`` and ``%(choices)s``, a help text
    may say ``%(scenes)s``, ``%(paper_scenes)s``, ``%(mappings)s``, ``%(default_mappings)s``,
    ``%(hierarchies)s`` or ``%(paper_processes)s``: the registry's names,
    looked up when the help is printed. A description or epilog may say the
    same, and ``%(study_times)s`` (the study's sequential S times, from
    :mod:`tracer.scenes.study`).
    """

    _REGISTRIES = {"scenes": SCENES, "paper_scenes": PAPER_SCENES, "mappings": MAPPINGS, "default_mappings": DEFAULT_MAPPINGS,
                   "hierarchies": HIERARCHIES, "paper_processes": PAPER_PROCESSES, "study_times": STUDY_TIMES}

    def _format_text(self, text):
        for key, names in self._REGISTRIES.items():
            if f"%({key})s" in text:
                text = text.replace(f"%({key})s", str(names))
        return super()._format_text(text)

    def _expand_help(self, action):
        help_text = self._get_help_string(action)
        wanted = {key: names for key, names in self._REGISTRIES.items() if f"%({key})" in help_text}
        if not wanted:
            return super()._expand_help(action)
        # argparse formats with vars(action); a copy carrying the names leaves the parser untouched
        expanded = argparse.Namespace(**vars(action))
        expanded.__dict__.update({key: str(names) for key, names in wanted.items()})
        return super()._expand_help(expanded)


def check_at_least(args: argparse.Namespace, **minimum: int) -> None:
    """Raise :class:`rtcommon.validate.InputError` naming the option if an integer option is below its minimum.

    Runs inside a subcommand, before any work, so the error is printed as
    ``coherence CMD: error: --size must be >= 1, got 0`` and exits with 2.
    Options left at ``None`` (meaning "the default") are not checked.
    """
    for name, low in minimum.items():
        value = getattr(args, name)
        values = value if isinstance(value, list) else [value]
        for item in values:
            if item is not None and item < low:
                raise InputError(f"--{name.replace('_', '-')} must be >= {low}, got {item}")


class ExplicitStore(argparse.Action):
    """Stores the value like ``store`` and records that the option was given (see :func:`given`)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        explicit = set(getattr(namespace, "explicit_options", ()))
        setattr(namespace, "explicit_options", explicit | {self.dest})


def given(args: argparse.Namespace, dest: str) -> bool:
    """Whether the option stored in ``dest`` was given on the command line (an :class:`ExplicitStore` option)."""
    return dest in getattr(args, "explicit_options", ())


#: Options a platform sets, by ``args`` attribute: combining one with ``--platform`` is an error.
PLATFORM_SETS = {"hierarchy": "--hierarchy", "cost": "--cost", "cpus": "--cpus"}


def check_platform_options(args: argparse.Namespace) -> None:
    """Raise :class:`rtcommon.validate.InputError` when ``--platform`` is combined with an option it sets."""
    platform = getattr(args, "platform", None)
    if platform is None:
        if getattr(args, "interleave_cycles", None) is not None:
            raise InputError("--interleave-cycles applies to a platform's shared levels; give --platform NAME")
        return
    if getattr(args, "interleave_cycles", None) is not None and args.interleave_cycles < 1:
        raise InputError(f"--interleave-cycles must be an integer >= 1, got {args.interleave_cycles}")
    for dest, option in PLATFORM_SETS.items():
        if given(args, dest):
            raise InputError(f"--platform {platform} sets the hierarchy, the cost model and the CPUs; drop {option}")


def _parent() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(add_help=False, formatter_class=HelpFormatter)


def scene_options(default: str | None = None) -> argparse.ArgumentParser:
    """The positional ``SCENE``: a study scene's name or a .nff/.obj path (optional if ``default``)."""
    parent = _parent()
    optional = {} if default is None else {"nargs": "?", "default": default}
    parent.add_argument("scene", metavar="SCENE", **optional,
                        help="a study scene (%(scenes)s) or a .nff/.obj path"
                             + ("" if default is None else f" (default {default})"))
    return parent


def hierarchy_options() -> argparse.ArgumentParser:
    """``--hierarchy NAME|FILE``: a cachesim preset or a .toml/.json file."""
    parent = _parent()
    parent.add_argument("--hierarchy", default="alpha21164", metavar="NAME|FILE", action=ExplicitStore,
                        help="cache hierarchy: a preset (%(hierarchies)s) or a .toml/.json file "
                             "(default %(default)s)")
    return parent


def model_options() -> argparse.ArgumentParser:
    """The simulated machine's memory: ``--hierarchy``, ``--layout``, ``--cost``.

    Their defaults, like ``--cpus``'s, are :class:`analyses.experiment.Experiment`'s, written out
    because importing it here would load numba before ``--help``; tests/test_experiment.py ties
    each to the Experiment's.
    """
    parent = argparse.ArgumentParser(add_help=False, formatter_class=HelpFormatter, parents=[hierarchy_options()])
    parent.add_argument("--layout", default="compact", choices=LAYOUTS, metavar="NAME",
                        help="memory layout of scene records: %(choices)s (default %(default)s)")
    parent.add_argument("--cost", default="alpha8400", choices=COST_MODELS, metavar="NAME", action=ExplicitStore,
                        help="cycles per operation and clock rate: %(choices)s (default %(default)s)")
    return argparse.ArgumentParser(add_help=False, formatter_class=HelpFormatter, parents=[parent, platform_options()])


def platform_options(processes: str = "process counts default to 1..2 x hardware threads, at most 32"
                     ) -> argparse.ArgumentParser:
    """``--platform NAME``: a machine of today (:data:`coherence.platforms.PLATFORMS`); ``processes`` says
    what it does to the subcommand's process counts."""
    parent = _parent()
    parent.add_argument("--platform", choices=PLATFORMS, metavar="NAME",
                        help="a machine of today: %(choices)s (docs/platforms.md). It sets the hierarchy, the cost "
                             "model and the CPUs (one per hardware thread), so it is not combined with --hierarchy, "
                             f"--cost or --cpus; {processes}. Processes run on its hardware threads and interleave "
                             "at its shared levels, coherence on (default: the study's machine)")
    parent.add_argument("--interleave-cycles", type=int, metavar="Q", default=None,
                        help="with --platform: a hardware thread runs Q cycles (or to its pixel's end) before the "
                             "thread whose clock is lowest takes over; 1 interleaves access by access "
                             "(default 1000, within 1%% of Q=1 in L3 misses: docs/multicore.md)")
    return parent


def tree_options(depth_help: str = "ray-tree depth, primary = 1 (default: the scene's)",
                 kd_default: str | None = "sah",
                 kd_why: str = "sah") -> argparse.ArgumentParser:
    """How the scene is traced: ``--kd`` builder and ``--max-depth`` of the ray tree.

    ``kd_default`` None leaves the tree to ``--workload`` (:func:`workload_options`);
    ``kd_why`` says what the default is.
    """
    parent = _parent()
    parent.add_argument("--kd", default=kd_default, choices=KD_BUILDERS, metavar="BUILDER",
                        help="kd-tree builder: %(choices)s; sah = surface area heuristic, median = spatial "
                             f"median like a 1990s BSP (default {kd_why})")
    parent.add_argument("--max-depth", type=int, metavar="N", default=None, help=depth_help)
    return parent


def workload_options(default: str = "modern", why: str = "") -> argparse.ArgumentParser:
    """``--workload NAME``: the tracer imitated (:data:`tracer.rendering.workload.WORKLOADS`); ``why`` explains the default.

    Also ``--tree-variant NAME``, the study-era tree rule
    (:data:`tracer.rendering.tree_variants.TREE_VARIANTS`); left at None,
    the workload's own tree.
    """
    parent = _parent()
    parent.add_argument("--workload", default=default, choices=WORKLOADS, metavar="NAME",
                        help="tracer imitated: %(choices)s; modern = today's SAH tracer, study1997 = the "
                             "study's mid-1990s BSP tracer (one median-tree rule for every scene, shadow rays "
                             "that find the nearest hit, its own per-ray data logged), pathtrace = a path "
                             "tracer on today's tree (--spp, --seed) (default %(default)s"
                             + (f": {why})" if why else ")"))
    parent.add_argument("--tree-variant", choices=TREE_VARIANTS, metavar="NAME",
                        help="tree rule of the study1997 workload, named d<depth limit>-l<leaf size>-box-<axis "
                             "rule>-todepth-nearest: %(choices)s (default: the study's own rule, the first; "
                             "see docs/unknowns.md, tree_variant)")
    parent.add_argument("--spp", type=int, metavar="N", default=None,
                        help="samples per pixel of the pathtrace workload (default 1); its bounce limit is "
                             "--max-depth")
    parent.add_argument("--seed", type=int, metavar="N", default=None,
                        help="seed of the pathtrace workload's counter-based random numbers (default 0)")
    return parent


def workload_from_args(args: argparse.Namespace):
    """The :class:`tracer.rendering.workload.Workload` of ``--workload`` with the tree of ``--tree-variant``.

    Raises
    ------
    InputError
        A tree variant for another workload, or beside ``--kd``.
    """
    from tracer.rendering.tree_variants import workload_with_tree

    variant = getattr(args, "tree_variant", None)
    if variant is not None and getattr(args, "kd", None):
        raise InputError(f"--tree-variant {variant} sets the tree; drop --kd {args.kd}")
    try:
        return workload_with_tree(args.workload, variant)
    except ValueError as error:
        raise InputError(f"--tree-variant: {error}") from None


def size_options(default: int | None = 512, why: str = "the study's 512x512") -> argparse.ArgumentParser:
    """``--size N``, the image's width and height; ``why`` explains the default."""
    parent = _parent()
    parent.add_argument("--size", type=int, default=default, metavar="N",
                        help=f"image width and height in pixels (default: {why})")
    return parent


def cache_options() -> argparse.ArgumentParser:
    """``--cache DIR``, where rendered traces are kept between runs."""
    parent = _parent()
    parent.add_argument("--cache", metavar="DIR",
                        help="trace cache folder (default: $COHERENCE_CACHE, else ~/.cache/raytrace-coherence)")
    return parent


def dask_options(what: str = "the runs") -> argparse.ArgumentParser:
    """``--dask ADDRESS``: send ``what`` to a Dask scheduler (:mod:`analyses.cluster`)."""
    parent = _parent()
    parent.add_argument("--dask", metavar="ADDRESS",
                        help=f"simulate {what} on a Dask scheduler (tcp://host:8786); every worker must read the "
                             "trace cache (--cache) under the same path. Same results as a local run")
    return parent


def memory_budget_options(runs_at_once: int = 1) -> argparse.ArgumentParser:
    """``--memory-budget MB``: what the process may take in memory (:mod:`analyses.memory_budget`).

    ``runs_at_once`` is the fewest runs the subcommand holds at once, which
    the least budget it accepts (:func:`memory_budget_bytes`) sets aside.
    """
    parent = _parent()
    parent.add_argument("--memory-budget", type=float, metavar="MB", default=2048.0,
                        help="memory the whole process may take, in MB (default 2048). About 640 MB for the "
                             "process and 96 bytes a pixel for each run at once are set aside; of the rest, half "
                             "holds the records a render keeps before writing them out, and then three quarters "
                             "(at most 1 GiB) the line addresses the runs share and a quarter the trace's pages "
                             "resident while runs read it, so a trace of any length streams from disk. Results "
                             "do not depend on it")
    parent.set_defaults(memory_budget_runs=runs_at_once)
    return parent


#: The largest ``--memory-budget``, in MB (an exbibyte: more than any machine has).
MAX_MEMORY_BUDGET_MB = 2 ** 40


def memory_budget_bytes(args: argparse.Namespace) -> int:
    """``--memory-budget`` in bytes.

    Raises
    ------
    InputError
        NaN; above :data:`MAX_MEMORY_BUDGET_MB`; or below the least budget
        (:func:`analyses.memory_budget.least_memory_budget`) for the image of
        ``--size`` and the runs the subcommand holds at once, naming it in
        whole MB.
    """
    from analyses.memory_budget import least_memory_budget

    value = args.memory_budget
    if value != value:
        raise InputError(f"--memory-budget must be a number of MB, got {value}")
    if value > MAX_MEMORY_BUDGET_MB:
        raise InputError(f"--memory-budget must be at most {MAX_MEMORY_BUDGET_MB} MB, got {value:g}")
    size = getattr(args, "size", None) or 0
    least = -(-least_memory_budget(size * size, getattr(args, "memory_budget_runs", 1)) >> 20)
    if value < least:
        raise InputError(f"--memory-budget must be at least {least} MB{f' at --size {size}' if size else ''}, "
                         f"got {value:g}")
    return int(value * 2**20)


#: Option (``args`` attribute) -> :class:`analyses.experiment.Experiment` field it sets.
EXPERIMENT_OPTIONS = {"scene": "scene", "size": "size", "workload": "workload", "tree_variant": "tree_variant",
                      "kd": "kd", "max_depth": "max_depth", "spp": "spp", "seed": "seed",
                      "mappings": "mappings", "processes": "n_processes", "hierarchy": "hierarchy", "layout": "layout",
                      "cost": "cost", "cpus": "n_cpus", "background": "background",
                      "background_footprint": "background_footprint", "page_placement": "page_placement",
                      "page_seed": "page_seed", "cache": "cache_dir", "dask": "dask", "platform": "platform",
                      "interleave_cycles": "interleave_cycles"}


def experiment_from_args(args: argparse.Namespace, base=None, **fields):
    """The :class:`analyses.experiment.Experiment` a subcommand's options ask for.

    Every option of :data:`EXPERIMENT_OPTIONS` (and ``--memory-budget``) the
    subcommand has and that is not None replaces ``base``'s field (default
    ``Experiment()``, the report's choices); ``fields`` replace last.
    Progress bars are shown when stderr is a terminal.

    Raises
    ------
    InputError
        Naming the field or option that is out of range, or ``--platform``
        beside an option it sets.
    """
    import sys
    from dataclasses import replace

    from analyses.experiment import Experiment

    check_platform_options(args)

    choices = {field: getattr(args, option) for option, field in EXPERIMENT_OPTIONS.items()
               if getattr(args, option, None) is not None}
    if "mappings" in choices:
        choices["mappings"] = tuple(choices["mappings"])
    if getattr(args, "memory_budget", None) is not None:
        choices["memory_budget"] = memory_budget_bytes(args)
    choices["progress"] = sys.stderr.isatty()
    return replace(base if base is not None else Experiment(), **{**choices, **fields})


def mappings_options(why: str = "") -> argparse.ArgumentParser:
    """``--mappings NAME ...``; left at None, the subcommand uses :data:`coherence.mappings.DEFAULT_MAPPINGS`.

    ``why`` replaces the default's description when a subcommand's default
    comes from elsewhere (a what-if study file).
    """
    parent = _parent()
    parent.add_argument("--mappings", nargs="+", metavar="NAME",
                        help="mappings to compare, any of %(mappings)s (default: "
                             f"{why or '%(default_mappings)s'})")
    return parent


def machine_options(*, processes, processes_help: str, background: int, background_why: str,
                    cpus: bool = True) -> argparse.ArgumentParser:
    """The simulated machine: ``--processes``, ``--cpus``, ``--background`` (and its footprint) and page placement.

    Parameters
    ----------
    processes : list of int or None
        Default process counts (None: the subcommand chooses, as
        ``processes_help`` says).
    background : int
        Default always-runnable processes of other users.
    background_why : str
        Why this subcommand's default background load is what it is.
    cpus : bool
        Whether ``--cpus`` is offered (the paper fixes the study's 8).
    """
    parent = _parent()
    parent.add_argument("--processes", type=int, nargs="+", default=processes, metavar="N", help=processes_help,
                        action=ExplicitStore)
    if cpus:
        parent.add_argument("--cpus", type=int, default=8, metavar="C", action=ExplicitStore,
                            help="CPUs of the simulated machine (default 8, the study's AlphaServer 8400)")
    parent.add_argument("--background", type=int, default=background, metavar="B",
                        help="always-runnable processes of other users, for real time "
                             f"(default {background}: {background_why})")
    parent.add_argument("--background-footprint", type=int, default=None, metavar="BYTES",
                        help="bytes one slice of another user's process streams through its CPU's caches "
                             "(default 1 MiB: about 100 MB/s for a 10 ms slice; see coherence.simulation.Machine)")
    parent.add_argument("--page-placement", default="contiguous", choices=PAGE_PLACEMENTS, metavar="NAME",
                        help="which physical pages the operating system gives the scene's 8 KB pages, which decides "
                             "conflicts in the physically indexed S- and B-cache: %(choices)s (default %(default)s: "
                             "physical = virtual; see coherence.page_placement)")
    parent.add_argument("--page-seed", type=int, default=0, metavar="N",
                        help="seed of bin-hopping's first colour and of random's colours (default %(default)s)")
    return parent
