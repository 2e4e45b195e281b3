"""``coherence report``: the per-scene coherence report (HTML, CSV, JSON)."""
from __future__ import annotations

import argparse

from analyses.commands.options import (ExplicitStore, HelpFormatter, cache_options, check_at_least, dask_options,
                                       experiment_from_args, given, machine_options, mappings_options,
                                       memory_budget_options, model_options, scene_options, size_options,
                                       tree_options, workload_options)

HELP = "per-scene report: did load balance or cache coherence decide the speed-up, and why?"

EPILOG = """\
SCENE is one of the study's scenes or a .nff/.obj path; default balls. The
trace is rendered once and cached (key: scene or file content, size, kd
builder, depth, package version) under
CACHE/traces, where CACHE is --cache, else $COHERENCE_CACHE, else
~/.cache/raytrace-coherence; a second report of the same scene and size
reuses it. Every load checks the trace's checksums: a damaged entry is
reported, evicted and rendered again.

Every mapping runs at 1..--max-processes processes on --cpus simulated CPUs
(default 8 CPUs, 1..16 processes, as in the study). Real time assumes
--background always-runnable processes of other users (default 4).

Output folder (default report-SCENE):
  index.html    one self-contained page: the scene, bytes of scene data
                against each cache, hit rates and misses per ray at 1 and 8
                processes, miss-ratio curves, the per-pixel cost map, the
                per-pixel miss map, mapping pictures, per-process user
                times, speed-up curves, the efficiency decomposition and the
                verdict
  results.csv   every number, tidy long form: section, mapping, n_processes,
                item, metric, value (sections: scene, scene_bytes, cache,
                runs, processes, miss_ratio, cost_map, miss_map, verdict)
  summary.json  parameters, versions, headline numbers and the verdict
  miss_map.npy  misses per pixel per cache level of one run (--miss-map):
                shape (height, width, levels), rows from the image's top,
                uint32; numpy.load reads it
  miss_map.png  the same drawn, one panel per cache level
The same inputs give byte-identical results.csv, summary.json and
miss_map.npy.

examples:
  coherence report                               # balls at 512x512
  coherence report tetra --size 256 --out tetra-report
  coherence report shell --mappings S B DB hilbert --background 0
  coherence report balls --hierarchy modern --json
  coherence report balls --miss-map S:8          # map the misses of S at 8 processes
  coherence report shell --dask tcp://scheduler:8786 --cache /shared/cache
"""


def register(subparsers) -> None:
    """Add the ``report`` subcommand to ``subparsers``."""
    machine = machine_options(processes=None, processes_help="explicit process counts instead of "
                              "1..--max-processes (1 is always added)", background=4,
                              background_why="a busy shared machine like the study's, so that real time shows "
                              "what sharing costs; 'coherence paper' uses 2 so that a lone process runs at full "
                              "speed, as its calibration needs")
    parents = [scene_options(default="balls"), size_options(),
               tree_options(kd_default=None, kd_why="the workload's: sah for modern, the study's median tree for "
                            "study1997"), workload_options(), mappings_options(), machine, model_options(),
               cache_options(), dask_options(), memory_budget_options()]
    parser = subparsers.add_parser("report", help=HELP, description=HELP[0].upper() + HELP[1:], epilog=EPILOG,
                                   formatter_class=HelpFormatter, parents=parents)
    parser.add_argument("--out", metavar="DIR", help="output folder (default report-SCENE)")
    parser.add_argument("--max-processes", type=int, default=16, metavar="N", action=ExplicitStore,
                        help="simulate 1..N processes (default 16; under --platform 2 x its hardware threads, at "
                             "most 32)")
    parser.add_argument("--miss-map", metavar="MAPPING:N",
                        help="map the misses per pixel of MAPPING at N processes, e.g. P:8, in one more run "
                             "(default: the compared mapping that loses most to coherence at 8 processes, or "
                             "at the largest count without 8: the misses the verdict weighs)")
    parser.add_argument("--prefetch", choices=("on", "off"), metavar="on|off",
                        help="with --platform: its prefetchers on (next-line at L1, stride at L2: "
                             "coherence.platforms.PREFETCHERS_ON, docs/prefetch.md) or off; the run table then "
                             "counts prefetches issued, useful and useless per level (default: the platform's own; "
                             "the presets have none)")
    parser.add_argument("--json", action="store_true", help="print summary.json to stdout instead of the verdict")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from analyses.report import MISS_MAP_FILES, REPORT_FILES, build_report, parse_miss_map, write_report

    from analyses.commands import checks

    # every user error surfaces here or in build_report, before rendering
    check_at_least(args, size=1, max_processes=1, cpus=1, background=0, background_footprint=0, page_seed=0,
                   processes=1)
    checks.check_max_depth(args.max_depth)
    checks.check_scene_argument(args.scene)
    checks.check_memory("--size", args.size)
    miss_map = parse_miss_map(args.miss_map, "--miss-map")
    if args.dask:
        checks.require_distributed()
    platform = _platform(args)
    out = args.out if args.out is not None else f"report-{Path(args.scene).stem.lower()}"
    counts = args.processes if args.processes else range(1, args.max_processes + 1)
    if platform is not None and not given(args, "processes") and not given(args, "max_processes"):
        counts = platform.default_processes()
    # a variant that changes the platform is passed as the object; otherwise the name stays as given
    changed = {"platform": platform} if platform is not None and platform.name != args.platform else {}
    experiment = experiment_from_args(args, n_processes=tuple(counts), **changed)
    report = build_report(experiment, out=out, miss_map=miss_map)
    path = write_report(report, out)
    others = [REPORT_FILES["results"], REPORT_FILES["summary"], *(MISS_MAP_FILES if report.miss_map is not None else ())]
    print(f"wrote {path / REPORT_FILES['page']}, {', '.join(others)}"
          f"{' (trace from cache)' if report.render_info.get('cached') else ''}", file=sys.stderr)
    if args.json:
        print(json.dumps(report.summary, indent=2))
    else:
        print(report.verdict.headline)
        for sentence in report.verdict.sentences:
            print("  " + sentence)
    return 0


def _platform(args: argparse.Namespace):
    """``--platform``'s :class:`coherence.platforms.Platform` with ``--prefetch`` applied, or None."""
    from coherence.platforms import get_platform
    from rtcommon.validate import InputError

    if args.platform is None:
        if args.prefetch is not None:
            raise InputError(f"--prefetch {args.prefetch} switches a platform's prefetchers; give --platform NAME")
        return None
    platform = get_platform(args.platform)
    return platform if args.prefetch is None else platform.variant(prefetch=args.prefetch == "on")
