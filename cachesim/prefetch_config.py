"""Configuration of a hardware prefetcher, an option of a cache level.

A :class:`Prefetcher` is the optional ``prefetcher`` field of
:class:`cachesim.CacheLevel`; the kernels that simulate it, and the exact
rules, are in :mod:`cachesim.prefetch`; ``docs/prefetch.md`` gives the models
and their published sources.
"""
from __future__ import annotations

from dataclasses import dataclass

from rtcommon.validate import InputError, require_int

PREFETCH_KINDS = ("next-line", "stride")
#: The accesses that trigger a prefetcher, per kind; the first is the kind's default.
TRIGGERS = {"next-line": ("tagged", "miss", "access"), "stride": ("access", "miss")}
#: Upper bounds of the counts (a prefetcher, not a bulk copy).
MAX_DEGREE = 64
MAX_DISTANCE = 1024
MAX_TABLE_SIZE = 65536


@dataclass(frozen=True)
class Prefetcher:
    """A prefetcher of one cache level.

    Parameters
    ----------
    kind : {"next-line", "stride"}
        ``next-line``: one-block-lookahead sequential prefetching (Smith,
        "Cache memories", ACM Computing Surveys 14(3), 1982): on a trigger
        for line ``x`` of the level, fetch lines ``x + distance`` to
        ``x + distance + degree - 1``. ``stride``: the basic reference
        prediction table of Chen & Baer ("Effective hardware-based data
        prefetching for high-performance processors", IEEE Transactions on
        Computers 44(5), 1995), indexed by a PC-like id per access; from its
        steady state it fetches the lines of ``a + k * stride`` for ``k``
        from ``distance`` to ``distance + degree - 1``, ``a`` the access's
        byte address.
    degree : int
        Lines fetched per trigger, in [1, :data:`MAX_DEGREE`].
    distance : int
        How far ahead the first of them lies: lines (next-line) or strides
        (stride), in [1, :data:`MAX_DISTANCE`].
    trigger : str or None
        Which demand accesses reaching the level trigger (next-line) or
        train (stride) the prefetcher. Next-line: ``"miss"`` (Smith's
        prefetch on miss, the default), ``"access"`` (prefetch always) or
        ``"tagged"`` (on a miss and on the first demand hit of a prefetched
        line). Stride: ``"access"`` (every access, as Chen & Baer's table
        sees every load; the default) or ``"miss"``. None: the kind's default.
    table_size : int
        Entries of the stride prefetcher's table (direct-mapped by the id),
        in [1, :data:`MAX_TABLE_SIZE`]; ignored by next-line.
    """

    kind: str
    degree: int = 1
    distance: int = 1
    trigger: str | None = None
    table_size: int = 64

    def __post_init__(self):
        if not isinstance(self.kind, str) or self.kind.lower() not in PREFETCH_KINDS:
            raise InputError(f"Prefetcher.kind must be one of {', '.join(PREFETCH_KINDS)}; got {self.kind!r}")
        kind = self.kind.lower()
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "degree", require_int("Prefetcher.degree", self.degree, 1, MAX_DEGREE))
        object.__setattr__(self, "distance", require_int("Prefetcher.distance", self.distance, 1, MAX_DISTANCE))
        allowed = TRIGGERS[kind]
        trigger = allowed[0] if self.trigger is None else self.trigger
        if not isinstance(trigger, str) or trigger.lower() not in allowed:
            raise InputError(f"Prefetcher.trigger of a {kind} prefetcher must be one of {', '.join(allowed)}; "
                             f"got {self.trigger!r}")
        object.__setattr__(self, "trigger", trigger.lower())
        object.__setattr__(self, "table_size",
                           require_int("Prefetcher.table_size", self.table_size, 1, MAX_TABLE_SIZE))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "degree": self.degree, "distance": self.distance, "trigger": self.trigger,
                "table_size": self.table_size}

    @classmethod
    def from_dict(cls, data: dict, source: str = "prefetcher") -> "Prefetcher":
        """Build from a table as written by :meth:`to_dict` (``source`` names it in messages)."""
        if not isinstance(data, dict):
            raise InputError(f"{source} must be a table with 'kind', got {type(data).__name__}")
        allowed = {"kind", "degree", "distance", "trigger", "table_size"}
        if set(data) - allowed:
            raise InputError(f"{source}: unknown field(s) {sorted(set(data) - allowed)}; "
                             f"allowed: {', '.join(sorted(allowed))}")
        if "kind" not in data:
            raise InputError(f"{source}: missing field 'kind' (one of {', '.join(PREFETCH_KINDS)})")
        try:
            return cls(**data)
        except ValueError as error:
            raise InputError(f"{source}: {error}") from None
