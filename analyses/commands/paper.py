"""``coherence paper``: the study reproduced, all five scenes beside its table and figures."""
from __future__ import annotations

import argparse

from analyses.commands.options import (HelpFormatter, cache_options, check_at_least, dask_options,
                                       experiment_from_args, machine_options, mappings_options,
                                       memory_budget_options, platform_options, size_options, workload_options)

#: The names of coherence.calibration.FITS, the default first (the parser is built without importing the
#: fit's dependencies; tests/test_paper.py checks the two agree).
FIT_CHOICES = ("priors", "study-bounds")

HELP = "the study reproduced: five scenes beside its table, calibrated times, speed-up figures, verdicts"

EPILOG = """\
For each scene (default all five: %(paper_scenes)s) the trace is
rendered once and cached (see 'coherence report --help' for the cache) with
the study-era workload: a spatial-median BSP with one rule for every scene,
the study's kind of shadow rays, and the tracer's own per-ray data, laid out
as a 1990s C tracer's structs (alpha1997 layout, docs/memory_image.md). One
sequential run with the strip mapping S gives the operation counters and the
simulated memory cycles; three costs are then fitted by least squares of
relative errors to the study's sequential S times (%(study_times)s at
512x512; scaled by pixel count at other sizes): cycles per intersection test,
per ray and per kd-node visit. With --fit priors (the default) each stays
inside its prior range, counted from the routine's instructions on the
21164 (docs/unknowns.md): sphere test 30-120, ray 75-300, node visit 15-60;
the triangle test and a light's shading are tied to the sphere test inside
their own priors (50-200, 120-480), the other operations by their routines'
floating-point operation counts. What the model then does not explain is
each scene's unexplained_seconds, and a cost at a bound is flagged. With
--fit study-bounds each cost may take any value in 5-5000 cycles and every
other operation is tied to the test cost by its floating-point operation
count. Either way a sphere test with real roots pays the 21164's software
square root (90 cycles, fixed, not fitted) on top. Each scene is also
predicted from a fit to the other four. Then every
mapping runs at every process count on 8 simulated CPUs with the calibrated
model. Real time assumes --background always-runnable processes of other
users (default 2: a lone process runs at full speed, and real-time speed-up
keeps growing past 8 processes, as on the study's shared machine).

Output folder (default paper):
  paper.csv          one row per scene x mapping x process count
  scenes.csv         the study's table beside ours, calibrated times
  predictions.csv    every mapping's predicted one-process time and its gap to S
  paper.json         parameters, versions, calibration, residuals, verdicts
  speedup_real.png   speed-up from real time, one panel per scene
  speedup_user.png   speed-up from user time (worst process)
  index.html         one self-contained page with all of it
  today.csv          with --platform: the runs on that machine of today
The same inputs give byte-identical files.

examples:
  coherence paper                                   # 512x512, ~ minutes
  coherence paper --size 128 --out paper-128
  coherence paper --scenes balls tetra --processes 1 2 4 8 16
  coherence paper --dask tcp://scheduler:8786 --cache /shared/cache
  coherence paper --platform zen4-7950x --size 64   # beside a machine of today
"""


def register(subparsers) -> None:
    """Add the ``paper`` subcommand to ``subparsers``."""
    # the study's machine had 8 CPUs and the calibration assumes them: no --cpus here
    machine = machine_options(processes=None, processes_help="process counts (default the study's: "
                              "%(paper_processes)s; 1 is always added)", background=2,
                              background_why="a lone process runs at full speed, as the calibration to the "
                              "study's sequential times needs, and real-time speed-up keeps growing past 8 "
                              "processes as on the study's shared machine", cpus=False)
    parser = subparsers.add_parser("paper", help=HELP, description=HELP[0].upper() + HELP[1:], epilog=EPILOG,
                                   formatter_class=HelpFormatter,
                                   parents=[size_options(), mappings_options(), machine, cache_options(), dask_options(),
                                            memory_budget_options(runs_at_once=2),  # two scenes' runs at once
                                            workload_options("study1997", "the study's tracer, whose test counts "
                                                             "and memory image the calibration needs"),
                                            platform_options("for paper it is opt-in: a 'today' column beside "
                                                             "the study's machine, the same mappings and process "
                                                             "counts on the platform with its own cost model, not "
                                                             "fitted (today_* columns of scenes.csv, today.csv)")])
    parser.add_argument("--out", metavar="DIR", default="paper", help="output folder (default paper)")
    parser.add_argument("--scenes", nargs="+", metavar="SCENE",
                        help="the study's scenes, any of %(paper_scenes)s (default: all of them)")
    parser.add_argument("--fit", choices=FIT_CHOICES, default=FIT_CHOICES[0],
                        help="which cost fit: every cost inside its prior range (priors), or any value in "
                             "5-5000 cycles with flop-ratio ties (study-bounds) (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print paper.json to stdout instead of the verdicts")
    parser.add_argument("--crossover", action="store_true",
                        help="also find, per scene at 8 processes, how much bigger the records (x1..x64) and "
                             "slower the memory (x1..x64) would have to be before P or R lose more to coherence "
                             "than S loses to imbalance (48 more runs per scene; crossover.csv, crossover.png)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys

    from analyses.paper import (PAPER_EXPERIMENT, check_output_folder, check_scenes, paper_summary, reproduce,
                                write_paper)
    from analyses.paper_output import CROSSOVER_FILES, PAPER_FILES
    from analyses.paper_today import TODAY_FILES
    from coherence.calibration import FITS
    from tracer.scenes.catalog import PAPER_SCENES

    # every user error surfaces here, before any rendering
    from analyses.commands.checks import check_memory, require_distributed
    from analyses.traces import check_cache_dir

    check_at_least(args, size=1, background=0, background_footprint=0, page_seed=0, processes=1)
    if args.dask:
        require_distributed()
    check_memory("--size", args.size)
    experiment = experiment_from_args(args, PAPER_EXPERIMENT)
    check_cache_dir(args.cache)
    scenes = check_scenes(args.scenes if args.scenes else PAPER_SCENES)
    out = check_output_folder(args.out)
    result = reproduce(experiment, scenes=scenes, costs=FITS[args.fit], crossover=args.crossover)
    path = write_paper(result, out)
    others = [name for role, name in PAPER_FILES.items() if role != "page"]
    others += list(CROSSOVER_FILES.values()) if result.crossover is not None else []
    others += list(TODAY_FILES.values()) if result.today is not None else []
    print(f"wrote {path / PAPER_FILES['page']}, {', '.join(others)}", file=sys.stderr)
    if args.json:
        print(json.dumps(paper_summary(result), indent=2, allow_nan=False))
    else:
        cal = result.calibration
        fitted = ", ".join(f"{cost['name']} {cost['cycles']:.0f} ({cost['low']:g}-{cost['high']:g})"
                           for cost in cal["fitted"])
        print(f"calibrated cycles: {fitted}; RMS relative error {cal['rms_relative_error'] * 100:.1f}%, "
              f"each scene predicted from the others {cal['left_out_rms_relative_error'] * 100:.1f}%")
        print("at a bound: " + (", ".join(cal["at_bound"]) if cal["at_bound"] else "none"))
        unexplained = cal["residuals"]
        print("not explained by the model (s at 512x512): " + ", ".join(
            f"{row.scene} {row.unexplained_seconds_at_512:+.1f}" for row in unexplained.itertuples()))
        for text in result.verdicts["text"]:
            print(text)
        if result.today is not None:
            for text in result.today["verdicts"]["text"]:
                print(f"today, on {result.today['platform']['name']}: {text}")
    return 0
