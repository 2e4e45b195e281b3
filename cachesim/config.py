"""Cache hierarchy configuration: frozen, validated, saved to TOML or JSON.

A :class:`Hierarchy` is a tuple of :class:`CacheLevel` from the level next to
the CPU (L1) down to the last level before memory, plus the memory latency and
an inclusion policy. Any number of sets is allowed (96 KB 3-way with 64-byte
lines has 512 sets; 96 KB 2-way would have 768). Line sizes are powers of two
and may only grow towards memory.
"""
from __future__ import annotations

import json
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from cachesim.prefetch_config import Prefetcher
from cachesim.sets import MAX_LEVELS
from cachesim.tlb_config import Tlb, alpha21164_dtb
from rtcommon.files import read_text_file, write_text_atomic
from rtcommon.validate import InputError, require_bool, require_int, require_number, require_power_of_two

POLICIES = ("lru", "fifo", "random")
INCLUSIONS = ("non-inclusive", "inclusive", "exclusive")


@dataclass(frozen=True)
class CacheLevel:
    """One cache level.

    Parameters
    ----------
    name : str
        Label used in tables (``"L1"``).
    size : int
        Capacity in bytes; a multiple of ``line_size * assoc``.
    line_size : int
        Line (block) size in bytes, a power of two.
    assoc : int or "full"
        Ways per set; 1 is direct-mapped, ``"full"`` is fully associative.
    policy : {"lru", "fifo", "random"}
        Replacement policy. ``"random"`` evicts a way drawn from a hash of
        ``seed`` and the access clock, so runs are reproducible and a stream
        run in pieces evicts exactly as in one run.
    latency : float
        Hit latency in CPU cycles.
    seed : int
        Seed of the random replacement policy (ignored otherwise).
    write_allocate : bool
        Whether a write miss fills this level. False models a write-through,
        read-allocate cache such as the 21164 D-cache: the write passes on to
        the next level and leaves this one unchanged. A write hit is served
        like a read either way (see :mod:`cachesim.by_access`).
    prefetcher : Prefetcher or None
        A hardware prefetcher of this level (:mod:`cachesim.prefetch`), or
        None for none (the default: demand fetching only).
    """

    name: str
    size: int
    line_size: int
    assoc: int | str = 1
    policy: str = "lru"
    latency: float = 1.0
    seed: int = 0
    write_allocate: bool = True
    prefetcher: Prefetcher | None = None

    def __post_init__(self):
        owner = f"CacheLevel({self.name!r})" if isinstance(self.name, str) else "CacheLevel"
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputError(f"CacheLevel.name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "size", require_int(f"{owner}.size", self.size, 1))
        object.__setattr__(self, "line_size", require_int(f"{owner}.line_size", self.line_size, 1))
        require_power_of_two(f"{owner}.line_size", self.line_size)
        if self.line_size > self.size:
            raise InputError(f"{owner}.line_size ({self.line_size}) must not exceed size ({self.size})")
        if isinstance(self.assoc, str):
            if self.assoc.lower() != "full":
                raise InputError(f"{owner}.assoc must be a positive integer or 'full', got {self.assoc!r}")
            object.__setattr__(self, "assoc", "full")
        else:
            object.__setattr__(self, "assoc", require_int(f"{owner}.assoc", self.assoc, 1))
        ways = self.ways
        if self.size % (self.line_size * ways) != 0:
            raise InputError(
                f"{owner}.size ({self.size}) must be a multiple of line_size * assoc "
                f"({self.line_size} * {ways} = {self.line_size * ways}) so that the sets are whole"
            )
        if not isinstance(self.policy, str) or self.policy.lower() not in POLICIES:
            raise InputError(f"{owner}.policy must be one of {', '.join(POLICIES)}; got {self.policy!r}")
        object.__setattr__(self, "policy", self.policy.lower())
        object.__setattr__(self, "latency", require_number(f"{owner}.latency", self.latency, 0, "cycles"))
        object.__setattr__(self, "seed", require_int(f"{owner}.seed", self.seed, 0))
        object.__setattr__(self, "write_allocate", require_bool(f"{owner}.write_allocate", self.write_allocate))
        if self.prefetcher is not None and not isinstance(self.prefetcher, Prefetcher):
            raise InputError(f"{owner}.prefetcher must be a Prefetcher or None, got {type(self.prefetcher).__name__}")

    @property
    def ways(self) -> int:
        """Number of ways (lines per set)."""
        return self.size // self.line_size if self.assoc == "full" else int(self.assoc)

    @property
    def n_sets(self) -> int:
        """Number of sets (any positive integer, not only powers of two)."""
        return self.size // (self.line_size * self.ways)

    @property
    def n_lines(self) -> int:
        """Capacity in lines."""
        return self.size // self.line_size

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "size": self.size,
            "line_size": self.line_size,
            "assoc": self.assoc,
            "policy": self.policy,
            "latency": self.latency,
            "seed": self.seed,
            "write_allocate": self.write_allocate,
            **({"prefetcher": self.prefetcher.to_dict()} if self.prefetcher is not None else {}),
        }


@dataclass(frozen=True)
class Hierarchy:
    """A private cache hierarchy of one CPU.

    Two rules decide results where simulators differ (more in
    ``docs/cache_rules.md``):

    - **Fills run from the lowest level up.** After a miss, the levels that
      missed are filled from the one nearest memory to the first level. In
      an inclusive hierarchy a lower level's eviction thus back-invalidates
      the levels above before they take the new line, so an upper level
      whose set lost a line to back-invalidation fills that empty way
      instead of evicting its own least recent line.
    - **A write goes down as a write.** A write that misses a level goes on
      to the next as a write (counted in ``write_accesses`` there), also
      below a level that allocates on writes; a level with
      ``write_allocate=False`` is then left unchanged by it. Dinero IV
      instead has a write-allocating level fetch the line from the level
      below with a read, which that level would count as a read and fill.

    Parameters
    ----------
    levels : tuple of CacheLevel
        From the level next to the CPU to the last level before memory.
    memory_latency : float
        Cycles to serve an access that misses every level.
    inclusion : {"non-inclusive", "inclusive", "exclusive"}
        ``non-inclusive``: a miss fills every level that missed; levels evict
        independently. ``inclusive``: the same fills, and a line evicted from
        a lower level is invalidated in every level above it
        (back-invalidation); a lower level smaller than one above it is
        allowed (what-if grids ask for it) and then caps what the upper one
        can keep. ``exclusive``: a line lives in one level at most;
        misses fill only the first level, its victims move one level down, and
        a hit in a lower level moves the line up to the first level.
    name : str
        Label for reports.
    tlb : Tlb or None
        A data TLB looked up on every access, or None for none.
    """

    levels: tuple[CacheLevel, ...]
    memory_latency: float = 100.0
    inclusion: str = "non-inclusive"
    name: str = "custom"
    tlb: Tlb | None = None

    def __post_init__(self):
        levels = tuple(self.levels) if isinstance(self.levels, (list, tuple)) else None
        if not levels:
            raise InputError("Hierarchy.levels must be a non-empty sequence of CacheLevel")
        if len(levels) > MAX_LEVELS:
            raise InputError(f"Hierarchy.levels may hold at most {MAX_LEVELS} levels, got {len(levels)}")
        for index, level in enumerate(levels):
            if not isinstance(level, CacheLevel):
                raise InputError(f"Hierarchy.levels[{index}] must be a CacheLevel, got {type(level).__name__}")
        object.__setattr__(self, "levels", levels)
        names = [level.name for level in levels]
        if len(set(names)) != len(names):
            raise InputError(f"Hierarchy.levels must have distinct names, got {names}")
        object.__setattr__(self, "memory_latency", require_number("Hierarchy.memory_latency", self.memory_latency, 0, "cycles"))
        if not isinstance(self.inclusion, str) or self.inclusion.lower() not in INCLUSIONS:
            raise InputError(f"Hierarchy.inclusion must be one of {', '.join(INCLUSIONS)}; got {self.inclusion!r}")
        object.__setattr__(self, "inclusion", self.inclusion.lower())
        for upper, lower in zip(levels, levels[1:]):
            if lower.line_size < upper.line_size:
                raise InputError(
                    f"Hierarchy: line_size may only grow towards memory, but {lower.name} has "
                    f"{lower.line_size} B lines below {upper.name} with {upper.line_size} B"
                )
            if self.inclusion == "inclusive" and upper.write_allocate and not lower.write_allocate:
                raise InputError(
                    f"Hierarchy: in an inclusive hierarchy a level that allocates on writes ({upper.name}) "
                    f"cannot sit above one that does not ({lower.name}): the line it takes would not be below it"
                )
            if self.inclusion == "exclusive" and lower.line_size != upper.line_size:
                raise InputError(
                    f"Hierarchy: exclusive levels must share one line size; {upper.name} has "
                    f"{upper.line_size} B and {lower.name} {lower.line_size} B"
                )
        if self.inclusion == "exclusive":
            for level in levels:
                if level.prefetcher is not None:
                    raise InputError(f"Hierarchy: prefetchers are modelled in non-inclusive and inclusive "
                                     f"hierarchies only; {level.name} of this exclusive one has one")
                if not level.write_allocate:
                    raise InputError(f"Hierarchy: exclusive levels must allocate on writes; "
                                     f"{level.name} has write_allocate=False")
        if not isinstance(self.name, str):
            raise InputError(f"Hierarchy.name must be a string, got {self.name!r}")
        if self.tlb is not None and not isinstance(self.tlb, Tlb):
            raise InputError(f"Hierarchy.tlb must be a Tlb or None, got {type(self.tlb).__name__}")

    @property
    def level_names(self) -> list[str]:
        return [level.name for level in self.levels]

    @property
    def prefetches(self) -> bool:
        """Whether any level has a prefetcher."""
        return any(level.prefetcher is not None for level in self.levels)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "memory_latency": self.memory_latency,
            "inclusion": self.inclusion,
            "levels": [level.to_dict() for level in self.levels],
            **({"tlb": self.tlb.to_dict()} if self.tlb is not None else {}),
        }

    @classmethod
    def from_dict(cls, data: dict, source: str = "hierarchy") -> "Hierarchy":
        """Build from a mapping as written by :meth:`to_dict`.

        ``source`` names the file or object in error messages.
        """
        if not isinstance(data, dict):
            raise InputError(f"{source}: expected a table with 'levels', got {type(data).__name__}")
        unknown = set(data) - {"name", "memory_latency", "inclusion", "levels", "tlb"}
        if unknown:
            raise InputError(f"{source}: unknown field(s) {sorted(unknown)}; "
                             "allowed: name, memory_latency, inclusion, levels, tlb")
        raw_levels = data.get("levels")
        if not isinstance(raw_levels, list) or not raw_levels:
            raise InputError(f"{source}: 'levels' must be a non-empty list of tables")
        levels = []
        allowed = {"name", "size", "line_size", "assoc", "policy", "latency", "seed", "write_allocate", "prefetcher"}
        for index, raw in enumerate(raw_levels):
            where = f"{source}: levels[{index}]"
            if not isinstance(raw, dict):
                raise InputError(f"{where} must be a table")
            extra = set(raw) - allowed
            if extra:
                raise InputError(f"{where}: unknown field(s) {sorted(extra)}; allowed: {', '.join(sorted(allowed))}")
            missing = {"name", "size", "line_size"} - set(raw)
            if missing:
                raise InputError(f"{where}: missing field(s) {sorted(missing)}")
            if raw.get("prefetcher") is not None:
                raw = {**raw, "prefetcher": Prefetcher.from_dict(raw["prefetcher"], f"{where}: prefetcher")}
            try:
                levels.append(CacheLevel(**raw))
            except ValueError as error:
                raise InputError(f"{where}: {error}") from None
        kwargs = {key: data[key] for key in ("name", "memory_latency", "inclusion") if key in data}
        if data.get("tlb") is not None:
            raw = data["tlb"]
            allowed_tlb = {"name", "entries", "page_size", "policy", "miss_cycles"}
            if not isinstance(raw, dict):
                raise InputError(f"{source}: 'tlb' must be a table")
            if set(raw) - allowed_tlb:
                raise InputError(f"{source}: tlb: unknown field(s) {sorted(set(raw) - allowed_tlb)}; "
                                 f"allowed: {', '.join(sorted(allowed_tlb))}")
            missing = {"entries", "page_size", "miss_cycles"} - set(raw)
            if missing:
                raise InputError(f"{source}: tlb: missing field(s) {sorted(missing)}")
            try:
                kwargs["tlb"] = Tlb(**raw)
            except ValueError as error:
                raise InputError(f"{source}: tlb: {error}") from None
        try:
            return cls(levels=tuple(levels), **kwargs)
        except ValueError as error:
            raise InputError(f"{source}: {error}") from None

    def save(self, path: str | os.PathLike) -> Path:
        """Write to ``.toml`` or ``.json`` (chosen by suffix), atomically."""
        return write_config_table(path, self.to_dict(), "hierarchy")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Hierarchy":
        """Read a hierarchy written by :meth:`save` (or by hand)."""
        return cls.from_dict(read_config_table(path, "hierarchy"), source=str(path))


def read_config_table(path: str | os.PathLike, what: str) -> dict:
    """The table of a ``.toml`` or ``.json`` configuration file (``what`` names it in messages).

    Raises
    ------
    FileNotFoundError
        No such file.
    InputError
        Another suffix, or text that is not valid TOML or JSON (with the line).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such {what} file")
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise InputError(f"{path}: {what} files must end in .toml or .json")
    text = read_text_file(path, f"a {suffix.lstrip('.').upper()} {what}")
    try:
        return tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"{path}: not valid TOML: {error}") from None
    except json.JSONDecodeError as error:
        raise InputError(f"{path}:{error.lineno}:{error.colno}: not valid JSON: {error.msg}") from None


def write_config_table(path: str | os.PathLike, table: dict, what: str) -> Path:
    """Write ``table`` to a ``.toml`` or ``.json`` file (chosen by suffix), atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".toml":
        import tomli_w

        text = tomli_w.dumps(table)
    elif suffix == ".json":
        text = json.dumps(table, indent=2) + "\n"
    else:
        raise InputError(f"{path}: {what} files must end in .toml or .json")
    write_text_atomic(path, text)
    return path


def alpha21164() -> Hierarchy:
    """The Alpha 21164 of the AlphaServer 8400, per CPU, as its manuals describe it.

    - L1, the D-cache: 8 KB direct-mapped, 32-byte lines, write-through and
      read-allocate (``write_allocate=False``), kept a subset of the S-cache;
    - L2, the S-cache: 96 KB 3-way (3 sets of 512 blocks), 64-byte lines,
      write-back and write-allocate;
    - L3, the B-cache: 4 MB direct-mapped, 64-byte lines, a superset of both.

    Sources: the AlphaServer 8200/8400 technical manual for the three
    caches (docs/design.md, "The simulated machine"); the D-cache facts (a
    write-through, read-allocate, direct-mapped cache of 32-byte blocks, kept
    a subset of the S-cache) also read in Digital's manual EK-SWRA2-IG,
    chapter 4 "Memory Subsystem", section 4.1.2. The B-cache being a
    superset of the D-cache and S-cache makes the hierarchy ``inclusive``: a
    line evicted from the S-cache or B-cache is invalidated in every level
    above it. :func:`alpha21164_noninclusive` is the same machine without
    that rule, for comparison.

    Replacement: the D-cache and B-cache are direct-mapped, so only the
    S-cache has a choice. Its policy is modelled as LRU. The manual text we
    could consult here (searches of the 21164 hardware reference manual and
    the AlphaServer 8400 manual) does not state the S-cache's replacement
    rule; LRU is an assumption, flagged as such, and ``policy="random"`` is
    available to test its weight.

    Dirty write-backs are not modelled (see :mod:`cachesim.by_access`).
    Latencies 2 / 8 / 12 cycles and 80 for memory are approximate defaults.
    """
    return Hierarchy(
        levels=(
            CacheLevel("L1", 8 * 1024, 32, 1, "lru", latency=2, write_allocate=False),
            CacheLevel("L2", 96 * 1024, 64, 3, "lru", latency=8),
            CacheLevel("L3", 4 * 1024 * 1024, 64, 1, "lru", latency=12),
        ),
        memory_latency=80,
        inclusion="inclusive",
        name="alpha21164",
    )


def alpha21164_noninclusive() -> Hierarchy:
    """:func:`alpha21164` without inclusion: levels evict independently.

    The model of the 21164 used before the manuals were checked; kept to show
    what inclusion changes. For a stream of reads it gives exactly the
    counts of the earlier ``alpha21164`` preset.
    """
    inclusive = alpha21164()
    return Hierarchy(inclusive.levels, memory_latency=inclusive.memory_latency, inclusion="non-inclusive",
                     name="alpha21164-noninclusive")


def alpha21164_with_dtb() -> Hierarchy:
    """:func:`alpha21164` with its data TLB (:func:`cachesim.tlb_config.alpha21164_dtb`)."""
    machine = alpha21164()
    return Hierarchy(machine.levels, memory_latency=machine.memory_latency, inclusion=machine.inclusion,
                     name="alpha21164-dtb", tlb=alpha21164_dtb())


def modern() -> Hierarchy:
    """A current desktop core, for what-if studies (values are typical, not one product).

    L1 data 32 KB 8-way; L2 1 MB 16-way; L3 32 MB 16-way (modelled as private
    to the core); 64-byte lines everywhere; latencies 4 / 14 / 50 cycles and
    300 cycles for memory.
    """
    return Hierarchy(
        levels=(
            CacheLevel("L1", 32 * 1024, 64, 8, "lru", latency=4),
            CacheLevel("L2", 1024 * 1024, 64, 16, "lru", latency=14),
            CacheLevel("L3", 32 * 1024 * 1024, 64, 16, "lru", latency=50),
        ),
        memory_latency=300,
        name="modern",
    )


PRESETS = {"alpha21164": alpha21164, "alpha21164-noninclusive": alpha21164_noninclusive,
           "alpha21164-dtb": alpha21164_with_dtb, "modern": modern}

#: The hierarchy a run simulates unless told otherwise: the study's Alpha 21164 (:func:`alpha21164`).
DEFAULT_HIERARCHY = "alpha21164"


def get_hierarchy(name_or_path: str | os.PathLike | Hierarchy) -> Hierarchy:
    """A preset by name (``alpha21164``, ``alpha21164-noninclusive``, ``alpha21164-dtb``,
    ``modern``), a file path, or a Hierarchy."""
    if isinstance(name_or_path, Hierarchy):
        return name_or_path
    key = str(name_or_path)
    if key in PRESETS:
        return PRESETS[key]()
    path = Path(key)
    if path.suffix.lower() in (".toml", ".json"):
        return Hierarchy.load(path)
    raise InputError(f"unknown hierarchy {key!r}: use a preset ({', '.join(PRESETS)}) or a .toml/.json file")

