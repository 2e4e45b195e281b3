"""Peak memory of rendering one large concave polygon against a square.

Each scene is one polygon facing the camera (a star of N vertices, radii
alternating 1 and 0.6, so it is concave; and a 4-vertex square), rendered
with logging at 16x16. Each render runs in a fresh process, after one
warm-up process has filled numba's cache, and reports its peak resident
memory (``ru_maxrss``). Prints both peaks, the difference against its target
(at most 500 MB more), and the seconds; ends with one JSON line.

    python benchmarks/bench_polygon.py [--vertices 10000] [--size 16]
"""
import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET_MB = 500.0

CHILD = """
import json, resource, sys, time
import numpy as np
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.model import Camera, SceneBuilder

vertices, size = int(sys.argv[1]), int(sys.argv[2])
angles = np.linspace(0.0, 2.0 * np.pi, vertices, endpoint=False)
radii = np.where(np.arange(vertices) % 2, 0.6, 1.0) if vertices > 4 else np.full(vertices, 1.0)
builder = SceneBuilder("polygon")
builder.camera = Camera(eye=(0.0, 0.0, 4.0), look_at=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), angle=45.0,
                        resolution=(size, size))
builder.light((1.0, 2.0, 5.0))
builder.polygon(np.column_stack([radii * np.cos(angles), radii * np.sin(angles), np.zeros(vertices)]))
scene = builder.build()
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
result = render(scene, options=RenderOptions(size=size))
seconds = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"before_mb": before / 1024, "peak_mb": peak / 1024, "seconds": seconds,
                  "primary_hits": result.totals()["primary_hits"]}))
"""


def _measure(vertices: int, size: int) -> dict:
    done = subprocess.run([sys.executable, "-c", CHILD, str(vertices), str(size)], cwd=ROOT, capture_output=True,
                          text=True, check=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vertices", type=int, default=10_000)
    parser.add_argument("--size", type=int, default=16)
    args = parser.parse_args()

    _measure(4, args.size)  # fill numba's cache, so neither measured run compiles
    square = _measure(4, args.size)
    large = _measure(args.vertices, args.size)
    extra = large["peak_mb"] - square["peak_mb"]
    for name, figures in ((f"{4}-vertex square", square), (f"{args.vertices}-vertex star", large)):
        print(f"{name:<20} peak {figures['peak_mb']:8.1f} MB  (after imports {figures['before_mb']:.1f} MB)  "
              f"render {figures['seconds']:.2f} s, {figures['primary_hits']} primary hits")
    print(f"extra peak memory: {extra:.1f} MB (target <= {TARGET_MB:g} MB) {'met' if extra <= TARGET_MB else 'NOT met'}")
    print(json.dumps({"vertices": args.vertices, "size": args.size, "square": square, "large": large,
                      "extra_mb": round(extra, 1), "target_mb": TARGET_MB}))


if __name__ == "__main__":
    main()
