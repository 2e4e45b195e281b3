"""The grid language of what-if studies: parameter names, values from text, and a point's cache levels.

A grid names the parameters to vary and their values (``--grid key=v1,v2`` on
the command line, a ``[grid]`` table in a study file); a point is one
combination. Parameters (names as in flags and TOML files):

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

The study's unknowns that ``coherence robustness`` samples
(:data:`coherence.unknowns.UNKNOWNS`), by the same names; each sets one
field of the point's :class:`~analyses.experiment.Experiment`
(:data:`UNKNOWN_FIELDS`, :func:`point_experiment`) and takes any value that
field takes, the documented plausible range (``docs/unknowns.md``) and
beyond:

======================== ======================================================
``background_footprint`` bytes one time slice of another user's process
                         streams through its CPU's caches (``256KB``)
``page_placement``       ``contiguous``, ``colouring``, ``bin-hopping``,
                         ``random`` (seeded by the base's ``page_seed``)
``memory_image``         the memory layout: ``compact``, ``alpha1997``,
                         ``malloc1997`` (a grid varies it or ``layout``)
``tree_variant``         the study-era tree rule
                         (:data:`tracer.rendering.tree_variants.TREE_VARIANTS`;
                         ``study1997`` workload); one trace per variant
======================== ======================================================

Under a platform, also its variants (:data:`PLATFORM_VARIANTS`, see
:mod:`analyses.whatif_platform`).
"""
from __future__ import annotations

import re
from dataclasses import replace

from cachesim import Hierarchy
from coherence.layout import LAYOUTS
from coherence.page_placement import PAGE_PLACEMENTS
from rtcommon.validate import InputError
from tracer.rendering.tree_variants import TREE_VARIANTS

__all__ = ["LEVEL_FIELDS", "SIMPLE", "UNKNOWN_FIELDS", "PLATFORM_VARIANTS", "PLATFORM_PARAMETERS", "check_parameter",
           "parse_value", "parse_grid_flag", "parse_switch", "point_levels", "point_experiment"]

LEVEL_FIELDS = ("size", "line_size", "assoc", "latency", "policy")
SIMPLE = ("memory_latency", "hierarchy", "compute_scale", "cost", "layout", "texture_layout", "scene_size",
          "n_processes", "n_cpus", "background", "line_size", "frame_buffer_bytes")
#: Grid parameters named as the unknowns of :data:`coherence.unknowns.UNKNOWNS`, each to the
#: :class:`~analyses.experiment.Experiment` field it sets.
UNKNOWN_FIELDS = {"background_footprint": "background_footprint", "page_placement": "page_placement",
                  "memory_image": "layout", "tree_variant": "tree_variant"}
#: The values each categorical one of :data:`UNKNOWN_FIELDS` takes.
_UNKNOWN_CHOICES = {"page_placement": PAGE_PLACEMENTS, "memory_image": tuple(LAYOUTS),
                    "tree_variant": tuple(TREE_VARIANTS)}
#: Grid parameters that vary the base's platform (:meth:`coherence.platforms.Platform.variant`).
PLATFORM_VARIANTS = ("cores", "smt", "l3_size", "prefetch")
#: Grid parameters a platform sets, so a study under one may not vary them.
PLATFORM_PARAMETERS = ("hierarchy", "cost", "n_cpus")
_SWITCHES = {"on": True, "true": True, "off": False, "false": False}
_UNITS = {"": 1, "B": 1, "KB": 1024, "K": 1024, "MB": 1024**2, "M": 1024**2, "GB": 1024**3, "G": 1024**3}


def check_parameter(key: str) -> None:
    """Raise ``ValueError`` naming the allowed parameters unless ``key`` is one."""
    if key in SIMPLE or key in UNKNOWN_FIELDS or key in PLATFORM_VARIANTS:
        return
    level, _, attribute = key.partition(".")
    if attribute in LEVEL_FIELDS and level:
        return
    names = (*SIMPLE, *UNKNOWN_FIELDS, *PLATFORM_VARIANTS)
    raise InputError(f"unknown what-if parameter {key!r}: use one of {', '.join(names)} or "
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
    check_parameter(key)
    return key, [parse_value(value) for value in values.split(",")]


def parse_switch(key: str, value, other: str = ""):
    """``on``/``off`` (or ``true``/``false``, any case) of parameter ``key`` as a bool; other values as given.

    ``other`` names what else ``key`` takes in the error (``" or threads per core"``).
    """
    if not isinstance(value, str):
        return value
    if value.lower() not in _SWITCHES:
        raise InputError(f"what-if parameter {key} must be on or off{other}, got {value!r}")
    return _SWITCHES[value.lower()]


def point_levels(hierarchy: Hierarchy, point: dict) -> Hierarchy:
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


def point_experiment(base, point: dict):
    """``base`` (an :class:`~analyses.experiment.Experiment`) with the point's :data:`UNKNOWN_FIELDS` set.

    Raises
    ------
    ValueError
        Naming the parameter and the values it takes: a value it does not
        take, ``memory_image`` beside ``layout``, or a value the base does
        not allow (a tree variant beside a workload other than
        ``study1997``, a page placement under a platform).
    """
    if "memory_image" in point and "layout" in point:
        raise InputError("what-if parameters memory_image and layout both set the memory layout; vary one of them")
    experiment = base
    for key, field in UNKNOWN_FIELDS.items():
        if key not in point:
            continue
        value = point[key]
        if key == "background_footprint":
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise InputError(f"what-if parameter background_footprint must be bytes, an integer >= 0 "
                                 f"(262144, 256KB), got {value!r}")
        elif value not in _UNKNOWN_CHOICES[key]:
            raise InputError(f"what-if parameter {key} must be one of {', '.join(_UNKNOWN_CHOICES[key])}, "
                             f"got {value!r}")
        try:
            experiment = replace(experiment, **{field: value})
        except ValueError as error:
            raise InputError(f"what-if parameter {key}={value}: {error}") from None
    return experiment
