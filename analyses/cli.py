"""The ``coherence`` command line: a thin front end over the Python API.

It sits in :mod:`analyses`, the top layer (DESIGN.md §4): it imports
tracer, cachesim, coherence and analyses, and nothing imports it. Run it as
``coherence ...`` (the installed script) or ``python -m analyses ...``.

Each subcommand lives in its own module under :mod:`analyses.commands` and
exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` (a callable taking the parsed ``argparse.Namespace`` and
returning an exit status). Options that several subcommands share come from
:mod:`analyses.commands.options`. Heavy imports happen inside ``run`` so that
``coherence --help`` stays instant.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "analyses.commands.cachesim",
    "analyses.commands.scene",
    "analyses.commands.render",
    "analyses.commands.simulate",
    "analyses.commands.report",
    "analyses.commands.whatif",
    "analyses.commands.paper",
)


class UserError(Exception):
    """An error caused by the user's input; printed without a traceback."""


def build_parser() -> argparse.ArgumentParser:
    """The ``coherence`` parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="coherence",
        description=(
            "Cache-coherence analysis for parallel ray tracing: does cache "
            "coherence or load balance decide the speed-up of an image-space "
            "work distribution? Each subcommand has its own --help."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from coherence import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; return its exit status (2 for a user error, printed in one line)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    # Only the command line picks how figures are drawn: into files, never a window. Library code
    # leaves the backend alone so that a notebook keeps its inline one. Picked after parsing, so
    # that --help does not pay for importing matplotlib.
    import matplotlib

    matplotlib.use("Agg")
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as error:
        print(f"coherence {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
