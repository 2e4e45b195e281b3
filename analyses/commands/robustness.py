"""``coherence robustness``: how the verdict holds across what the model does not know about the 1997 machine."""
from __future__ import annotations

import argparse

from analyses.commands.options import HelpFormatter, cache_options, check_at_least, dask_options, size_options

HELP = "the verdict under uncertainty: Morris screening over the study's unknowns, per scene"

EPILOG = """\
Every unknown of docs/unknowns.md (memory and B-cache latency, page
placement, memory image, other users' count and footprint, time slice, data
TLB and its miss cost, square-root cost, five operation costs, tree variant)
is sampled over its documented range by Morris trajectories (SALib, six
levels). Each scene's trace is rendered once per tree variant (study-era
workload) and every sample replays the trace of its variant: every mapping
at 1 and 8 processes, all sharing the
sample's values and seeds. A run whose schedule does not depend on cycles
(one process per CPU, a static mapping or one process) is re-costed from the
miss counts of an earlier sample that differs from it only in costs or in
the other users' count and footprint (they run on CPUs of their own); the
rest are simulated. With --sobol N,
first-order and total Sobol indices of the top four unknowns follow.
The 8-process losses and the verdict need --size >= 256. The size check
simulates the one-process B - S and DB - S of 5 samples at half and twice
--size (128 and 512 at the default) and says, per quantity, whether the
smaller image is within 10% of the larger at every point.

Output folder (default robustness):
  samples.csv       one row per scene x sample: outputs and sampled values
  indices.csv       Morris mu*, mu, sigma, rank (and Sobol S1, ST) per scene x unknown
  robustness.json   parameters, seed, versions and per scene the summary
  index.html        one self-contained page with tornado charts
and with --faithfulness-md FILE the faithfulness section, Markdown generated
from robustness.json alone.
The same inputs and --seed give byte-identical files.
Progress: when stderr is a terminal, a bar there per scene and phase counts
the samples (Morris, size check, Sobol), and a trace being rendered shows
its own; --no-progress turns them off. Files and stdout are the same either
way.
Time: on 2 cores, one scene at the defaults (256x256, 10 trajectories, size
check) takes up to about 18 minutes (room), the five scenes about 53; a
Sobol study with --sobol 64 adds up to about an hour a scene (balls, room).
--dask spreads the runs over more cores (docs/usage.md has the figures).

examples:
  coherence robustness --scenes tetra --size 64 --trajectories 4
  coherence robustness --size 256 --trajectories 10 --json
  coherence robustness --scenes balls --size 64 --trajectories 4 --sobol 16
"""


def register(subparsers) -> None:
    """Add the ``robustness`` subcommand to ``subparsers``."""
    parser = subparsers.add_parser("robustness", help=HELP, description=HELP[0].upper() + HELP[1:], epilog=EPILOG,
                                   formatter_class=HelpFormatter,
                                   parents=[size_options(256, "256x256, the smallest size the 8-process losses "
                                                              "and the verdict are computed at"),
                                            cache_options(), dask_options()])
    parser.add_argument("--scenes", nargs="+", metavar="SCENE",
                        help="the study's scenes, any of %(paper_scenes)s (default: all of them)")
    parser.add_argument("--trajectories", type=int, default=10, metavar="R",
                        help="Morris trajectories, >= 2 (default 10); each is one sample per unknown plus one")
    parser.add_argument("--seed", type=int, default=0, metavar="S",
                        help="seed of the design, the page placements and the other users' streams (default 0)")
    parser.add_argument("--sobol", type=int, default=0, metavar="N",
                        help="then Sobol indices over the top 4 unknowns by Morris mu*, from N (k + 2) samples per "
                             "scene, N a power of two (default 0: none)")
    parser.add_argument("--no-size-check", dest="size_check", action="store_false",
                        help="skip the size check (the one-process quantities at half and twice --size on 5 "
                             "samples; by default part of the output)")
    parser.add_argument("--out", metavar="DIR", default="robustness", help="output folder (default robustness)")
    parser.add_argument("--json", action="store_true", help="print robustness.json to stdout")
    parser.add_argument("--no-progress", dest="progress", action="store_false",
                        help="no progress bars (by default, when stderr is a terminal, a bar per scene and phase "
                             "counts the samples: Morris, size check, Sobol)")
    parser.add_argument("--faithfulness-md", metavar="FILE",
                        help="also write the faithfulness section (Markdown) generated from robustness.json to "
                             "FILE; python -m analyses.faithfulness regenerates it from a stored robustness.json")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from dataclasses import replace

    from analyses.cluster import dask_executor
    from analyses.commands.checks import check_memory, require_distributed
    from analyses.output import check_output_folder
    from analyses.paper_study import check_scenes
    from analyses.robustness import ROBUSTNESS_EXPERIMENT, robustness
    from analyses.robustness_output import ROBUSTNESS_FILES, robustness_summary, write_robustness
    from analyses.traces import check_cache_dir
    from rtcommon.files import check_writable_ancestor
    from rtcommon.validate import require_power_of_two
    from tracer.scenes.catalog import PAPER_SCENES

    # every user error surfaces here, before any rendering
    check_at_least(args, size=1, trajectories=2, seed=0, sobol=0)
    if args.sobol:
        require_power_of_two("--sobol", args.sobol)
    if args.dask:
        require_distributed()
    check_memory("--size", args.size)
    check_cache_dir(args.cache)
    scenes = check_scenes(args.scenes if args.scenes else PAPER_SCENES)
    check_output_folder(args.out)
    if args.faithfulness_md:
        check_writable_ancestor(args.faithfulness_md, "--faithfulness-md")
    base = replace(ROBUSTNESS_EXPERIMENT, size=args.size, cache_dir=args.cache,
                   progress=args.progress and sys.stderr.isatty())
    with dask_executor(args.dask) as executor:
        result = robustness(base, scenes=scenes, trajectories=args.trajectories, seed=args.seed, sobol=args.sobol,
                            size_check=args.size_check, executor=executor)
    path = write_robustness(result, args.out)
    print(f"wrote {path / ROBUSTNESS_FILES['page']}, "
          f"{', '.join(name for role, name in ROBUSTNESS_FILES.items() if role != 'page')}", file=sys.stderr)
    if args.faithfulness_md:
        from analyses.faithfulness import write_faithfulness

        write_faithfulness(json.loads((path / ROBUSTNESS_FILES["summary"]).read_text(encoding="utf-8")),
                           args.faithfulness_md)
        print(f"wrote {args.faithfulness_md}", file=sys.stderr)
    if args.json:
        print(json.dumps(robustness_summary(result), indent=2, allow_nan=False))
    else:
        for scene, summary in result.summary["scenes"].items():
            print(f"{scene}: P(load balance) = {summary['p_load_balance']:.2f} over {summary['n_evaluations']} "
                  f"evaluations; top unknowns {', '.join(summary['top'])}")
    return 0
