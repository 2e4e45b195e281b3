"""Path tracer speed: logged rays per second on one thread (shadow rays counted as rays).

Run:  python3 benchmarks/bench_pathtrace.py [--scene balls] [--size 128] [--spp 4] [--threads 1]

Renders once to compile, then times the logged pass (records and segments
kept in memory, as a cached trace is made) and the pass without logging, each
the best of ``--repeats``. The target of the path-tracing workload is at least
1 M logged rays/s on one thread for balls at spp 4 (:data:`TARGET_RAYS_PER_SECOND`);
the line ``target`` says whether it is met. Its peer, timed in the same run so
that the machine's load shows in both, is the Whitted renderer's logged pass of
the same scene and size (its rays counted the same way). The last line printed
is one JSON object with every figure.
"""
from __future__ import annotations

import argparse
import json

import numba

from benchmarks.timing import best_of
from tracer.kd.tree import build_kdtree
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import load

#: Logged rays per second the path tracer is to reach on one thread (balls, spp 4).
TARGET_RAYS_PER_SECOND = 1e6


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="balls")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--max-depth", type=int, default=None)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    numba.set_num_threads(args.threads)
    scene = load(args.scene, max_depth=args.max_depth)
    tree = build_kdtree(scene)
    figures = {"scene": scene.name, "size": args.size, "spp": args.spp, "max_depth": scene.max_depth,
               "threads": args.threads}
    runs = (("logged", "pathtrace", True), ("unlogged", "pathtrace", False), ("whitted", None, True))
    for label, workload, log in runs:
        spp = args.spp if workload else 1
        options = RenderOptions(size=args.size, workload=workload, spp=spp, log=log)
        render(scene, tree, RenderOptions(size=8, workload=workload, spp=spp, log=log))  # compile
        seconds, result = best_of(args.repeats, lambda: render(scene, tree, options))
        totals = result.totals()
        figures[f"{label}_seconds"] = seconds
        figures[f"{label}_rays"] = totals["rays"]
        figures[f"{label}_rays_per_second"] = totals["rays"] / seconds
        if label == "logged":
            figures["records"] = totals["records"]
            figures["segments"] = result.trace.segments.n_segments
        print(f"{label:9s} {totals['rays']:>10,} rays in {seconds:.3f} s: {totals['rays'] / seconds / 1e6:.3f} M rays/s")
    rate = figures["logged_rays_per_second"]
    figures["target_met"] = rate >= TARGET_RAYS_PER_SECOND
    print(f"target    logged path tracing {rate / 1e6:.3f} M rays/s against {TARGET_RAYS_PER_SECOND / 1e6:g} M: "
          f"{'met' if figures['target_met'] else 'NOT met'}; "
          f"{rate / figures['whitted_rays_per_second']:.2f}x the logged Whitted renderer's rays/s")
    print(json.dumps(figures))
    return figures


if __name__ == "__main__":
    main()
