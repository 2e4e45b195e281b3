"""CPU time of the schedule on a platform's shared levels with its prefetchers off and on.

Balls at ``--size`` (default 128), rendered as every run under a platform
renders it (per-ray data and frame-buffer writes logged; trace-cached),
the platform's shared levels (default ``zen4-7950x``) at the default
interleaving Q, and the runs a report makes most of: S, P and DB at 16
processes and P at 4. Each run is timed in process CPU seconds, best of
``--repeats``, after one untimed run that loads the compiled kernels; the
peer is the same runs without prefetchers, in the same session. Prints
seconds and accesses per second per run, the totals and their ratio,
then one JSON line.

    python benchmarks/bench_schedule_prefetch.py [--size 128] [--platform zen4-7950x] [--repeats 3]
"""
import argparse
import json
import time

RUNS = (("S", 16), ("P", 16), ("DB", 16), ("P", 4))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--platform", default="zen4-7950x")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cache", default=None, help="trace cache folder (default the toolkit's)")
    args = parser.parse_args()

    from analyses.experiment import Experiment
    from analyses.traces import cached_trace
    from coherence.mappings import get_mapping
    from coherence.platforms import get_platform
    from coherence.shared_run import pixel_pieces, simulate_shared_run
    from coherence.studies import place_layout
    from tracer.trace.access import COUNTER_NAMES

    experiment = Experiment(scene="balls", size=args.size, platform=args.platform)
    scene, trace, _ = cached_trace("balls", args.size, cache_dir=args.cache, workload=experiment.trace_workload(),
                                   progress=False)
    placed = place_layout(experiment.layout_object(), trace, scene)
    platform = get_platform(args.platform)
    machine = experiment.machine()
    pieces = pixel_pieces(trace, placed, platform.hierarchy.hierarchy.levels[0].line_size)
    compute = platform.cost.compute_cycles(trace.counters, COUNTER_NAMES)
    accesses = int(pieces.addresses.shape[0])
    figures = {}
    for switch in ("off", "on"):
        shared = platform.variant(prefetch=switch == "on").hierarchy

        def run(mapping, n):
            return simulate_shared_run(trace, get_mapping(mapping).build(args.size, args.size, n), shared, placed,
                                       platform.cost, machine, interleave_cycles=experiment.interleave_cycles,
                                       compute=compute, pieces=pieces)

        run("S", 2)  # loads (or compiles) the kernels
        for mapping, n in RUNS:
            best = float("inf")
            for _ in range(args.repeats):
                start = time.process_time()
                result = run(mapping, n)
                best = min(best, time.process_time() - start)
            issued = 0 if result.shared.prefetch_counts is None else int(result.shared.prefetch_counts[..., 0].sum())
            figures[f"{switch} {mapping}@{n}"] = best
            print(f"prefetch {switch:<3} {mapping:>2} at {n:>2}: {best:7.3f} s CPU, "
                  f"{accesses / best / 1e6:6.1f} M accesses/s, prefetches issued {issued:,}", flush=True)
    totals = {switch: sum(seconds for key, seconds in figures.items() if key.startswith(switch))
              for switch in ("off", "on")}
    print(f"balls {args.size}x{args.size} on {args.platform}, {accesses:,} accesses a run, Q = "
          f"{experiment.interleave_cycles}: off {totals['off']:.3f} s, on {totals['on']:.3f} s CPU "
          f"({totals['on'] / totals['off']:.2f}x)")
    print(json.dumps({"benchmark": "schedule_prefetch", "size": args.size, "platform": args.platform,
                      "accesses_per_run": accesses, "interleave_cycles": experiment.interleave_cycles,
                      "cpu_seconds": figures, "total_off": totals["off"], "total_on": totals["on"]}))


if __name__ == "__main__":
    main()
