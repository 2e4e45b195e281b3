"""Both phases of ``coherence robustness`` against the issue's budgets, with the share of runs not simulated.

Renders (or loads from the trace cache) every trace the study will read
(each scene's tree variants at ``--size``, the base's tree at half and
twice it for the size check) and compiles the kernels first, untimed. Then
one :func:`analyses.robustness.robustness` call per scene with
``--trajectories`` Morris trajectories, the size check and Sobol's design of
``--sobol`` base samples, every phase timed (wall and this process's CPU
time) and printed as the scene ends.

The budgeted designs are larger than the measured ones; their times are
**projected** from the measured rates (a design's time grows with its
samples; the size check is run once a scene whatever the design):

- Morris screening, r = 10 trajectories over every unknown (17 samples
  each) per scene, plus the size check: target <= 20 minutes;
- Sobol over the top 4 unknowns with N = 64 (N (4 + 2) = 384 samples) per
  scene: target <= 60 minutes.

Both are printed at the measured wall rate (the machine may be shared with
other work) and, for the target's 2 idle cores, from the measured CPU rate:
between CPU time / 2 (``study`` keeps both cores busy with a sample's runs,
one thread per CPU) and CPU time (one core busy). A target counts as met
when even the slower bound meets it. With each phase, the
share of its runs that were re-costed from stored miss counts and reused
(:mod:`coherence.recost`). Ends with one JSON line.

    python benchmarks/bench_robustness.py [--size 256] [--trajectories 2] [--sobol 2] [--scenes balls tetra ...]
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
from analyses.robustness import ROBUSTNESS_EXPERIMENT, SOBOL_FACTORS, robustness  # noqa: E402
from analyses.robustness_factors import FACTORS  # noqa: E402
from analyses.robustness_size import check_sizes  # noqa: E402
from coherence.unknowns import TREE_VARIANTS  # noqa: E402
from tracer.scenes.catalog import PAPER_SCENES  # noqa: E402

MORRIS_TARGET_SECONDS = 20 * 60.0
SOBOL_TARGET_SECONDS = 60 * 60.0
BUDGET_TRAJECTORIES = 10
BUDGET_SOBOL = 64
CORES = 2


def prepare(base, scenes) -> float:
    """Compile the kernels and render or load every trace the study reads; seconds taken."""
    from analyses.traces import cached_trace

    start = time.perf_counter()
    robustness(replace(base, size=16), scenes=scenes[:1], trajectories=2, sobol=2)  # compile
    for scene in scenes:
        sizes = [(variant, base.size) for variant in TREE_VARIANTS]
        sizes += [(base.tree_variant, size) for size in check_sizes(base.size)]
        for variant, size in sizes:
            cached_trace(scene, size, kd=base.kd_builder(), max_depth=None, progress=False, workload=base.workload,
                         tree_variant=variant)
    return time.perf_counter() - start


def scene_phases(result, timings) -> dict:
    """Per phase of one scene's study: seconds, CPU seconds, samples and run paths."""
    (scene, summary), = result.summary["scenes"].items()
    phases = {}
    for phase in ("morris", "size_check", "sobol"):
        design = result.samples["design"]
        phases[phase] = {**timings[scene][phase], "samples": int((design == phase).sum()),
                         "runs": summary["sobol"]["runs"] if phase == "sobol" else
                         summary["runs"] if phase == "morris" else dict.fromkeys(("simulated", "re_costed", "reused"), 0)}
    return phases


def add_phases(totals: dict, phases: dict) -> None:
    """Add one scene's ``phases`` into ``totals`` (same shape)."""
    for phase, figures in phases.items():
        total = totals.setdefault(phase, {"seconds": 0.0, "cpu_seconds": 0.0, "samples": 0,
                                          "runs": dict.fromkeys(figures["runs"], 0)})
        for key in ("seconds", "cpu_seconds", "samples"):
            total[key] += figures[key]
        for path, count in figures["runs"].items():
            total["runs"][path] += count


def share(runs: dict) -> str:
    total = sum(runs.values())
    if not total:
        return "no runs counted"
    return (f"{runs['simulated']} runs simulated, {runs['re_costed']} re-costed ({100 * runs['re_costed'] / total:.0f}%),"
            f" {runs['reused']} reused ({100 * runs['reused'] / total:.0f}%)")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--trajectories", type=int, default=2)
    parser.add_argument("--sobol", type=int, default=2, help="Sobol base samples measured (a power of two)")
    parser.add_argument("--scenes", nargs="+", default=list(PAPER_SCENES))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    base = replace(ROBUSTNESS_EXPERIMENT, size=args.size)
    warnings.simplefilter("ignore")
    prepared = prepare(base, args.scenes)
    print(f"{len(args.scenes)} scene(s) at {args.size}x{args.size}; {os.cpu_count()} CPUs here; traces and "
          f"compilation before, untimed: {prepared:.0f} s", flush=True)
    totals, per_scene = {}, {}
    for scene in args.scenes:
        timings = {}
        result = robustness(base, scenes=[scene], trajectories=args.trajectories, seed=args.seed, sobol=args.sobol,
                            timings=timings)
        per_scene[scene] = scene_phases(result, timings)
        add_phases(totals, per_scene[scene])
        print(f"{scene}: " + "; ".join(f"{phase} {f['samples']} samples {f['seconds']:.0f} s wall "
                                       f"{f['cpu_seconds']:.0f} s CPU, {share(f['runs'])}"
                                       for phase, f in per_scene[scene].items()), flush=True)
    morris, check, sobol = (totals[phase] for phase in ("morris", "size_check", "sobol"))
    n_scenes = len(args.scenes)
    morris_samples = BUDGET_TRAJECTORIES * (len(FACTORS) + 1) * n_scenes
    sobol_samples = BUDGET_SOBOL * (SOBOL_FACTORS + 2) * n_scenes
    projected = {}
    for rate, spread in (("seconds", 1.0), ("cpu_seconds", 1.0), ("cpu_seconds_on_cores", float(CORES))):
        measured = rate.replace("_on_cores", "")
        projected[rate] = {
            "morris": (morris[measured] * morris_samples / morris["samples"] + check[measured]) / spread,
            "sobol": sobol[measured] * sobol_samples / sobol["samples"] / spread}
    print(f"measured Morris: {args.trajectories} trajectories x {len(FACTORS) + 1} samples a scene: "
          f"{morris['samples']} samples in {morris['seconds']:.0f} s wall, {morris['cpu_seconds']:.0f} s CPU; "
          f"{share(morris['runs'])}")
    print(f"measured size check: {check['seconds']:.0f} s wall, {check['cpu_seconds']:.0f} s CPU "
          f"(5 samples a scene at {' and '.join(map(str, check_sizes(args.size)))})")
    print(f"measured Sobol: N = {args.sobol} over the top {SOBOL_FACTORS}: {sobol['samples']} samples in "
          f"{sobol['seconds']:.0f} s wall, {sobol['cpu_seconds']:.0f} s CPU; {share(sobol['runs'])}")
    for phase, samples, target in (("morris", morris_samples, MORRIS_TARGET_SECONDS),
                                   ("sobol", sobol_samples, SOBOL_TARGET_SECONDS)):
        wall, one, both = (projected[rate][phase] for rate in ("seconds", "cpu_seconds", "cpu_seconds_on_cores"))
        design = (f"r = {BUDGET_TRAJECTORIES} over {len(FACTORS)} unknowns + size check" if phase == "morris"
                  else f"N = {BUDGET_SOBOL} over {SOBOL_FACTORS} unknowns")
        verdict = ("met" if one <= target else f"NOT met ({both / target:.1f}x over even with both cores busy)"
                   if both > target else "met only if both cores stay busy")
        print(f"projected {phase} ({design}, {samples} samples): {wall:.0f} s at the measured wall rate; on "
              f"{CORES} idle cores from the CPU rate between {both:.0f} s (both busy) and {one:.0f} s (one busy); "
              f"target <= {target:.0f} s: {verdict}")
    print(json.dumps({"size": args.size, "scenes": args.scenes, "trajectories": args.trajectories,
                      "sobol": args.sobol, "morris": morris, "size_check": check, "sobol_phase": sobol,
                      "per_scene": per_scene, "budget_morris_samples": morris_samples,
                      "budget_sobol_samples": sobol_samples,
                      "projected_seconds": {k: {p: round(v, 1) for p, v in d.items()} for k, d in projected.items()},
                      "targets": {"morris": MORRIS_TARGET_SECONDS, "sobol": SOBOL_TARGET_SECONDS},
                      "cpus": os.cpu_count()}, default=float))


if __name__ == "__main__":
    main()
