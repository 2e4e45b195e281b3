"""What textures cost the tracer: a logged trace of balls-textured against balls.

Renders both scenes at the same size with logging (the trace a report
replays), warm numba, best of ``--repeats``, and prints the seconds, the
records, the texel share and the ratio textured / untextured beside its
target (<= 2). Ends with one JSON line.

    python benchmarks/bench_texture.py [--size 512] [--repeats 2] [--filter trilinear]
"""
import argparse
import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from timing import best_of  # noqa: E402

from tracer.rendering.render import RenderOptions, render  # noqa: E402
from tracer.scenes.catalog import load  # noqa: E402

TARGET_RATIO = 2.0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--filter", default="trilinear", choices=("nearest", "bilinear", "trilinear"))
    args = parser.parse_args()

    figures = {"size": args.size, "filter": args.filter, "cpus": os.cpu_count()}
    for name in ("balls", "balls-textured"):
        scene = load(name)
        # compile (or load the numba cache) first
        render(scene, options=RenderOptions(size=16, texture_filter=args.filter))
        options = RenderOptions(size=args.size, texture_filter=args.filter)
        seconds, result = best_of(args.repeats, lambda: render(scene, options=options))
        totals = result.totals()
        records = totals["records"]
        figures[name] = {"seconds": round(seconds, 3), "trace_seconds": round(result.timings["trace"], 3),
                         "records": records, "texel_reads": totals["texel_reads"],
                         "texel_share": round(totals["texel_reads"] / records, 4)}
        print(f"{name:<15} {seconds:7.2f} s  (trace {result.timings['trace']:.2f} s)  {records:>11,} records, "
              f"{totals['texel_reads']:>9,} texel reads ({100 * totals['texel_reads'] / records:.1f}%)")
        del result
    ratio = figures["balls-textured"]["seconds"] / figures["balls"]["seconds"]
    figures["ratio"] = round(ratio, 3)
    figures["target_ratio"] = TARGET_RATIO
    print(f"textured / untextured: {ratio:.2f}x (target <= {TARGET_RATIO:g}x) "
          f"{'met' if ratio <= TARGET_RATIO else 'NOT met'}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
