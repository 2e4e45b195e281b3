"""The study's reproduction as a user runs it: ``coherence paper`` wall time and peak memory.

Runs the CLI in a subprocess (peak memory from ``wait4``, as
``bench_report.py`` does) with the study-era workload at the study's
512x512, every scene, mapping and process count: about 200 simulated runs of
0.05-1.25 billion line accesses each. By default the traces come from the
user's trace cache (rendered there first if missing, which adds about a
minute); ``--fresh-traces`` renders them into a scratch cache inside the
timed run. Prints the figures beside issue 16's target (10 minutes on 2
cores) and ends with one JSON line.

    python benchmarks/bench_paper.py [--size 512] [--fresh-traces]
"""
import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_report import run  # noqa: E402
from analyses.paper_output import PAPER_FILES  # noqa: E402

TARGET_SECONDS = 600.0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--fresh-traces", action="store_true",
                        help="render the five traces into a scratch cache inside the timed run")
    args = parser.parse_args()

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    with tempfile.TemporaryDirectory(prefix="bench-paper-") as scratch:
        argv = ["paper", "--size", str(args.size), "--out", str(Path(scratch) / "out")]
        if args.fresh_traces:
            argv += ["--cache", str(Path(scratch) / "cache")]
        seconds, peak = run(argv, env)
        runs = sum(1 for _ in open(Path(scratch) / "out" / PAPER_FILES["runs"])) - 1
    print(f"coherence paper --size {args.size}{' (traces rendered in the run)' if args.fresh_traces else ''}: "
          f"{seconds:7.1f} s  peak {peak / 2**30:5.2f} GiB, {runs} rows of runs, {os.cpu_count()} CPUs")
    met = seconds <= TARGET_SECONDS
    print(f"target: <= {TARGET_SECONDS:g} s on 2 cores: {seconds:.1f} s: {'met' if met else 'NOT met'}")
    print(json.dumps({"size": args.size, "fresh_traces": args.fresh_traces, "seconds": round(seconds, 1),
                      "peak_gib": round(peak / 2**30, 3), "cpus": os.cpu_count(), "runs": runs,
                      "target_seconds": TARGET_SECONDS, "met": met}))


if __name__ == "__main__":
    main()
