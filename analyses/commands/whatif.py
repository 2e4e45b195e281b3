"""``coherence whatif``: sweep cache, latency, cost and scene parameters."""
from __future__ import annotations

import argparse

from analyses.commands.options import (HelpFormatter, cache_options, dask_options, mappings_options, platform_options,
                                       memory_budget_options, size_options, workload_options)
from rtcommon.validate import InputError

HELP = "what-if studies: where would coherence matter more than load balance?"

EPILOG = """\
built-in studies (STUDY):
  latency     memory latency x compute cycles per operation (a map)
  caches      L3 size x L2 size
  lines       line size of every level
  assoc       L1 associativity (1, 2, 4, 8, full)
  scene-size  SPD size factor of the scene x L3 size
  modern      alpha21164 vs modern caches x alpha8400 vs modern costs
  texture     texel order (linear, tiled4, morton, blocked4x8) x L1 size,
              on balls-textured with S, P, R, B, DB and hilbert: texel
              misses per texel read and the texels' share of the misses

your own grid: --grid NAME=V1,V2,... (repeatable), or --file STUDY.toml:

  scene = "balls"            # base configuration (all optional)
  size = 128
  mappings = ["S", "R", "DB"]
  n_processes = 8
  workload = "modern"        # also kd, max_depth, hierarchy, layout, cost,
                             # n_cpus, background, background_footprint,
                             # page_placement, page_seed, memory_budget
  [grid]
  memory_latency = [80, 320]
  "L3.size" = ["1MB", "4MB"]

parameters: memory_latency, <level>.size|line_size|assoc|latency|policy,
line_size, hierarchy, compute_scale, cost, layout, texture_layout
(linear, tiled<k>, morton, blocked<k>x<s>), scene_size, n_processes,
n_cpus, background, frame_buffer_bytes (3, 4, 16); the study's unknowns
that robustness samples, by its names (docs/unknowns.md): background_footprint
(bytes a slice of another user's process streams through its CPU's
caches), page_placement (contiguous, colouring, bin-hopping, random),
memory_image (compact, alpha1997, malloc1997: the layout) and tree_variant
(with --workload study1997; one trace per variant). Under --platform
also its variants: cores (complexes keep their size), smt (on, off or
threads per core), l3_size (the whole shared L3), prefetch (on, off:
next-line at L1, stride at L2; rows add <level>_prefetches_issued,
_useful, _useless). Sizes take KB/MB suffixes. On a textured scene the
CSV also has texel_<level>_misses_per_access and texture_<level>_miss_share.

outputs in --out DIR: whatif-<name>.csv (long form: the grid's columns,
mapping, n_processes, metric, value) with .meta.json, and whatif-<name>.png
(a map for two-parameter grids, loss lines for one). Grids over level
sizes also get whatif-<name>-lru.csv: the exact misses of fully
associative LRU caches of those sizes, from one reuse-distance pass per
process stream (the full simulation answers for the real caches).

where reordering rays pays for itself (--orders, path-traced): each point
renders a path-traced trace and reports, per mapping and ray order at the
one process count, the reordering gain and overhead of the report's
ray-order section and net_speedup (depth-first's slowest process time over
the order's). Grid parameters: scene, scene_size, spp, max_depth,
<level>.size; default base: balls 32x32, spp 1, P, 8 processes. Under
--platform every order runs on its shared levels (a size is one whole
level's). Writes whatif-orders.csv with .meta.json (analyses.order_whatif).

examples:
  coherence whatif latency --size 64
  coherence whatif --orders --grid spp=1,4 --grid L1.size=8KB,32KB --size 16
  coherence whatif --grid L1.size=4KB,8KB,32KB --grid memory_latency=80,300 --scene tetra
  coherence whatif caches --dask tcp://scheduler:8786
  coherence whatif --platform zen4-7950x --grid cores=4,8,16 --grid smt=on,off
  coherence whatif --scene balls --platform zen4-7950x --grid prefetch=on,off
"""


def register(subparsers) -> None:
    """Add the ``whatif`` subcommand to ``subparsers``."""
    # A study's defaults come from its file or the WhatIf dataclass, so these options only override
    # them; the image is smaller than elsewhere because a grid renders and replays many points.
    size = size_options(default=None, why="the study's, 128x128, small because every grid point is a "
                                          "full replay")
    mappings = mappings_options(why="the study's, %(default_mappings)s")
    workload = workload_options(default=None, why="the study's, modern")
    parser = subparsers.add_parser("whatif", help=HELP, description=HELP[0].upper() + HELP[1:],
                                   epilog=EPILOG, formatter_class=HelpFormatter,
                                   parents=[size, mappings, workload, cache_options(), dask_options("the grid points"),
                                            memory_budget_options(),
                                            platform_options("the process count stays the study's; a grid may "
                                                             "not vary hierarchy, cost or n_cpus")])
    parser.add_argument("study", nargs="?", metavar="STUDY", help="a built-in study (see below)")
    parser.add_argument("--grid", action="append", metavar="NAME=V1,V2", help="vary a parameter (repeatable)")
    parser.add_argument("--file", metavar="TOML", help="a study file with a [grid] table")
    parser.add_argument("--scene", metavar="SCENE",
                        help="a study scene (%(scenes)s) or a .nff/.obj path (default: the study's, balls)")
    parser.add_argument("--processes", type=int, metavar="N",
                        help="processes per run (default: the study's, 8; vary it with --grid n_processes=...)")
    parser.add_argument("--out", default="whatif", metavar="DIR", help="output folder (default: ./whatif)")
    parser.add_argument("--jobs", type=int, metavar="N", help="local worker processes (default: CPUs)")
    parser.add_argument("--list", action="store_true", help="list the built-in studies' grids and exit")
    parser.add_argument("--orders", action="store_true",
                        help="the path-traced ray orders' what-if: where reordering pays for itself (see below)")
    parser.set_defaults(func=run)


def build_study(args):
    from dataclasses import replace

    from analyses.commands.options import experiment_from_args
    from analyses.whatif import BUILTIN, WHATIF_EXPERIMENT, WhatIf, load_study_file, parse_grid_flag

    sources = sum(bool(source) for source in (args.study, args.grid, args.file))
    if sources != 1:
        raise InputError("give exactly one of: a built-in STUDY, --grid flags, or --file TOML")
    if args.study:
        if args.study not in BUILTIN:
            raise InputError(f"unknown study {args.study!r}: choose one of {', '.join(BUILTIN)}")
        study = BUILTIN[args.study]
    elif args.file:
        from analyses.commands.checks import check_input_file

        check_input_file("--file", args.file)
        study = load_study_file(args.file)
    else:
        pairs = [parse_grid_flag(flag) for flag in args.grid]
        names = [name for name, _ in pairs]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise InputError(f"--grid {repeated[0]} is given more than once; list every value in one flag "
                             f"({repeated[0]}=V1,V2,...)")
        # the base first: a grid over a platform's variants needs the platform the options give
        study = WhatIf(name="grid", experiment=experiment_from_args(args, WHATIF_EXPERIMENT), grid=dict(pairs))
    # the options given replace the study's base experiment; the rest stay the study's
    return replace(study, experiment=experiment_from_args(args, study.experiment))


def run(args: argparse.Namespace) -> int:
    if args.list:
        from analyses.whatif import BUILTIN

        for name, study in BUILTIN.items():
            print(f"{name:<11} " + "; ".join(f"{key} = {values}" for key, values in study.grid.items()))
        return 0
    from analyses.commands import checks
    from analyses.output import check_output_folder
    from analyses.traces import check_cache_dir

    # every user error surfaces here, before any trace is rendered
    checks.check_range("--jobs", args.jobs, 1)
    checks.check_range("--processes", args.processes, 1)
    checks.check_range("--size", args.size, 1)
    checks.check_scene_argument(args.scene, "--scene")
    if args.size is not None:  # before the memory budget's check, which would ask for more than the machine has
        checks.check_memory("--size", args.size)
    if args.orders:
        return run_orders(args)
    study = build_study(args)
    if args.dask:
        checks.require_distributed()
    check_cache_dir(args.cache)
    checks.check_memory("--size", study.size)
    out = check_output_folder(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from analyses.whatif import exact_lru_curves, lru_csv_path, run_whatif, save_whatif

    table = run_whatif(study, n_jobs=args.jobs)
    curves = exact_lru_curves(study)
    csv, png = save_whatif(table, study, out, curves)
    if curves is not None:
        print(f"exact fully associative LRU misses at the grid's sizes: {lru_csv_path(study, out)}")
    shown = [*study.grid, "mapping", "imbalance_loss", "coherence_loss", "verdict"]
    print(table[shown].to_string(index=False, float_format=lambda value: f"{value:.4f}"))
    print(f"wrote {csv} and {png}")
    return 0


def run_orders(args: argparse.Namespace) -> int:
    """``coherence whatif --orders --grid ...``: :func:`analyses.order_whatif.order_whatif` on the options' base."""
    from analyses.commands import checks
    from analyses.commands.options import experiment_from_args
    from analyses.order_whatif import ORDER_WHATIF_EXPERIMENT, order_whatif, parse_order_grid, save_order_whatif
    from analyses.output import check_output_folder
    from analyses.traces import check_cache_dir

    if args.study or args.file or not args.grid:
        raise InputError("--orders takes its grid from --grid flags only (no STUDY, no --file)")
    grid = parse_order_grid(args.grid)
    base = experiment_from_args(args, ORDER_WHATIF_EXPERIMENT)
    if args.dask:
        checks.require_distributed()
    check_cache_dir(args.cache)
    out = check_output_folder(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = order_whatif(base, grid, n_jobs=args.jobs)
    csv = save_order_whatif(table, base, grid, out)
    shown = [*grid, "mapping", "order", "reordering_gain", "reordering_overhead", "net_speedup"]
    print(table[shown].to_string(index=False, float_format=lambda value: f"{value:.4f}"))
    print(f"wrote {csv}")
    return 0
