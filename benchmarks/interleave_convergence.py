"""How the counts of a run on shared levels depend on the interleaving granularity ``Q`` (``--interleave-cycles``).

A report's experiment under ``--platform`` (balls, its default machine:
background load, shared run queue), at one process count, simulated on the
platform's shared levels (:func:`coherence.shared_run.simulate_shared_run`)
for each ``Q``. Printed per ``Q`` and mapping: our processes' misses at the
last level and the first, the machine's coherence and false-sharing misses
at the first level, and the last level's misses relative to ``Q = 1``
(the access-by-access interleaving); then the seconds each ``Q`` took. Ends
with one JSON line. The docs' table (docs/multicore.md) is this script's
output.

    python benchmarks/interleave_convergence.py [--platform zen4-7950x] [--size 64] [--processes 8]
                                                [--q 1 10 100 1000 10000 100000]
"""
import argparse
import json
import time

from analyses.experiment import Experiment
from analyses.traces import cached_trace
from coherence.shared_run import SharedLevels
from coherence.studies import Execution, study


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--platform", default="zen4-7950x")
    parser.add_argument("--scene", default="balls")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--processes", type=int, default=8)
    parser.add_argument("--q", type=int, nargs="+", default=[1, 10, 100, 1000, 10000, 100000])
    parser.add_argument("--cache", default=None, help="trace cache folder (default: the user's)")
    args = parser.parse_args()

    experiment = Experiment(scene=args.scene, size=args.size, platform=args.platform, progress=False,
                            cache_dir=args.cache)
    platform = experiment.platform_object()
    scene, trace, _ = cached_trace(experiment.scene, experiment.size, cache_dir=experiment.cache_dir,
                                   kd=experiment.kd_builder(), workload=experiment.trace_workload(), progress=False)
    layout = experiment.layout_object()
    levels = platform.hierarchy.hierarchy.level_names
    first, last = levels[0], levels[-1]
    print(f"{args.scene} {args.size}x{args.size}, {args.processes} processes on {platform.name} "
          f"({platform.n_threads} hardware threads), background {experiment.background}")
    print(f"{'Q':>7} {'mapping':>7} {last + ' misses':>12} {'vs Q=1':>8} {first + ' misses':>12} "
          f"{first + ' coherence':>13} {first + ' false sh.':>13}")
    figures = {"platform": platform.name, "scene": args.scene, "size": args.size, "processes": args.processes,
               "rows": [], "seconds": {}}
    reference = {}
    for q in args.q:
        start = time.perf_counter()
        result = study(trace, experiment.mapping_objects(), [args.processes],
                       hierarchy=SharedLevels(platform.hierarchy, q), layout=layout, cost=experiment.cost_model(),
                       machine=experiment.machine(), scene=scene, progress=False, execution=Execution())
        figures["seconds"][q] = round(time.perf_counter() - start, 2)
        runs = result.runs[result.runs["n_processes"] == args.processes]
        processes = result.processes[result.processes["n_processes"] == args.processes]
        for mapping in experiment.mapping_names():
            mine = processes[processes["mapping"] == mapping]
            row = runs[runs["mapping"] == mapping].iloc[0]
            misses = int(mine[f"{last}_misses"].sum())
            reference.setdefault(mapping, misses)
            ratio = misses / reference[mapping] if reference[mapping] else float("nan")
            entry = {"q": q, "mapping": mapping, f"{last}_misses": misses, "vs_q1": round(ratio, 5),
                     f"{first}_misses": int(mine[f"{first}_misses"].sum()),
                     f"{first}_coherence_misses": int(row[f"{first}_coherence_misses"]),
                     f"{first}_false_sharing_misses": int(row[f"{first}_false_sharing_misses"])}
            figures["rows"].append(entry)
            print(f"{q:>7} {mapping:>7} {misses:>12,} {ratio:>8.4f} {entry[f'{first}_misses']:>12,} "
                  f"{entry[f'{first}_coherence_misses']:>13,} {entry[f'{first}_false_sharing_misses']:>13,}")
    print("seconds per Q (all mappings, 1 and the process count):", figures["seconds"])
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
