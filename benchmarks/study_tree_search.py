"""The documented search for the study-era tree rule (issue 12, item 1).

    python benchmarks/study_tree_search.py [--size 32] [--check-size 128] [--out docs/study_tree_search.csv]

Renders balls, tetra and shell with every candidate rule (spatial-median
tree: depth limit, leaf size, clipping, axis rule, splitting down to the
depth limit or stopping where a plane separates nothing; shadow rays any-hit or
nearest) at a reduced image size, without logging, and counts intersection
tests (ray-primitive tests, see :mod:`tracer.rendering.workload`). Tests scale with the
pixel count, so a count at ``size`` x ``size`` is scaled by
``(512 / size)**2`` to the study's 512 x 512 (one ray per pixel); the script
checks that scaling for the chosen rule at ``--check-size``. The score of a
rule is the mean squared log error of its three scaled counts against the
study's (DESIGN.md §2): ``mean(log(ours / study)**2)``. Room and fluid (the
stand-ins) are rendered with the best rules only, and reported, not scored.

Output: one CSV row per rule and scene (``rule``, the rule's parameters,
``scene``, ``size``, ``tests_1e6`` scaled to 512², ``study_tests_1e6``,
``ratio``, ``msle`` of the rule over balls/tetra/shell, ``rank``), written
atomically. It lives in ``benchmarks/`` because it is how the preset was
chosen, not something users rerun: they select the result by name
(``--workload study1997``).
"""
from __future__ import annotations

import argparse
import itertools
import math
import os
import sys
import time
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tracer.scenes import catalog as scenes  # noqa: E402
from tracer.kd.tree import KdTreeConfig  # noqa: E402
from tracer.rendering.render import RenderOptions, render  # noqa: E402
from tracer.scenes.study import STUDY_SCENES  # noqa: E402
from tracer.rendering.workload import Workload  # noqa: E402

FITTED = ("balls", "tetra", "shell")
STAND_INS = ("room", "fluid")
STUDY_SIZE = 512

# The candidate rules: every combination of these levers.
DEPTHS = (13, 14, 15, 16, 17)
LEAF_SIZES = (8, 16, 32, 48, 64)
CLIPS = (True, False)
AXIS_RULES = ("longest", "cycle")
SPLIT_TO_DEPTH = (False, True)
SHADOW_NEAREST = (False, True)
BEST_FOR_STAND_INS = 6


def candidates():
    """Every candidate rule as ``(rule name, Workload)``."""
    for depth, leaf, clip, axis, to_depth, nearest in itertools.product(DEPTHS, LEAF_SIZES, CLIPS, AXIS_RULES,
                                                                        SPLIT_TO_DEPTH, SHADOW_NEAREST):
        name = (f"d{depth}-l{leaf}-{'clip' if clip else 'box'}-{axis}-{'todepth' if to_depth else 'separate'}"
                f"-{'nearest' if nearest else 'anyhit'}")
        config = KdTreeConfig(builder="median", tree_depth=depth, leaf_size=leaf, clip=clip, axis_rule=axis,
                              split_to_depth=to_depth)
        yield name, Workload(name, config, shadow_nearest=nearest)


def tests_at_study_size(scene, workload: Workload, size: int) -> float:
    """Intersection tests of ``scene`` at ``size``², scaled to 512², in millions."""
    result = render(scene, options=RenderOptions(size=size, log=False, workload=workload))
    return result.totals()["intersection_tests"] * (STUDY_SIZE / size) ** 2 / 1e6


def rows_of(name, workload, scene_names, loaded, size):
    rows = []
    for scene_name in scene_names:
        tests = tests_at_study_size(loaded[scene_name], workload, size)
        study = STUDY_SCENES[scene_name].tests_1e6
        config = workload.kd_config
        rows.append({"rule": name, "builder": config.builder, "tree_depth": config.tree_depth,
                     "leaf_size": config.leaf_size, "clip": config.clip, "axis_rule": config.axis_rule,
                     "split_to_depth": config.split_to_depth,
                     "shadow_nearest": workload.shadow_nearest, "scene": scene_name, "size": size,
                     "tests_1e6": round(tests, 3), "study_tests_1e6": study, "ratio": round(tests / study, 4)})
    return rows


def msle(ratios) -> float:
    """Mean squared log error of ``ours / study`` ratios."""
    return sum(math.log(r) ** 2 for r in ratios) / len(ratios)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=32, help="image size of the search (default 32)")
    parser.add_argument("--check-size", type=int, default=128, help="size at which the scaling is checked")
    parser.add_argument("--out", default="docs/study_tree_search.csv")
    args = parser.parse_args(argv)
    if args.size < 8 or args.check_size < 8:
        parser.error("--size and --check-size must be >= 8")
    loaded = {name: scenes.load(name) for name in FITTED + STAND_INS}
    start = time.perf_counter()
    rows = []
    rules = dict(candidates())
    for k, (name, workload) in enumerate(rules.items()):
        rows.extend(rows_of(name, workload, FITTED, loaded, args.size))
        if k % 50 == 49:
            print(f"{k + 1} of {len(rules)} rules, {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    table = pd.DataFrame(rows)
    score = table.groupby("rule")["ratio"].apply(msle).rename("msle")
    table = table.join(score, on="rule")
    order = score.sort_values(kind="stable")
    best = list(order.index[:BEST_FOR_STAND_INS])
    for name in best:
        table = pd.concat([table, pd.DataFrame(rows_of(name, rules[name], STAND_INS, loaded, args.size))
                           .assign(msle=score[name])], ignore_index=True)
    table["rank"] = table["rule"].map({name: k + 1 for k, name in enumerate(order.index)})
    table = table.sort_values(["rank", "scene"], kind="stable").reset_index(drop=True)
    search_seconds = time.perf_counter() - start
    # the scaling check: the chosen rule at a larger size
    chosen = rules[best[0]]
    check = pd.DataFrame(rows_of(best[0], chosen, FITTED + STAND_INS, loaded, args.check_size))
    check = check.assign(msle=msle(check[check.scene.isin(FITTED)].ratio), rank=1)
    table = pd.concat([table, check], ignore_index=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    table.to_csv(tmp, index=False)
    os.replace(tmp, out)
    pd.set_option("display.width", 200)
    print(f"{len(rules)} rules x {len(FITTED)} scenes at {args.size}^2 in {search_seconds:.0f} s")
    wide = table[table["size"] == args.size].pivot(index="rule", columns="scene", values="ratio")
    wide = wide.join(score).sort_values("msle").head(12)
    print("best rules (ratio ours / study, scaled to 512^2):")
    print(wide.to_string(float_format=lambda v: f"{v:.3f}"))
    print(f"scaling check, {best[0]} at {args.check_size}^2:")
    print(check[["scene", "tests_1e6", "study_tests_1e6", "ratio"]].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
