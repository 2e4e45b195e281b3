"""``coherence report``: the per-scene coherence report (HTML, CSV, JSON)."""
from __future__ import annotations

import argparse

HELP = "per-scene report: did load balance or cache coherence decide the speed-up, and why?"

EPILOG = """\
SCENE is one of the study's scenes (balls, tetra, shell, room, fluid) or a
.nff/.obj path; default balls. The trace is rendered once and cached (key:
scene or file content, size, kd builder, depth, package version) under
~/.cache/raytrace-coherence/traces, or $COHERENCE_CACHE/traces, or --cache;
a second report of the same scene and size reuses it.

Every mapping runs at 1..--max-processes processes on --cpus simulated CPUs
(default 8 CPUs, 1..16 processes, as in the study). Real time assumes
--background always-runnable processes of other users (default 4).

Output folder (default report-SCENE):
  index.html    one self-contained page: the scene, bytes of scene data
                against each cache, hit rates and misses per ray at 1 and 8
                processes, miss-ratio curves, the per-pixel cost map, mapping
                pictures, per-process user times, speed-up curves, the
                efficiency decomposition and the verdict
  results.csv   every number, tidy long form: section, mapping, n_processes,
                item, metric, value (sections: scene, scene_bytes, cache,
                runs, processes, miss_ratio, cost_map, verdict)
  summary.json  parameters, versions, headline numbers and the verdict
The same inputs give byte-identical results.csv and summary.json.

examples:
  coherence report                               # balls at 512x512
  coherence report tetra --size 256 --out tetra-report
  coherence report shell --mappings S B DB hilbert --background 0
  coherence report balls --hierarchy modern --json
"""


def register(subparsers) -> None:
    """Add the ``report`` subcommand to ``subparsers``."""
    parser = subparsers.add_parser("report", help=HELP, description=HELP[0].upper() + HELP[1:], epilog=EPILOG,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", metavar="SCENE", nargs="?", default="balls",
                        help="balls | tetra | shell | room | fluid, or a .nff/.obj path (default balls)")
    parser.add_argument("--size", type=int, default=512, metavar="N", help="image width and height (default 512)")
    parser.add_argument("--out", metavar="DIR", help="output folder (default report-SCENE)")
    parser.add_argument("--mappings", nargs="+", default=["S", "P", "R", "B", "DB"], metavar="NAME",
                        help="mappings to compare (default: S P R B DB; also hilbert, morton, serpentine, "
                             "hilbert-tiles)")
    parser.add_argument("--max-processes", type=int, default=16, metavar="N",
                        help="simulate 1..N processes (default 16)")
    parser.add_argument("--processes", type=int, nargs="+", metavar="N",
                        help="explicit process counts instead of 1..--max-processes (1 is always added)")
    parser.add_argument("--cpus", type=int, default=8, metavar="C", help="simulated CPUs (default 8)")
    parser.add_argument("--background", type=int, default=4, metavar="B",
                        help="always-runnable processes of other users, for real time (default 4)")
    parser.add_argument("--hierarchy", default="alpha21164", metavar="NAME|FILE",
                        help="cache hierarchy preset (alpha21164, modern) or .toml/.json file (default alpha21164)")
    parser.add_argument("--layout", default="compact", choices=["compact", "alpha1997"],
                        help="memory layout of scene records (default compact)")
    parser.add_argument("--cost", default="alpha8400", choices=["alpha8400", "modern"],
                        help="cycles per operation and clock rate (default alpha8400)")
    parser.add_argument("--kd", default="sah", choices=["sah", "median"], help="kd-tree builder (default sah)")
    parser.add_argument("--max-depth", type=int, metavar="N", help="ray-tree depth (default: the scene's)")
    parser.add_argument("--cache", metavar="DIR", help="trace cache folder (default: see below)")
    parser.add_argument("--json", action="store_true", help="print summary.json to stdout instead of the verdict")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from analyses.report import build_report, write_report

    if args.size < 1:
        raise ValueError(f"--size must be >= 1, got {args.size}")
    if args.max_processes < 1:
        raise ValueError(f"--max-processes must be >= 1, got {args.max_processes}")
    if args.cpus < 1:
        raise ValueError(f"--cpus must be >= 1, got {args.cpus}")
    if args.background < 0:
        raise ValueError(f"--background must be >= 0, got {args.background}")
    out = args.out or f"report-{Path(args.scene).stem.lower()}"
    progress = sys.stderr.isatty()
    report = build_report(args.scene, args.size, mappings=args.mappings, max_processes=args.max_processes,
                          n_processes=args.processes, background=args.background, n_cpus=args.cpus,
                          hierarchy=args.hierarchy, layout=args.layout, cost=args.cost, kd=args.kd,
                          max_depth=args.max_depth, cache_dir=args.cache, out=out, progress=progress)
    path = write_report(report, out)
    print(f"wrote {path / 'index.html'}, results.csv, summary.json"
          f"{' (trace from cache)' if report.render_info.get('cached') else ''}", file=sys.stderr)
    if args.json:
        print(json.dumps(report.summary, indent=2))
    else:
        print(report.verdict.headline)
        for sentence in report.verdict.sentences:
            print("  " + sentence)
    return 0
