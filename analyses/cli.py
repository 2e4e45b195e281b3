"""The ``coherence`` command line: a thin front end over the Python API.

It sits in :mod:`analyses`, the top layer (docs/design.md, "Layers"): it imports
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

from analyses.interrupts import InterruptsOutsideNumba, exit_by_sigint
from rtcommon.validate import InputError

# Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES = (
    "analyses.commands.cachesim",
    "analyses.commands.scene",
    "analyses.commands.render",
    "analyses.commands.simulate",
    "analyses.commands.report",
    "analyses.commands.whatif",
    "analyses.commands.paper",
    "analyses.commands.robustness",
)



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


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as ``coherence: warning: ...``, one line each (no source line under it)."""
    stream = file if file is not None else sys.stderr
    try:
        stream.write(f"coherence: warning: {message}\n")
    except (OSError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; return its exit status.

    2 for a user error, printed in one line: an :class:`InputError` (the
    toolkit's checks of what it was given), an ``OSError`` (a file it could
    not read or write), or running out of memory. 1 for any other exception:
    a bug, printed as its traceback and a line that says "internal error".
    130 after Ctrl-C (one line; a real command line, ``argv`` None, then
    dies by SIGINT at once, which its shell reports as 130). 141 (128 +
    SIGPIPE, as a C tool killed by it) without a word when the reader of the
    output went away (a closed pipe: ``| head``).

    A real command line (``argv`` None) that has finished ends its process
    once the exit handlers have run, skipping Python's teardown, during
    which Ctrl-C could no longer be caught (:func:`_leave_after_exit_handlers`).
    """
    if argv is not None:
        return _main(argv)
    import atexit

    ending: list[int] = []
    atexit.register(_leave_after_exit_handlers, ending)  # registered first, so it runs last
    status = _main(None)
    ending.append(status)
    return status


def _leave_after_exit_handlers(ending: list) -> None:
    """End a finished command line's process once the exit handlers have run, without Python's teardown.

    The teardown (modules, numba's and llvmlite's objects) takes about a
    second after a report and does nothing the run needs: every output is
    written and closed by then. It runs with signal handlers gone, so a
    Ctrl-C during it killed the process without a word. ``ending`` holds the
    exit status once the command has returned one (not after --help or an
    argparse error, which leave the normal way).
    """
    # os._exit is the documented way to end a process without clean-up; the underscore names what it skips
    from os import _exit as exit_without_teardown

    if not ending:
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    exit_without_teardown(ending[0])


def _main(argv: list[str] | None) -> int:
    words = sys.argv[1:] if argv is None else argv
    commands = {module.rpartition(".")[2] for module in COMMAND_MODULES}
    # named before parsing: a Ctrl-C during start-up says "coherence report: interrupted" too
    name = f"coherence {words[0]}" if words and words[0] in commands else "coherence"
    args = None
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        name = f"coherence {args.command}"
        status = _run(args, name)
        if argv is None:
            _interrupts_end_at_once(name)
        return status
    except (InputError, OSError) as error:
        if isinstance(error, BrokenPipeError):
            return _quiet_broken_pipe()
        print(f"{name}: error: {_error_text(error)}", file=sys.stderr)
        return 2
    except MemoryError:
        hint = "; try a smaller --size" if getattr(args, "size", None) is not None else ""
        print(f"{name}: error: out of memory{hint}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        if argv is None:
            exit_by_sigint(130)
        return 130
    except Exception as error:  # noqa: BLE001 - anything else is a bug: say so, with where it happened
        import traceback

        traceback.print_exc()
        print(f"{name}: internal error (a bug in the toolkit, not in what it was given): "
              f"{type(error).__name__}: {_error_text(error)}", file=sys.stderr)
        return 1


def _run(args: argparse.Namespace, name: str) -> int:
    import warnings

    # Only the command line picks how figures are drawn: into files, never a window. Library code
    # leaves the backend alone so that a notebook keeps its inline one. Picked after parsing, so
    # that --help does not pay for importing matplotlib.
    import matplotlib

    matplotlib.use("Agg")
    warnings.showwarning = _one_line_warning
    with InterruptsOutsideNumba(name):
        status = int(args.func(args) or 0)
    sys.stdout.flush()  # inside the caller's try: a closed pipe shows up here, not at exit
    return status


def _interrupts_end_at_once(name: str) -> None:
    """From now on Ctrl-C ends the process at once, in one line: the work is done, and what is left
    (Python's exit) would otherwise show a KeyboardInterrupt traceback or drop it."""
    import os
    import signal

    def interrupted(signum, frame):
        try:
            os.write(2, f"{name}: interrupted\n".encode())
        except OSError:
            pass
        exit_by_sigint(130)

    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored SIGINT stays ignored
        signal.signal(signal.SIGINT, interrupted)


def _error_text(error: Exception) -> str:
    """One line: the message, or for a bare OS error its reason and the file it names."""
    if isinstance(error, OSError) and error.strerror and error.filename:
        return f"{error.filename}: {error.strerror}"
    text = str(error).strip() or type(error).__name__
    return " ".join(text.splitlines())


def _quiet_broken_pipe() -> int:
    # The reader closed the pipe: say nothing, and keep Python from complaining at exit when it
    # flushes stdout into the same closed pipe.
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 141


if __name__ == "__main__":
    sys.exit(main())
