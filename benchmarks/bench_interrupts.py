"""Ctrl-C at random times into a warm report: does every run end the way an interrupted Unix tool does?

Runs ``coherence report SCENE --size N`` once to warm the trace cache and
time a whole warm run (``T``), then ``--runs`` more, each sent one SIGINT
after a delay drawn uniformly (seeded) from ``[0, T)``. A run is clean when
it dies by SIGINT (a shell reports 130) and its stderr, beside what the
report says anyway (warnings, the files it wrote), is the one line
``coherence report: interrupted`` (``coherence: interrupted`` while the
command line is still loading). Prints each run that is not clean and
the tally; a run that ended before its SIGINT was sent is counted apart.

    python benchmarks/bench_interrupts.py [--runs 50] [--seed 0] [--scene balls] [--size 64] [--cache DIR]
"""
import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _report(args, folder: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "COHERENCE_CACHE": str(args.cache), "MPLBACKEND": "Agg"}
    return subprocess.Popen([sys.executable, "-m", "analyses", "report", args.scene, "--size", str(args.size),
                             "--out", str(folder / "report")], cwd=folder, env=env, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=_interruptible)


def _interruptible():
    # a shell starts background jobs with SIGINT ignored, and Python would keep ignoring it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _said(err: str) -> list[str]:
    """stderr's lines beside what a report says anyway: its warnings and the files it wrote."""
    return [line for line in err.strip().splitlines() if not line.startswith(("coherence: warning:", "wrote "))]


def interrupted_run(args, folder: Path, delay: float) -> tuple[str, int, str]:
    """One report sent SIGINT ``delay`` seconds after its start: (outcome, return code, stderr)."""
    process = _report(args, folder)
    time.sleep(delay)
    if process.poll() is not None:
        outcome = "ended first"
    else:
        process.send_signal(signal.SIGINT)
        outcome = None
    _, err = process.communicate(timeout=600)
    if outcome is None:
        said = _said(err)
        clean = process.returncode == -signal.SIGINT and said in (["coherence report: interrupted"],
                                                                   ["coherence: interrupted"])
        outcome = "clean" if clean else f"exit {process.returncode}"
    return outcome, process.returncode, err


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scene", default="balls")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "coherence-bench-interrupts")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        warm = _report(args, folder)
        _, err = warm.communicate()
        if warm.returncode != 0:
            sys.exit(f"the warm-up report failed ({warm.returncode}): {err[-500:]}")
        start = time.perf_counter()
        _report(args, folder).communicate()  # a second, warm run: its time is what the delays span
        whole = time.perf_counter() - start
        print(f"warm report {args.scene} --size {args.size}: {whole:.1f} s; {args.runs} SIGINTs in [0, {whole:.1f}) s "
              f"(seed {args.seed})", flush=True)
        rng = random.Random(args.seed)
        tally: dict[str, int] = {}
        for number in range(args.runs):
            delay = rng.uniform(0, whole)
            outcome, code, err = interrupted_run(args, folder, delay)
            tally[outcome] = tally.get(outcome, 0) + 1
            if outcome not in ("clean", "ended first"):
                lines = _said(err)
                print(f"run {number} at {delay:.2f} s: rc {code}, {len(lines)} stderr lines: "
                      f"{' | '.join(lines[-6:])[-600:]}", flush=True)
    interrupted = args.runs - tally.get("ended first", 0)
    print(f"{tally.get('clean', 0)} of {interrupted} interrupted runs died by SIGINT (130) with one line; "
          + ", ".join(f"{count} {outcome}" for outcome, count in sorted(tally.items()) if outcome != "clean"))


if __name__ == "__main__":
    main()
