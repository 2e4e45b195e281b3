"""Mappings: recipes for splitting an image among processes.

A :class:`Mapping` is a recipe (frozen, validated parameters); its
:meth:`Mapping.build` turns it into a concrete
:class:`~coherence.distribution.Distribution` of a ``width x height`` image
among ``n_processes`` (tasks of ordered pixels, assigned statically or handed
out dynamically; see :mod:`coherence.distribution`).

Built-in mappings: the study's five (docs/design.md, "The study's
experiment"), :class:`Strip` "S", :class:`Pixel` "P", :class:`Row` "R",
:class:`Block` "B" and :class:`DynamicBlock` "DB", plus space-filling-curve
orders (:class:`CurveSegments`, :class:`CurveTiles`) and
users' own (:class:`CustomMapping`, :func:`from_owner_image`). :data:`MAPPINGS`
holds a default instance of each built-in by name; :func:`get_mapping` looks
one up.

This module is the registry and names every public mapping; the recipes live
in :mod:`coherence.mapping_base`, :mod:`coherence.study_mappings`,
:mod:`coherence.curve_mappings` and :mod:`coherence.custom_mappings`.
"""
from __future__ import annotations

from .curve_mappings import CurveSegments, CurveTiles
from .custom_mappings import CustomMapping, from_owner_image
from .distribution import Distribution
from .mapping_base import DEFAULT_DISPATCH_CYCLES, Mapping
from .study_mappings import Block, DynamicBlock, Pixel, Row, Strip
from rtcommon.validate import InputError

__all__ = [
    "DEFAULT_DISPATCH_CYCLES",
    "DEFAULT_MAPPINGS",
    "MAPPINGS",
    "Block",
    "CurveSegments",
    "CurveTiles",
    "CustomMapping",
    "Distribution",
    "DynamicBlock",
    "Mapping",
    "Pixel",
    "Row",
    "Strip",
    "from_owner_image",
    "get_mapping",
]

# --------------------------------------------------------------------------
# registry

MAPPINGS: dict[str, Mapping] = {
    m.name: m
    for m in (
        Strip(),
        Pixel(),
        Row(),
        Block(),
        DynamicBlock(),
        CurveSegments("hilbert"),
        CurveSegments("morton"),
        CurveSegments("serpentine"),
        CurveTiles(),
    )
}


#: The study's five mappings, in its order: the default of every comparison
#: (the command line, :func:`coherence.studies.study`, reports, the paper, what-ifs).
DEFAULT_MAPPINGS = ("S", "P", "R", "B", "DB")


def get_mapping(name_or_mapping) -> Mapping:
    """A :class:`Mapping` given itself or a name of :data:`MAPPINGS`.

    Names match exactly first, then ignoring case (``"db"`` is ``"DB"``).
    """
    if isinstance(name_or_mapping, Mapping):
        return name_or_mapping
    if isinstance(name_or_mapping, str):
        if name_or_mapping in MAPPINGS:
            return MAPPINGS[name_or_mapping]
        folded = {k.lower(): v for k, v in MAPPINGS.items()}
        if name_or_mapping.lower() in folded:
            return folded[name_or_mapping.lower()]
    raise InputError(f"unknown mapping {name_or_mapping!r}; choose one of {', '.join(MAPPINGS)} or pass a Mapping")
