"""Cycles per operation of this project's own tracer, measured on this machine.

The platform cost models (:mod:`coherence.platforms`) charge fixed cycles per
operation (ray, kd-node visit, index read, intersection test by primitive
type, shading). This script measures them: it renders the five paper scenes
without logging, at several ray-tree depths and with both tree builders (so
the counters vary independently), times each render in CPU seconds of one
core (best of ``--repeats``), and solves for cycles per operation with
non-negative least squares (:meth:`coherence.cost.CostModel.calibrate`) at
the clock given by ``--clock-ghz``. Patches and cones, in no paper scene,
get the polygon test's cycles. Cache behaviour is inside the measured time:
the fitted cycles are "all told" figures of this machine.

Run:  python benchmarks/bench_platform_costs.py [--size 256] [--repeats 3] [--clock-ghz 2.6]

Prints one row per render, the fitted cycles per operation with the
relative errors of the fit, and last one JSON object with every figure.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from dataclasses import replace

import numba
import pandas as pd

from tracer.kd.tree import KdTreeConfig, build_kdtree
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import PAPER_SCENES, load
from tracer.trace.records import COUNTER_NAMES
from coherence.cost import CostModel


def _pin_one_core():
    numba.set_num_threads(1)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def measure(size: int, repeats: int) -> pd.DataFrame:
    """One row per (scene, builder, depth): best CPU seconds of a render and its counter sums."""
    rows = []
    for name in PAPER_SCENES:
        scene = load(name)
        for builder in ("sah", "median"):
            tree = build_kdtree(scene, KdTreeConfig(builder=builder))
            for depth in sorted({1, scene.max_depth}):
                options = RenderOptions(size=size, log=False, max_depth=depth)
                render(scene, tree, options)  # compile and warm
                best = float("inf")
                for _ in range(repeats):
                    start = time.process_time()
                    result = render(scene, tree, options)
                    best = min(best, time.process_time() - start)
                sums = result.counters.sum(axis=0)
                row = {"scene": name, "builder": builder, "depth": depth, "seconds": best}
                row.update({counter: int(value) for counter, value in zip(COUNTER_NAMES, sums)})
                rows.append(row)
                print(f"{name:6s} {builder:6s} depth {depth}: {best:.4f} s CPU, "
                      f"{int(sums[COUNTER_NAMES.index('node_visits')]):,} node visits", flush=True)
    return pd.DataFrame(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256, help="image width and height (default 256)")
    parser.add_argument("--repeats", type=int, default=3, help="renders per point, best taken (default 3)")
    parser.add_argument("--clock-ghz", type=float, default=2.6,
                        help="clock of this machine in GHz, to turn seconds into cycles (default 2.6)")
    args = parser.parse_args(argv)
    _pin_one_core()
    frame = measure(args.size, args.repeats)
    model, residuals = CostModel.calibrate(frame, clock_hz=args.clock_ghz * 1e9, name="measured")
    # no paper scene has patches or cones: they cost what a polygon test costs
    model = replace(model, test_patch=model.test_polygon, test_cone=model.test_polygon)
    fitted = {key: round(float(value), 2) for key, value in model.to_dict().items()
              if key not in ("clock_hz", "name")}
    print("cycles per operation:", fitted)
    print("relative error of the fit per render:",
          [round(float(value), 3) for value in residuals["relative_error"]])
    print(json.dumps({"machine": platform.processor() or platform.machine(), "size": args.size,
                      "clock_ghz": args.clock_ghz, "cycles": fitted,
                      "max_abs_relative_error": float(residuals["relative_error"].abs().max()),
                      "renders": frame.to_dict(orient="records")}))


if __name__ == "__main__":
    main()
