"""The tree variants against the study: tests per SPD scene, tree bytes and depth.

    python benchmarks/tree_variants.py [--sizes 32 128] [--scenes balls tetra shell] [--csv OUT]

For every rule of :data:`tracer.rendering.tree_variants.TREE_VARIANTS`, renders
each SPD scene with the ``study1997`` workload and that rule at each size,
without logging, counts intersection tests (ray-primitive tests, see
:mod:`tracer.rendering.workload`), scales them by ``(512 / size)**2`` to the
study's 512 x 512 (one ray per pixel) and divides by the study's count
(:mod:`tracer.scenes.study`). It also reports each variant's tree per scene:
its node count, index entries (duplicated references included), deepest
leaf, and bytes in the ``alpha1997`` memory image (node count times the
``kd_node`` record's size plus index entries times the ``index_entry``
record's size, :data:`coherence.layout.PRESET_RECORDS`).

A variant is plausible when its ratio lies within ``1 +- TOLERANCE`` on every
scene at the largest size; the last lines printed say which are, to be set
in :data:`tracer.rendering.tree_variants.PLAUSIBLE_TREE_VARIANTS`. The table
is written atomically with ``--csv``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from coherence.layout import get_layout  # noqa: E402
from rtcommon.files import write_text_atomic  # noqa: E402
from tracer.kd.tree import build_kdtree  # noqa: E402
from tracer.rendering.render import RenderOptions, render  # noqa: E402
from tracer.rendering.tree_variants import TREE_VARIANTS, workload_with_tree  # noqa: E402
from tracer.scenes import catalog  # noqa: E402
from tracer.scenes.study import STUDY_SCENES  # noqa: E402

SPD_SCENES = ("balls", "tetra", "shell")
STUDY_SIZE = 512
#: Largest relative distance of a plausible variant's tests from the study's.
TOLERANCE = 0.25


def tree_figures(scene, variant: str) -> dict:
    """The variant's tree over ``scene``: ``nodes``, ``index_entries``, ``depth`` and ``tree_bytes``
    (in the ``alpha1997`` image)."""
    tree = build_kdtree(scene, workload_with_tree("study1997", variant).kd_config)
    records = get_layout("alpha1997").records
    nodes, entries = int(tree.stats["nodes"]), int(tree.stats["references"])
    return {"nodes": nodes, "index_entries": entries, "depth": int(tree.stats["depth"]),
            "tree_bytes": nodes * records["kd_node"].size + entries * records["index_entry"].size}


def variant_table(scenes: dict, sizes, variants=None) -> pd.DataFrame:
    """One row per variant, scene and size.

    Parameters
    ----------
    scenes : dict
        Scene name -> loaded :class:`tracer.scenes.model.Scene`, each a
        study scene (its test count is the reference).
    sizes : sequence of int
        Image sizes rendered.
    variants : sequence of str, optional
        Default every variant.

    Returns
    -------
    DataFrame
        Columns ``variant``, ``scene``, ``size``, ``tests_1e6`` (scaled to
        512²), ``study_tests_1e6``, ``ratio``, ``nodes``, ``index_entries``,
        ``depth``, ``tree_bytes``.
    """
    rows = []
    for variant in (TREE_VARIANTS if variants is None else variants):
        workload = workload_with_tree("study1997", variant)
        for name, scene in scenes.items():
            figures = tree_figures(scene, variant)
            study = STUDY_SCENES[name].tests_1e6
            for size in sizes:
                result = render(scene, options=RenderOptions(size=size, log=False, workload=workload))
                tests = result.totals()["intersection_tests"] * (STUDY_SIZE / size) ** 2 / 1e6
                rows.append({"variant": variant, "scene": name, "size": int(size), "tests_1e6": round(tests, 3),
                             "study_tests_1e6": study, "ratio": round(tests / study, 4), **figures})
    return pd.DataFrame(rows)


def plausible(table: pd.DataFrame, size: int) -> list:
    """Variants whose ratio lies within ``1 +- TOLERANCE`` on every scene of ``table`` at ``size``, in table order."""
    at = table[table["size"] == size]
    inside = at.groupby("variant", sort=False)["ratio"].apply(
        lambda ratios: bool(((ratios - 1).abs() <= TOLERANCE).all()))
    return [variant for variant, ok in inside.items() if ok]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 128])
    parser.add_argument("--scenes", nargs="+", default=list(SPD_SCENES), choices=SPD_SCENES)
    parser.add_argument("--csv", help="write the table here")
    args = parser.parse_args(argv)
    if min(args.sizes) < 8:
        parser.error("--sizes must be >= 8")
    start = time.perf_counter()
    table = variant_table({name: catalog.load(name) for name in args.scenes}, args.sizes)
    if args.csv:
        write_text_atomic(args.csv, table.to_csv(index=False))
    pd.set_option("display.width", 200)
    print(table.to_string(index=False))
    wide = table.pivot_table(index="variant", columns=["size", "scene"], values="ratio", sort=False)
    print("ratio of tests to the study's, scaled to 512^2:")
    print(wide.to_string(float_format=lambda v: f"{v:.3f}"))
    largest = max(args.sizes)
    print(f"plausible at {largest}^2 (every scene within {TOLERANCE:.0%}): {', '.join(plausible(table, largest))}")
    print(f"{time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
