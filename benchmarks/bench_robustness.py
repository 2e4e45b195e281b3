"""The Morris phase of ``coherence robustness``: wall time of the evaluations against the issue's budget.

Renders (or loads from the trace cache) every scene's trace and compiles
the kernels first, untimed, then times :func:`analyses.robustness.robustness`
(every sample simulated in full). Prints the seconds, the evaluations and
the seconds per evaluation, and the time the budgeted design (``--budget-
trajectories`` trajectories over every unknown, all scenes asked for) would
take at that rate, beside the target: <= 20 minutes on 2 cores. Ends with
one JSON line.

    python benchmarks/bench_robustness.py [--size 256] [--trajectories 10] [--scenes balls tetra ...]
"""
import argparse
import json
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from analyses.robustness import ROBUSTNESS_EXPERIMENT, robustness  # noqa: E402
from analyses.robustness_factors import FACTORS  # noqa: E402
from tracer.scenes.catalog import PAPER_SCENES  # noqa: E402

TARGET_SECONDS = 20 * 60.0
BUDGET_TRAJECTORIES = 10


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--trajectories", type=int, default=BUDGET_TRAJECTORIES)
    parser.add_argument("--scenes", nargs="+", default=list(PAPER_SCENES))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    base = replace(ROBUSTNESS_EXPERIMENT, size=args.size)
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    robustness(replace(base, size=16), scenes=args.scenes, trajectories=2, seed=args.seed)  # compile
    for scene in args.scenes:  # render or load each trace once, outside the timed phase
        from analyses.traces import cached_trace

        cached_trace(scene, args.size, kd=base.kd_builder(), max_depth=None, progress=False, workload=base.workload)
    prepare = time.perf_counter() - start
    start = time.perf_counter()
    result = robustness(base, scenes=args.scenes, trajectories=args.trajectories, seed=args.seed)
    seconds = time.perf_counter() - start
    evaluations = len(result.samples)
    per_evaluation = seconds / evaluations
    budgeted = BUDGET_TRAJECTORIES * (len(FACTORS) + 1) * len(args.scenes)
    projected = per_evaluation * budgeted
    print(f"Morris phase, {len(args.scenes)} scene(s) at {args.size}x{args.size}, {args.trajectories} trajectories "
          f"x {len(FACTORS) + 1}: {seconds:.1f} s for {evaluations} evaluations ({per_evaluation:.2f} s each; "
          f"traces and compilation before it {prepare:.1f} s), {os.cpu_count()} CPUs")
    met = projected <= TARGET_SECONDS
    print(f"target: r >= {BUDGET_TRAJECTORIES} over every unknown ({budgeted} evaluations) <= {TARGET_SECONDS:g} s "
          f"on 2 cores: {projected:.1f} s at this rate: {'met' if met else 'NOT met'}")
    print(json.dumps({"size": args.size, "scenes": args.scenes, "trajectories": args.trajectories,
                      "evaluations": evaluations, "seconds": round(seconds, 1),
                      "seconds_per_evaluation": round(per_evaluation, 3), "budgeted_evaluations": budgeted,
                      "projected_seconds": round(projected, 1), "target_seconds": TARGET_SECONDS, "met": met,
                      "cpus": os.cpu_count()}))


if __name__ == "__main__":
    main()
