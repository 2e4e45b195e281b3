"""SAH kd-tree build time: events sorted once (O(N log N)) against the
earlier per-node sort (O(N log^2 N)), in one run.

For SPD balls (size 2..5), tetra (size 4..8) and the five paper scenes, times
the builder kernel of each (best of ``--repeats``; the scene arrays both take
as input are prepared once and timed apart as ``prep``), checks that both
build the same tree, and prints seconds and nanoseconds per N log2 N, so the
scaling and the ratio show side by side. "old" is the per-node builder of
``tests/naive_kdtree.py`` (imported from there), which shares the clipping
and sweep code with the new one. Both SAH configurations are run:
``clip`` on (the default) and off (no clipping, so the event handling is
most of the time). The last line printed is one JSON object with every figure.

    python benchmarks/bench_kdtree.py [--repeats R] [--quick]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from tracer.scenes import spd
from tracer.kd.sah import _build_sah
from tracer.kd.tree import KdTreeConfig, build_params, builder_inputs, default_tree_depth
from tracer.scenes.catalog import PAPER_SCENES, load

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from naive_kdtree import build_per_node_sah_kernel  # noqa: E402  (the test-only peer)
from timing import best_of  # noqa: E402

CONFIGS = {"sah": KdTreeConfig(), "sah-noclip": KdTreeConfig(clip=False)}


def _scenes(quick: bool):
    balls = range(2, 5) if quick else range(2, 6)
    tetra = range(4, 7) if quick else range(4, 9)
    for size in balls:
        yield f"balls-{size}", "balls", spd.balls(size)
    for size in tetra:
        yield f"tetra-{size}", "tetra", spd.tetra(size)
    for name in PAPER_SCENES:
        yield f"paper-{name}", "paper", load(name)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="timed builds per scene and builder (best kept)")
    ap.add_argument("--quick", action="store_true", help="smaller size ranges (a few seconds)")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")

    # compile (or load the numba cache) outside the timings
    warm = builder_inputs(spd.balls(1))
    for cfg in CONFIGS.values():
        params = build_params(KdTreeConfig(**{**cfg.to_dict(), "tree_depth": 8}))
        _build_sah(warm, params)
        build_per_node_sah_kernel(warm, params)

    rows = []
    print(f"{'scene':<13}{'config':<11}{'N':>7}{'nodes':>8}{'prep s':>8}{'new s':>9}{'old s':>9}"
          f"{'new ns/NlgN':>12}{'old ns/NlgN':>12}{'old/new':>8}  same")
    for label, family, scene in _scenes(args.quick):
        n = scene.n_elements
        t0 = time.perf_counter()
        inputs = builder_inputs(scene)
        prep = time.perf_counter() - t0
        nlogn = n * math.log2(n)
        for cname, cfg in CONFIGS.items():
            params = build_params(KdTreeConfig(**{**cfg.to_dict(), "tree_depth": default_tree_depth(n)}))
            new_s, new = best_of(args.repeats, lambda: _build_sah(inputs, params))
            old_s, old = best_of(args.repeats, lambda: build_per_node_sah_kernel(inputs, params))
            same = bool(np.array_equal(new[0], old[0]) and np.array_equal(new[1], old[1]))
            row = {"scene": label, "family": family, "config": cname, "n": n, "nodes": int(len(new[0])),
                   "prep_seconds": prep, "new_seconds": new_s, "old_seconds": old_s,
                   "new_ns_per_nlogn": 1e9 * new_s / nlogn, "old_ns_per_nlogn": 1e9 * old_s / nlogn,
                   "old_over_new": old_s / new_s, "same_tree": same}
            rows.append(row)
            print(f"{label:<13}{cname:<11}{n:>7}{row['nodes']:>8}{prep:>8.3f}{new_s:>9.4f}{old_s:>9.4f}"
                  f"{row['new_ns_per_nlogn']:>12.1f}{row['old_ns_per_nlogn']:>12.1f}"
                  f"{row['old_over_new']:>8.2f}  {'yes' if same else 'NO'}", flush=True)
    print(json.dumps({"benchmark": "kdtree_build", "repeats": args.repeats, "quick": args.quick,
                      "rows": rows, "all_same_tree": all(r["same_tree"] for r in rows)}))


if __name__ == "__main__":
    main()
