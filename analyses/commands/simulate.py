"""``coherence simulate``: replay a saved trace under mappings on a simulated machine."""
from __future__ import annotations

import argparse

from analyses.commands.options import (PLACEMENTS, SCHEDULERS, HelpFormatter, check_platform_options, given,
                                       machine_options, model_options)
from rtcommon.validate import InputError

HELP = "simulate work distributions of a saved trace: speed-ups, balance and coherence"

EPILOG = """\
TRACE is a folder written by 'coherence render SCENE --trace TRACE'. Every
mapping is also run by one process, the reference of its speed-up.

mappings: S (strips), P (pixels), R (rows), B (64x64 fields cut in n blocks),
DB (32x32 blocks handed out on demand), and orders along space-filling curves
(see --mapping).

columns: speedup_user = T1 / worst process user time (the study's
definition); efficiency = speedup / n = load_balance x coherence_factor x
dispatch_factor; hit rates and misses per ray per cache level.

examples:
  coherence render balls --size 128 --trace balls128
  coherence simulate balls128 --mapping S --mapping R --processes 8
  coherence simulate balls128 --mapping DB --processes 2 4 8 16 --cpus 8 --background 4
  coherence simulate balls128 --hierarchy modern --layout alpha1997 --json
  coherence simulate balls128 --processes 16 --scheduler static --placement neighbours
  coherence simulate balls128 --background 4 --background-footprint 262144 --hierarchy alpha21164-dtb
  coherence simulate balls128 --layout alpha1997 --page-placement random --page-seed 3
  coherence simulate balls128 --platform zen4-7950x --mapping S --mapping P --processes 8 16 32
"""


def register(subparsers) -> None:
    """Add the ``simulate`` subcommand to ``subparsers``."""
    machine = machine_options(processes=[8], processes_help="process counts (default: 8, one per CPU)",
                              background=0, background_why="an idle machine, no other users")
    parser = subparsers.add_parser("simulate", help=HELP, description=HELP[0].upper() + HELP[1:] + ".",
                                   epilog=EPILOG, formatter_class=HelpFormatter, parents=[machine, model_options()])
    parser.add_argument("trace", metavar="TRACE", help="trace folder saved by 'coherence render --trace'")
    parser.add_argument("--mapping", action="append", metavar="NAME",
                        help="mapping to simulate, any of %(mappings)s (repeatable; default: %(default_mappings)s)")
    parser.add_argument("--quantum", type=float, default=3e6, metavar="CYCLES",
                        help="time slice of processes sharing a CPU; 0 runs them one after another "
                             "(default: 3e6, 10 ms at 300 MHz)")
    parser.add_argument("--scheduler", default="shared-queue", choices=SCHEDULERS, metavar="NAME",
                        help="the operating system: %(choices)s; shared-queue = one run queue for all CPUs, a "
                             "process moves to whichever CPU is free at the end of a time slice and finds the "
                             "caches other processes left there; static = every process pinned to one CPU "
                             "(default %(default)s)")
    parser.add_argument("--placement", default="round-robin", choices=PLACEMENTS, metavar="NAME",
                        help="static scheduler: how processes are pinned to CPUs when there are more of them: "
                             "%(choices)s (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print JSON (runs and parameters) instead of a table")
    parser.add_argument("--csv", metavar="PATH", help="write the full per-run table to CSV (+ .meta.json)")
    parser.add_argument("--processes-csv", metavar="PATH", help="write the per-process table to CSV")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from analyses.commands import checks
    from analyses.experiment import platform_parameters
    from cachesim import get_hierarchy
    from coherence.platforms import SHARED_LEVELS_NOTE, get_platform
    from coherence.mappings import DEFAULT_MAPPINGS, get_mapping
    from coherence.page_placement import PagePlacement
    from coherence.metrics import EFFICIENCY_FACTORS
    from coherence.provenance import provenance, write_csv_atomic
    from coherence.shared_run import DEFAULT_INTERLEAVE_CYCLES, SharedLevels
    from coherence.simulation import Machine
    from coherence.studies import study
    from tracer.trace.access import AccessTrace

    # every user error surfaces here, before the trace is read
    checks.check_range("--processes", args.processes, 1)
    checks.check_range("--cpus", args.cpus, 1)
    checks.check_range("--background", args.background, 0)
    checks.check_range("--quantum", args.quantum, 0, float("inf"))
    checks.check_range("--background-footprint", args.background_footprint, 0)
    checks.check_range("--page-seed", args.page_seed, 0)
    check_platform_options(args)
    interleave = DEFAULT_INTERLEAVE_CYCLES if args.interleave_cycles is None else args.interleave_cycles
    if args.placement != "round-robin" and args.scheduler != "static":
        raise InputError(f"--placement {args.placement} needs --scheduler static (the {args.scheduler} "
                         "scheduler moves processes between CPUs)")
    if Path(args.hierarchy).suffix.lower() in (".toml", ".json"):
        checks.check_input_file("--hierarchy", args.hierarchy)
    platform = None if args.platform is None else get_platform(args.platform)
    if platform is not None:
        # the platform's machine: one CPU a hardware thread, the threads interleaving at its shared levels
        args.cpus, args.cost = platform.n_threads, platform.cost.name
        if not given(args, "processes"):
            args.processes = list(platform.default_processes())
    hierarchy = get_hierarchy(args.hierarchy) if platform is None else platform.hierarchy.hierarchy
    caches = hierarchy if platform is None else SharedLevels(platform.hierarchy, interleave)
    mappings = [get_mapping(name) for name in (args.mapping or DEFAULT_MAPPINGS)]
    footprint = {} if args.background_footprint is None else {"background_footprint": args.background_footprint}
    machine = Machine(n_cpus=args.cpus, quantum_cycles=args.quantum, scheduler=args.scheduler,
                      placement=args.placement, background_load=args.background,
                      page_placement=PagePlacement(args.page_placement, seed=args.page_seed), **footprint)
    for option, path in (("--csv", args.csv), ("--processes-csv", args.processes_csv)):
        if path:
            checks.check_output_file(option, path)
            checks.check_output_file(option, path + ".meta.json")
    if args.csv and args.processes_csv and Path(args.csv).resolve() == Path(args.processes_csv).resolve():
        raise InputError("--csv and --processes-csv name the same file")
    trace_path = Path(args.trace)
    if trace_path.exists() and not trace_path.is_dir():
        raise NotADirectoryError(f"TRACE {args.trace!r} is a file; expected a folder written by "
                                 "'coherence render --trace'")
    trace = AccessTrace.load(args.trace)
    result = study(trace, mappings, args.processes, hierarchy=caches, layout=args.layout, cost=args.cost,
                   machine=machine, progress=sys.stderr.isatty())
    extra = {} if platform is None else {"platform": platform_parameters(platform, interleave)}
    meta = provenance(trace=str(args.trace), scene=trace.metadata.get("scene"), **result.parameters, **extra)
    if args.csv:
        write_csv_atomic(result.runs, args.csv, meta)
    if args.processes_csv:
        write_csv_atomic(result.processes, args.processes_csv, meta)
    if args.json:
        runs = json.loads(result.runs.to_json(orient="records"))
        print(json.dumps({**meta, "runs": runs}, indent=2))
        return 0
    levels = hierarchy.level_names
    columns = ["mapping", "n_processes", "speedup_user", "speedup_real", "efficiency", *EFFICIENCY_FACTORS,
               *(f"{name}_hit_rate" for name in levels), f"{levels[-1]}_misses_per_ray"]
    print(f"{args.trace}: {trace.width}x{trace.height} pixels, {trace.n_records:,} records; "
          f"{hierarchy.name or 'hierarchy'} caches, {args.layout} layout, {args.cost} costs, "
          f"{machine.n_cpus} CPUs")
    if platform is not None:
        print(f"platform {platform.name}: {platform.n_threads} hardware threads, Q = {interleave} cycles; "
              f"{SHARED_LEVELS_NOTE}")
    print(result.runs[columns].to_string(index=False, float_format=lambda value: f"{value:.3f}"))
    return 0
