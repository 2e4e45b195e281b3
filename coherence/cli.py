"""The ``coherence`` command line: a thin front end over the Python API.

Each subcommand lives in its own module under :mod:`coherence.commands` and
exposes ``register(subparsers)``, which adds its parser and sets
``func=run`` (a callable taking the parsed ``argparse.Namespace`` and
returning an exit status). Heavy imports happen inside ``run`` so that
``coherence --help`` stays instant.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "coherence.commands.cachesim",
    "coherence.commands.scene",
    "coherence.commands.render",
    "coherence.commands.simulate",
    "coherence.commands.report",
    "coherence.commands.whatif",
    "coherence.commands.paper",
)


class UserError(Exception):
    """An error caused by the user's input; printed without a traceback."""


def build_parser() -> argparse.ArgumentParser:
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
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as error:
        print(f"coherence {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
