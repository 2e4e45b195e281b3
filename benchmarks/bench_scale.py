"""A million triangles traced at 512x512: SPD tetra at size factor 10 (4**10 triangles).

Generates the scene, builds its SAH tree and renders it with logging (the
trace a report replays), printing each step's seconds, the records and the
process's peak memory, beside tetra at the study's size factor 6 as the peer.
Ends with one JSON line.

    python benchmarks/bench_scale.py [--size 512] [--size-factor 10]
"""
import argparse
import json
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tracer.scenes import spd  # noqa: E402
from tracer.rendering.render import RenderOptions, render  # noqa: E402


def one(size_factor, size):
    start = time.perf_counter()
    scene = spd.tetra(size_factor)
    scene.max_depth = 2  # the study's depth for tetra
    generate = time.perf_counter() - start
    result = render(scene, options=RenderOptions(size=size))
    totals = result.totals()
    return {"triangles": scene.n_elements, "generate_seconds": round(generate, 2),
            "build_seconds": round(result.timings["build"], 2), "trace_seconds": round(result.timings["trace"], 2),
            "records": totals["records"], "rays": totals["rays"], "tree_nodes": result.tree.stats["nodes"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--size-factor", type=int, default=10)
    args = parser.parse_args()
    render(spd.tetra(2), options=RenderOptions(size=8))  # compile (or load the numba cache) first
    figures = {"size": args.size, "peer": one(6, args.size)}
    figures["large"] = one(args.size_factor, args.size)
    figures["peak_gib"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2)
    for name in ("peer", "large"):
        f = figures[name]
        print(f"tetra {f['triangles']:>9,} triangles: generate {f['generate_seconds']:6.2f} s, build "
              f"{f['build_seconds']:6.2f} s, trace {f['trace_seconds']:5.2f} s at {args.size}^2, "
              f"{f['records']:,} records")
    print(f"peak memory {figures['peak_gib']} GiB")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
