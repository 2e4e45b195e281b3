"""Named variants of the study-era tree rule: the one home of the rules a run may select.

The study's BSP tree is not public; what is known of it is its intersection
test counts. ``benchmarks/study_tree_search.py`` scored spatial-median rules
against them (``docs/study_tree_search.csv``) and the ``study1997`` workload
(:mod:`tracer.rendering.workload`) builds the best one. The rules here are
that rule and neighbours of it that test about as often but build other
trees: another depth limit, leaf size or axis rule, hence another node
count, depth and number of duplicated references. A run selects one by name
(``Experiment.tree_variant``, ``--tree-variant``); only the tree changes,
every other lever of the workload stays.

A name spells the rule as the search table does::

    d<depth limit>-l<leaf size>-<box|clip>-<longest|cycle>-<todepth|separate>-<nearest|anyhit>

(objects sorted into children by bounding box or clipped; axis halved;
split down to the depth limit or only where a plane separates objects;
shadow rays nearest-hit or any-hit). The configuration is read from the
name, so the two cannot disagree; the last part must be the workload's own
shadow rule.

:data:`PLAUSIBLE_TREE_VARIANTS` keeps the variants whose tests lie within
25% of the study's on balls, tetra and shell at 128 x 128
(``benchmarks/tree_variants.py``; table and command in
``docs/unknowns.md``, "tree_variant").
"""
from __future__ import annotations

import re
from dataclasses import replace

from tracer.kd.tree import KdTreeConfig
from tracer.rendering.workload import Workload, get_workload
from rtcommon.validate import InputError

__all__ = ["PLAUSIBLE_TREE_VARIANTS", "STUDY_TREE_VARIANT", "TREE_VARIANTS", "TREE_VARIANT_WORKLOADS",
           "get_tree_variant", "tree_rule_name", "workload_with_tree"]

#: The workloads whose tree a variant replaces.
TREE_VARIANT_WORKLOADS = ("study1997",)

#: The study-era rule itself (``STUDY_TREE`` of :mod:`tracer.rendering.workload`), the default.
STUDY_TREE_VARIANT = "d16-l32-box-cycle-todepth-nearest"

_NAME = re.compile(r"d(\d+)-l(\d+)-(box|clip)-(longest|cycle)-(todepth|separate)-(nearest|anyhit)")


def tree_rule_name(config: KdTreeConfig, shadow_nearest: bool) -> str:
    """The name of a spatial-median rule, as the tree search's table spells it.

    Raises
    ------
    ValueError
        For a rule that is not a spatial median with a depth limit.
    """
    if config.builder != "median" or config.tree_depth is None:
        raise InputError(f"a tree rule name needs a median builder with a depth limit, got {config}")
    return (f"d{config.tree_depth}-l{config.leaf_size}-{'clip' if config.clip else 'box'}-{config.axis_rule}"
            f"-{'todepth' if config.split_to_depth else 'separate'}-{'nearest' if shadow_nearest else 'anyhit'}")


def _rule(name: str) -> KdTreeConfig:
    match = _NAME.fullmatch(name)
    if match is None:
        raise InputError(f"tree rule name {name!r} does not read d<depth>-l<leaf>-<box|clip>-<longest|cycle>"
                         "-<todepth|separate>-<nearest|anyhit>")
    depth, leaf, clip, axis, split, _ = match.groups()
    return KdTreeConfig(builder="median", tree_depth=int(depth), leaf_size=int(leaf), clip=clip == "clip",
                        axis_rule=axis, split_to_depth=split == "todepth")


#: Name -> tree rule. The study's rule and the five rules of the search whose
#: scaled tests at 32 x 32 lie within 25% of the study's for balls and shell
#: and are no farther from tetra's than the study rule's.
TREE_VARIANTS = {name: _rule(name) for name in (
    STUDY_TREE_VARIANT,
    "d14-l32-box-longest-todepth-nearest",
    "d15-l32-box-longest-todepth-nearest",
    "d15-l48-box-longest-todepth-nearest",
    "d17-l32-box-cycle-todepth-nearest",
    "d17-l48-box-cycle-todepth-nearest",
)}

#: The variants whose tests at 128 x 128 lie within 25% of the study's on
#: every SPD scene (balls, tetra, shell); a sensitivity study samples these.
#: ``d14-l32-box-longest-todepth-nearest`` is left out: it tests 1.27 times
#: the study's count on balls.
PLAUSIBLE_TREE_VARIANTS = tuple(name for name in TREE_VARIANTS if name != "d14-l32-box-longest-todepth-nearest")

def get_tree_variant(name: str) -> KdTreeConfig:
    """The tree rule called ``name`` (:data:`TREE_VARIANTS`).

    Raises
    ------
    ValueError
        For any other name, listing the choices.
    """
    if not isinstance(name, str) or name not in TREE_VARIANTS:
        raise InputError(f"tree variant must be one of {', '.join(TREE_VARIANTS)}, got {name!r}")
    return TREE_VARIANTS[name]


def workload_with_tree(workload, tree_variant: str | None = None) -> Workload:
    """``workload`` (a name or a :class:`Workload`) building the tree of ``tree_variant``.

    ``None``, or the default :data:`STUDY_TREE_VARIANT`, leaves any workload
    as it is (the same object for a preset), so a run at the default is the
    run of before, ``modern`` included.

    Raises
    ------
    ValueError
        An unknown workload or variant name, a variant other than the
        default for a workload outside :data:`TREE_VARIANT_WORKLOADS`, or a
        variant whose shadow rule is not the workload's.
    """
    preset = get_workload(workload)
    if tree_variant is None or tree_variant == STUDY_TREE_VARIANT:
        return preset
    config = get_tree_variant(tree_variant)
    if preset.name not in TREE_VARIANT_WORKLOADS:
        raise InputError(f"tree variant {tree_variant} applies to the {', '.join(TREE_VARIANT_WORKLOADS)} "
                         f"workload only, not {preset.name}")
    if tree_rule_name(config, preset.shadow_nearest) != tree_variant:
        raise InputError(f"tree variant {tree_variant} has another shadow rule than the {preset.name} workload")
    if config == preset.kd_config:
        return preset
    return replace(preset, kd_config=config)

