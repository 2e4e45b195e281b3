"""``coherence cachesim``: run an address stream through a cache hierarchy."""
from __future__ import annotations

import argparse

from analyses.commands.options import HelpFormatter, hierarchy_options
from rtcommon.validate import InputError

EPILOG = """\
addresses file:
  .npy   a one-dimensional integer array (e.g. np.save("a.npy", addresses))
  other  text, one address per line, decimal (4096) or 0x-hex (0x1000);
         blank lines and '#' comments are skipped; ASCII (a UTF-8
         byte-order mark at the start is skipped)

hierarchy:
  alpha21164  8 KB direct-mapped 32 B / 96 KB 3-way 64 B / 4 MB direct-mapped 64 B
  modern      32 KB 8-way / 1 MB 16-way / 32 MB 16-way, 64 B lines
  FILE        a .toml or .json file, e.g. written by Hierarchy.save():

      name = "small"
      memory_latency = 80
      inclusion = "non-inclusive"       # or "inclusive", "exclusive"
      [[levels]]
      name = "L1"
      size = 8192
      line_size = 32
      assoc = 1                         # or "full"
      policy = "lru"                    # or "fifo", "random"
      latency = 2

examples:
  coherence cachesim trace.npy
  coherence cachesim addresses.txt --hierarchy modern --json
  coherence cachesim trace.npy --hierarchy my_cache.toml --csv levels.csv
"""


def register(subparsers) -> None:
    """Add the ``cachesim`` subcommand to ``subparsers``."""
    parser = subparsers.add_parser(
        "cachesim",
        help="run an address stream through a simulated cache hierarchy",
        description=(
            "Run a stream of byte addresses, in order, through a multi-level cache "
            "hierarchy and print accesses, hits, misses, evictions and hit rate per "
            "level. Every level sees only the misses of the level above."
        ),
        epilog=EPILOG,
        formatter_class=HelpFormatter,
        parents=[hierarchy_options()],
    )
    parser.add_argument("addresses", metavar="ADDRESSES", help="a .npy or text file of byte addresses")
    parser.add_argument("--json", action="store_true", help="print JSON with the same numbers instead of a table")
    parser.add_argument("--csv", metavar="PATH", help="also write the per-level table to a CSV file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from analyses.commands import checks
    from cachesim import CacheState, get_hierarchy, read_addresses, simulate
    from coherence.provenance import meta_path, provenance, write_csv_atomic

    # every user error surfaces here, before the stream is read
    checks.check_input_file("ADDRESSES", args.addresses)
    if Path(args.hierarchy).suffix.lower() in (".toml", ".json"):
        checks.check_input_file("--hierarchy", args.hierarchy)
    hierarchy = get_hierarchy(args.hierarchy)
    if args.csv:
        checks.check_output_file("--csv", args.csv)
        checks.check_output_file("--csv", meta_path(args.csv))
    try:
        state = CacheState(hierarchy)
    except MemoryError as error:
        raise InputError(f"--hierarchy {args.hierarchy}: {error}; use smaller caches") from None
    try:
        addresses = read_addresses(args.addresses)
        result = simulate(addresses, state)
    except MemoryError:
        size = Path(args.addresses).stat().st_size
        raise InputError(f"{args.addresses}: out of memory simulating its addresses ({size / 2**20:,.0f} MB "
                         "file); split the stream into shorter files") from None
    table = result.to_frame()
    meta = provenance(addresses=str(args.addresses), n_addresses=int(addresses.size))
    if args.csv:
        write_csv_atomic(table, args.csv, meta)
    if args.json:
        print(json.dumps({**meta, **result.to_dict()}, indent=2))
        return 0
    print(f"{args.addresses}: {addresses.size:,} addresses through {hierarchy.name or 'hierarchy'} "
          f"({hierarchy.inclusion})")
    shown = table.assign(hit_rate=table["hit_rate"].map(lambda rate: f"{rate:.4f}" if rate == rate else "-"))
    print(shown.drop(columns=["invalidations"] if not table["invalidations"].any() else []).to_string(index=False))
    print(f"memory accesses: {result.memory_accesses:,}")
    return 0
