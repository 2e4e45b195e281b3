"""What-if studies on a machine of today: a grid point's platform variant and the shared levels it runs on.

Under a platform (base ``platform``), a grid may vary its variants
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
useful and useless (:data:`PREFETCH_SUFFIXES`; 0 at points without
prefetchers). On a textured scene the texture columns come from the same
runs: the texel record kind's reads and misses at each level summed over
its instances (:func:`analyses.whatif.shared_texture_columns`), a level's
misses the processes' own, as in the report's texture section.
"""
from __future__ import annotations

from dataclasses import replace

from analyses.whatif_grid import PLATFORM_VARIANTS, parse_switch, point_levels
from rtcommon.validate import InputError

__all__ = ["PLATFORM_TIMES", "PREFETCH_SUFFIXES", "platform_variant", "shared_levels"]

#: Ends of the per-level prefetch columns of a row under a platform with prefetchers
#: (:data:`coherence.shared_run.PREFETCH_RUN_COLUMNS`); 0 at points without them.
PREFETCH_SUFFIXES = ("_prefetches_issued", "_prefetches_useful", "_prefetches_useless")

#: Columns a row under a platform adds beside the efficiency decomposition: the slowest process's user
#: seconds, the run's real seconds and its memory cycles summed over processes.
PLATFORM_TIMES = ("user_seconds_max", "real_seconds", "memory_cycles")


def platform_variant(study, point: dict):
    """The base's platform changed by the point's :data:`~analyses.whatif_grid.PLATFORM_VARIANTS` (None without a
    platform).

    ``smt`` and ``prefetch`` take ``on``/``off`` (or True/False); ``smt`` also a count of threads per core.
    ``study`` is an :class:`analyses.whatif.WhatIf`.
    """
    platform = study.experiment.platform_object()
    if platform is None:
        return None
    choices = {}
    for key in PLATFORM_VARIANTS:
        if key not in point:
            continue
        value = point[key]
        if key in ("smt", "prefetch"):
            value = parse_switch(key, value, " or threads per core" if key == "smt" else "")
        choices[key] = value
    try:
        return platform.variant(**choices)
    except ValueError as error:
        raise InputError(f"what-if point {point}: {error}") from None


def shared_levels(study, point: dict):
    """Under a platform, what a point's runs simulate on: the point's platform variant's shared levels, with the
    point's level changes applied to the whole levels (an ``L3.size`` is the size of one L3), interleaved at the
    base's ``interleave_cycles`` (:class:`coherence.shared_run.SharedLevels`); None without a platform."""
    from coherence.shared_run import SharedLevels

    platform = platform_variant(study, point)
    if platform is None:
        return None
    machine = platform.hierarchy
    try:
        machine = replace(machine, hierarchy=point_levels(machine.hierarchy, point))
    except ValueError as error:
        raise InputError(f"what-if point {point}: {error}") from None
    return SharedLevels(machine, study.experiment.interleave_cycles)
