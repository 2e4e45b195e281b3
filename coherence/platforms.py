"""Today's machines from public documentation: a shared cache hierarchy, a core count, SMT and a cost model.

A :class:`Platform` holds a :class:`cachesim.sharing.SharedHierarchy` (the
levels one hardware thread sees, the cores, SMT threads per core, core
complexes and which threads share each level) and a
:class:`coherence.cost.CostModel` of its own name and clock. The presets in
:data:`PLATFORMS` are one current AMD core complex pair (a Ryzen 9 7950X,
Zen 4), one current Intel server part (a Xeon Platinum 8480, Sapphire
Rapids) and one machine with a large shared L2 (the performance cluster of
an Apple M1). Every figure, its source or the words "not checked" with the
assumption made, and the derivation of the cost models are in
``docs/platforms.md``; a test reads that page's tables back and compares
them with these presets, so page and code cannot drift.

A run under a platform simulates its processes on the hardware threads of
:attr:`Platform.hierarchy`, interleaved at the shared levels
(:mod:`coherence.shared_schedule`). :meth:`Platform.thread_view` is one
hardware thread with its own copy of every level, a shared level cut to the
thread's share of its capacity (its size divided by the threads sharing
it): no run simulates on it; it is the private hierarchy
:meth:`analyses.experiment.Experiment.hierarchy_object` gives under a
platform, and ``benchmarks/platform_views.py`` compares it with the shared
levels.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from cachesim.config import CacheLevel, Hierarchy
from cachesim.prefetch_config import Prefetcher
from cachesim.sharing import MAX_CORES, MAX_SMT, SharedHierarchy
from coherence.cost import COST_MODELS, CostModel
from rtcommon.validate import InputError, require_bool, require_int, require_number

__all__ = ["MAX_DEFAULT_PROCESSES", "PLATFORMS", "PREFETCHERS_ON", "Platform", "get_platform", "SHARED_LEVELS_NOTE"]

#: The most processes a platform's default process counts go to.
MAX_DEFAULT_PROCESSES = 32

#: What runs under a platform say about their shared levels, in their parameters.
SHARED_LEVELS_NOTE = ("shared levels interleaved: processes run on the hardware threads and every access goes "
                      "through the one state of the machine's caches (write-invalidate coherence on), the thread "
                      "whose clock is lowest running interleave_cycles at a time, the levels' prefetchers, if any, "
                      "trained by every access; the report's miss map and texture section and a what-if's texture "
                      "columns are such runs too, the report's miss-ratio curves take no machine (fully "
                      "associative LRU of one process's stream); see docs/platforms.md")

#: The prefetchers of a platform variant with prefetching on (:meth:`Platform.variant`), for its first
#: levels in order: next-line on a miss at L1 (Smith 1982), a stride table at L2 fetching two strides
#: ahead (Chen & Baer 1995). Generic models of the kinds today's cores document, not any vendor's tuned
#: prefetchers (``docs/platforms.md``).
PREFETCHERS_ON = (Prefetcher("next-line", degree=1, distance=1, trigger="miss"),
                  Prefetcher("stride", degree=2, distance=1, trigger="access"))

_KB = 1024
_MB = 1024 * 1024


@dataclass(frozen=True)
class Platform:
    """A machine of today: its shared cache hierarchy, cost model and clock, and where its figures come from.

    Parameters
    ----------
    name : str
        Registry name (``zen4-7950x``).
    hierarchy : SharedHierarchy
        Levels, latencies in cycles, cores, SMT, core complexes and sharing.
    cost : CostModel
        Cycles per operation; its ``clock_hz`` is the platform's clock.
    clock_hz : float
        Clock rate the latencies in cycles are counted at, > 0.
    source : str
        Where the figures and their sources are written down (a section of
        ``docs/platforms.md``).
    """

    name: str
    hierarchy: SharedHierarchy
    cost: CostModel
    clock_hz: float
    source: str

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputError(f"Platform.name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.hierarchy, SharedHierarchy):
            raise InputError(f"Platform.hierarchy must be a SharedHierarchy, got {type(self.hierarchy).__name__}")
        if not isinstance(self.cost, CostModel):
            raise InputError(f"Platform.cost must be a CostModel, got {type(self.cost).__name__}")
        clock = require_number("Platform.clock_hz", self.clock_hz, 0)
        if clock <= 0 or clock != self.cost.clock_hz:
            raise InputError(f"Platform.clock_hz must be > 0 and equal its cost model's clock_hz "
                             f"({self.cost.clock_hz}), got {self.clock_hz}")
        if not isinstance(self.source, str) or not self.source.strip():
            raise InputError(f"Platform.source must say where its figures come from, got {self.source!r}")

    @property
    def n_threads(self) -> int:
        """Hardware threads: cores x SMT threads per core."""
        return self.hierarchy.n_threads

    def default_processes(self) -> tuple[int, ...]:
        """Process counts a run takes unless told: 1 .. 2 x hardware threads, at most :data:`MAX_DEFAULT_PROCESSES`."""
        return tuple(range(1, min(2 * self.n_threads, MAX_DEFAULT_PROCESSES) + 1))

    def thread_view(self) -> Hierarchy:
        """One hardware thread's private view: each level cut to the thread's share of its capacity.

        A level shared by ``k`` threads keeps its line size, ways and
        latency and gets ``size // k`` bytes, rounded down to whole sets
        (at least one). The levels' prefetchers are left out. Named
        ``<platform>-thread``. No run under a platform simulates on it (they
        run on :attr:`hierarchy`); it is what
        :meth:`analyses.experiment.Experiment.hierarchy_object` returns under
        a platform, and ``benchmarks/platform_views.py`` measures how far its
        misses are from the shared levels'.
        """
        machine = self.hierarchy
        levels = []
        for index, level in enumerate(machine.hierarchy.levels):
            sharing = machine.threads_per_instance(index)
            set_bytes = level.line_size * level.ways
            size = max(level.size // sharing // set_bytes, 1) * set_bytes
            levels.append(replace(level, size=size, prefetcher=None))
        return replace(machine.hierarchy, levels=tuple(levels), name=f"{self.name}-thread")

    def variant(self, *, cores: int | None = None, smt=None, l3_size: int | None = None,
                prefetch: bool | None = None) -> "Platform":
        """This platform changed for a what-if study; every choice left None stays the platform's.

        Parameters
        ----------
        cores : int, optional
            Cores, in [1, :data:`cachesim.sharing.MAX_CORES`]. Core complexes
            keep their size; fewer cores than a complex make one complex of
            them all, and more must fill whole complexes.
        smt : bool or int, optional
            Hardware threads per core: True keeps the platform's, False makes
            one; an int sets it, in [1, :data:`cachesim.sharing.MAX_SMT`].
        l3_size : int, optional
            Bytes of the level named ``L3``, the whole shared instance (a thread's
            share follows from it in :meth:`thread_view`).
        prefetch : bool, optional
            True: the prefetchers of :data:`PREFETCHERS_ON` on the first
            levels; False: none (the presets have none).

        Returns
        -------
        Platform
            Named ``<name>[cores=8,smt=1,...]`` after the choices that change
            it; the same platform when none does.

        Raises
        ------
        ValueError
            Naming the choice and what it may be.
        """
        machine, changes = self.hierarchy, []
        levels = list(machine.hierarchy.levels)
        n_cores, per_complex, threads = machine.n_cores, machine.cores_per_complex, machine.smt
        if cores is not None and cores != n_cores:
            n_cores = require_int("Platform.variant: cores", cores, 1, MAX_CORES)
            per_complex = min(per_complex, n_cores)
            if n_cores % per_complex:
                raise InputError(f"Platform.variant: cores must fill whole core complexes of {per_complex} on "
                                 f"{self.name}, got {n_cores}")
            changes.append(f"cores={n_cores}")
        if smt is not None:
            threads = (machine.smt if smt else 1) if isinstance(smt, bool) else \
                require_int("Platform.variant: smt", smt, 1, MAX_SMT)
            if threads != machine.smt:
                changes.append(f"smt={threads}")
        if l3_size is not None:
            names = machine.hierarchy.level_names
            if "L3" not in names:
                raise InputError(f"Platform.variant: {self.name} has no L3 (levels {', '.join(names)}); l3_size "
                                 "applies to platforms with one")
            index = names.index("L3")
            try:
                levels[index] = replace(levels[index], size=l3_size)
            except ValueError as error:
                raise InputError(f"Platform.variant: l3_size: {error}") from None
            if levels[index].size != machine.hierarchy.levels[index].size:
                changes.append(f"l3={levels[index].size}")
        if prefetch is not None and require_bool("Platform.variant: prefetch", prefetch):
            for index, prefetcher in enumerate(PREFETCHERS_ON[:len(levels)]):
                levels[index] = replace(levels[index], prefetcher=prefetcher)
            changes.append("prefetch")
        if not changes:
            return self
        name = f"{self.name}[{','.join(changes)}]"
        hierarchy = replace(machine.hierarchy, levels=tuple(levels), name=name)
        shared = SharedHierarchy(hierarchy, n_cores=n_cores, smt=threads, cores_per_complex=per_complex,
                                 shared_by=machine.shared_by)
        return replace(self, name=name, hierarchy=shared)

    def to_dict(self) -> dict:
        """Name, clock, source, the shared hierarchy's table and the cost model's fields (JSON-ready)."""
        return {"name": self.name, "clock_hz": self.clock_hz, "source": self.source,
                "hierarchy": self.hierarchy.to_dict(), "cost": self.cost.to_dict()}


def _levels(*rows) -> tuple[CacheLevel, ...]:
    """Cache levels from (name, size, ways, line, latency) rows, LRU."""
    return tuple(CacheLevel(name, size, line, ways, "lru", latency=latency) for name, size, ways, line, latency in rows)


def zen4_7950x() -> Platform:
    """AMD Ryzen 9 7950X (Zen 4): 16 cores in two core complexes of 8, SMT2, 5.7 GHz.

    Per core 32 KB 8-way L1D and 1 MB 8-way L2 (shared by the core's two
    threads); 32 MB 16-way L3 per complex. Figures and sources:
    ``docs/platforms.md``, section zen4-7950x.
    """
    hierarchy = Hierarchy(_levels(("L1", 32 * _KB, 8, 64, 4), ("L2", 1 * _MB, 8, 64, 14),
                                  ("L3", 32 * _MB, 16, 64, 58)),
                          memory_latency=456, inclusion="non-inclusive", name="zen4-7950x")
    machine = SharedHierarchy(hierarchy, n_cores=16, smt=2, cores_per_complex=8,
                              shared_by=("core", "core", "complex"))
    return Platform("zen4-7950x", machine, COST_MODELS["zen4-7950x"](), 5.7e9, "docs/platforms.md#zen4-7950x")


def xeon_8480() -> Platform:
    """Intel Xeon Platinum 8480 (Sapphire Rapids): 56 cores, SMT2, 3.8 GHz.

    Per core 48 KB 12-way L1D and 2 MB L2 (shared by the core's two
    threads); 105 MB L3 (1.875 MB a core) shared by the whole chip.
    Figures and sources: ``docs/platforms.md``, section xeon-8480.
    """
    hierarchy = Hierarchy(_levels(("L1", 48 * _KB, 12, 64, 5), ("L2", 2 * _MB, 16, 64, 16),
                                  ("L3", 105 * _MB, 15, 64, 114)),
                          memory_latency=418, inclusion="non-inclusive", name="xeon-8480")
    machine = SharedHierarchy(hierarchy, n_cores=56, smt=2, shared_by=("core", "core", "machine"))
    return Platform("xeon-8480", machine, COST_MODELS["xeon-8480"](), 3.8e9, "docs/platforms.md#xeon-8480")


def apple_m1() -> Platform:
    """Apple M1, performance cluster: 4 Firestorm cores, no SMT, 3.2 GHz.

    Per core 128 KB L1D; 12 MB L2 shared by the four cores (the system
    level cache beyond it is not modelled). Figures and sources:
    ``docs/platforms.md``, section apple-m1.
    """
    hierarchy = Hierarchy(_levels(("L1", 128 * _KB, 8, 128, 3), ("L2", 12 * _MB, 12, 128, 16)),
                          memory_latency=320, inclusion="non-inclusive", name="apple-m1")
    machine = SharedHierarchy(hierarchy, n_cores=4, smt=1, shared_by=("thread", "machine"))
    return Platform("apple-m1", machine, COST_MODELS["apple-m1"](), 3.2e9, "docs/platforms.md#apple-m1")


#: Platform presets by name.
PLATFORMS = {"zen4-7950x": zen4_7950x, "xeon-8480": xeon_8480, "apple-m1": apple_m1}


def get_platform(name_or_platform) -> Platform:
    """A preset by name (:data:`PLATFORMS`) or a Platform as given."""
    if isinstance(name_or_platform, Platform):
        return name_or_platform
    try:
        return PLATFORMS[str(name_or_platform)]()
    except KeyError:
        raise InputError(f"unknown platform {name_or_platform!r}: use one of {', '.join(PLATFORMS)}") from None
