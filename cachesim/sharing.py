"""Cache levels shared by hardware threads: the machine around a hierarchy.

A :class:`SharedHierarchy` is a :class:`~cachesim.config.Hierarchy` (the
levels one hardware thread sees, from L1 to the last level) placed on a
machine of ``n_cores`` cores with ``smt`` hardware threads each, the cores
grouped in core complexes of ``cores_per_complex``. Each level says which
threads share one instance of it (``shared_by``):

- ``"thread"``: one instance per hardware thread (private);
- ``"core"``: one per core, shared by its ``smt`` threads;
- ``"complex"``: one per core complex;
- ``"machine"``: one for the whole machine.

Hardware thread ``t`` runs on core ``t // smt``, which belongs to complex
``core // cores_per_complex``; so the instance of a level that serves thread
``t`` is ``t // threads_per_instance(level)``. A level may be shared no less
widely than the level above it (an L2 per core below an L1 per thread, not
the reverse): each instance then serves whole instances of the levels above.

Saved to TOML or JSON like a hierarchy, with the machine's fields at the top
and ``shared_by`` in each level's table::

    name = "two-core"
    n_cores = 2
    smt = 2
    cores_per_complex = 2
    memory_latency = 300.0
    inclusion = "non-inclusive"

    [[levels]]
    name = "L1"
    size = 32768
    line_size = 64
    assoc = 8
    shared_by = "core"

Simulated by :func:`cachesim.multicore.simulate_threads`.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from cachesim.config import Hierarchy, read_config_table, write_config_table
from rtcommon.validate import InputError, require_int

#: The sharing scopes of a level, narrowest first.
SHARING = ("thread", "core", "complex", "machine")
#: Limits of the machine's counts (a simulated machine, not a cluster).
MAX_CORES = 1024
MAX_SMT = 8
_MACHINE_FIELDS = ("n_cores", "smt", "cores_per_complex")


@dataclass(frozen=True)
class SharedHierarchy:
    """A cache hierarchy on a machine of several cores, each level private or shared.

    Parameters
    ----------
    hierarchy : Hierarchy
        The levels one hardware thread sees, their memory latency and inclusion.
    n_cores : int
        Cores of the machine, in [1, :data:`MAX_CORES`].
    smt : int
        Hardware threads per core, in [1, :data:`MAX_SMT`].
    cores_per_complex : int or None
        Cores per core complex, dividing ``n_cores``; None: one complex of all cores.
    shared_by : tuple of str or None
        Per level of ``hierarchy``, one of :data:`SHARING`; never narrower
        than the level above. None: every level private to a thread.
    """

    hierarchy: Hierarchy
    n_cores: int = 1
    smt: int = 1
    cores_per_complex: int | None = None
    shared_by: tuple[str, ...] | None = None

    def __post_init__(self):
        if not isinstance(self.hierarchy, Hierarchy):
            raise InputError(f"SharedHierarchy.hierarchy must be a Hierarchy, got {type(self.hierarchy).__name__}")
        n_cores = require_int("SharedHierarchy.n_cores", self.n_cores, 1, MAX_CORES)
        object.__setattr__(self, "n_cores", n_cores)
        object.__setattr__(self, "smt", require_int("SharedHierarchy.smt", self.smt, 1, MAX_SMT))
        per_complex = n_cores if self.cores_per_complex is None else self.cores_per_complex
        per_complex = require_int("SharedHierarchy.cores_per_complex", per_complex, 1, n_cores)
        if n_cores % per_complex:
            raise InputError(f"SharedHierarchy.cores_per_complex ({per_complex}) must divide n_cores ({n_cores})")
        object.__setattr__(self, "cores_per_complex", per_complex)
        n_levels = len(self.hierarchy.levels)
        shared_by = ("thread",) * n_levels if self.shared_by is None else self.shared_by
        if isinstance(shared_by, str) or not isinstance(shared_by, (list, tuple)) or len(shared_by) != n_levels:
            raise InputError(f"SharedHierarchy.shared_by must be a sequence of {n_levels} scopes (one per level "
                             f"{', '.join(self.hierarchy.level_names)}), got {shared_by!r}")
        scopes = []
        for name, scope in zip(self.hierarchy.level_names, shared_by):
            if not isinstance(scope, str) or scope.lower() not in SHARING:
                raise InputError(f"SharedHierarchy.shared_by of {name} must be one of {', '.join(SHARING)}; "
                                 f"got {scope!r}")
            scopes.append(scope.lower())
        names = self.hierarchy.level_names
        for below in range(1, n_levels):
            if SHARING.index(scopes[below]) < SHARING.index(scopes[below - 1]):
                raise InputError(f"SharedHierarchy.shared_by: {names[below]} ({scopes[below]}) may not be shared "
                                 f"less widely than {names[below - 1]} above it ({scopes[below - 1]})")
        object.__setattr__(self, "shared_by", tuple(scopes))

    @property
    def name(self) -> str:
        """The hierarchy's name."""
        return self.hierarchy.name

    @property
    def n_threads(self) -> int:
        """Hardware threads of the machine: ``n_cores * smt``."""
        return self.n_cores * self.smt

    def threads_per_instance(self, level: int) -> int:
        """Hardware threads one instance of ``level`` (an index) serves."""
        scope = self.shared_by[level]
        if scope == "thread":
            return 1
        if scope == "core":
            return self.smt
        if scope == "complex":
            return self.smt * self.cores_per_complex
        return self.n_threads

    def n_instances(self, level: int) -> int:
        """Instances of ``level`` (an index) on the machine."""
        return self.n_threads // self.threads_per_instance(level)

    def instance_of(self, level: int, thread: int) -> int:
        """The instance of ``level`` that serves hardware thread ``thread``."""
        return thread // self.threads_per_instance(level)

    def to_dict(self) -> dict:
        """The hierarchy's table with the machine's fields and each level's ``shared_by``."""
        table = self.hierarchy.to_dict()
        levels = [{**level, "shared_by": scope} for level, scope in zip(table.pop("levels"), self.shared_by)]
        return {"name": table.pop("name"), "n_cores": self.n_cores, "smt": self.smt,
                "cores_per_complex": self.cores_per_complex, **table, "levels": levels}

    @classmethod
    def from_dict(cls, data: dict, source: str = "shared hierarchy") -> "SharedHierarchy":
        """Build from a mapping as written by :meth:`to_dict`; ``source`` names it in error messages.

        A level without ``shared_by`` is private to a thread; a table without
        the machine's fields is a machine of one core and one thread.
        """
        if not isinstance(data, dict):
            raise InputError(f"{source}: expected a table with 'levels', got {type(data).__name__}")
        rest = {key: value for key, value in data.items() if key not in _MACHINE_FIELDS}
        levels = rest.get("levels")
        scopes = None
        if isinstance(levels, list) and all(isinstance(level, dict) for level in levels):
            scopes = tuple(level.get("shared_by", "thread") for level in levels)
            rest["levels"] = [{key: value for key, value in level.items() if key != "shared_by"}
                              for level in levels]
        hierarchy = Hierarchy.from_dict(rest, source=source)
        try:
            return cls(hierarchy, shared_by=scopes, **{key: data[key] for key in _MACHINE_FIELDS if key in data})
        except ValueError as error:
            raise InputError(f"{source}: {error}") from None

    def save(self, path: str | os.PathLike) -> Path:
        """Write to ``.toml`` or ``.json`` (chosen by suffix), atomically."""
        return write_config_table(path, self.to_dict(), "shared hierarchy")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SharedHierarchy":
        """Read a shared hierarchy written by :meth:`save` (or by hand)."""
        return cls.from_dict(read_config_table(path, "shared hierarchy"), source=str(path))


def private(hierarchy: Hierarchy, n_cores: int = 1, smt: int = 1) -> SharedHierarchy:
    """``hierarchy`` private to each hardware thread of a machine of ``n_cores`` x ``smt`` threads."""
    return SharedHierarchy(hierarchy, n_cores=n_cores, smt=smt)


def get_shared_hierarchy(source) -> SharedHierarchy:
    """A SharedHierarchy as given, a Hierarchy made one (one core, one thread), or a ``.toml``/``.json`` file."""
    if isinstance(source, SharedHierarchy):
        return source
    if isinstance(source, Hierarchy):
        return private(source)
    path = Path(str(source))
    if path.suffix.lower() in (".toml", ".json"):
        return SharedHierarchy.load(path)
    raise InputError(f"unknown shared hierarchy {str(source)!r}: give a SharedHierarchy or a .toml/.json file")
