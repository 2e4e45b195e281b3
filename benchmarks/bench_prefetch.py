"""Throughput of the cache simulator with prefetchers on against off, on one stream.

The stream is bench_cachesim's seeded ray-tracer-like one (bursts of consecutive
8-byte reads around a drifting position in a 4 MB scene, occasional far jumps).
It runs through the ``modern`` hierarchy (32 KB / 1 MB / 32 MB, non-inclusive)
and the inclusive ``alpha21164``: without prefetchers (the default kernels),
with a next-line prefetcher (tagged, degree 1) on L1, and with a stride
prefetcher (degree 2) on L1 and a next-line one on L2. The PC-like id of an
access is its 1 MB region of the scene (four ids), a stand-in for record kinds.
Then the shared-cache simulator (:func:`cachesim.multicore.simulate_threads`)
on the same stream cut into 8 consecutive parts, one per thread, interleaved
64 accesses at a time (Q = 64 accesses), on ``modern``'s levels with L1 and
L2 private to each of 8 cores and L3 shared: off, and with the same
prefetchers (the region as the kind). Prints accesses/s, L1 and last-level
misses and the prefetchers' counts, then one JSON line.

    python benchmarks/bench_prefetch.py [--accesses N] [--repeats R]
"""
import argparse
import json
from dataclasses import replace

import numpy as np

from bench_cachesim import ray_tracer_like_stream
from cachesim import Hierarchy, Prefetcher, SharedHierarchy, get_hierarchy, simulate
from cachesim.interleave import interleave
from cachesim.multicore import simulate_threads
from timing import best_of


def with_prefetchers(hierarchy: Hierarchy, prefetchers) -> Hierarchy:
    """``hierarchy`` with ``prefetchers[l]`` (None: none) on level ``l``."""
    levels = tuple(replace(level, prefetcher=prefetcher)
                   for level, prefetcher in zip(hierarchy.levels, list(prefetchers) + [None] * len(hierarchy.levels)))
    return replace(hierarchy, levels=levels)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--accesses", type=int, default=2_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    stream = ray_tracer_like_stream(args.accesses)
    pcs = ((stream - np.uint64(0x10000000)) >> np.uint64(20)).astype(np.int64)
    setups = {
        "off": [],
        "next-line L1": [Prefetcher("next-line")],
        "stride L1 + next-line L2": [Prefetcher("stride", degree=2), Prefetcher("next-line")],
    }
    figures = {"stream": "ray_tracer_like_stream", "accesses": int(stream.size)}
    for preset in ("modern", "alpha21164"):
        base = get_hierarchy(preset)
        off_rate = None
        for label, prefetchers in setups.items():
            hierarchy = with_prefetchers(base, prefetchers)
            simulate(stream[:1000], hierarchy, pcs=pcs[:1000])  # compile outside the timing
            seconds, result = best_of(args.repeats, lambda: simulate(stream, hierarchy, pcs=pcs))
            rate = stream.size / seconds / 1e6
            off_rate = rate if off_rate is None else off_rate
            line = (f"{preset:11s} {label:26s} {rate:7.2f} M accesses/s ({rate / off_rate:5.2f} x off)  "
                    f"L1 misses {result.misses[0]:>9,}  memory {result.memory_accesses:>8,}")
            if result.prefetch_counts is not None:
                issued, useful, useless = result.prefetch_counts.sum(axis=0)
                line += f"  prefetches issued {issued:,} useful {useful:,} useless {useless:,}"
            print(line, flush=True)
            figures[f"{preset} {label}"] = {"maccesses_per_s": rate, "l1_misses": int(result.misses[0]),
                                            "memory_accesses": result.memory_accesses}
    n_threads = 8
    parts = np.array_split(np.arange(stream.size), n_threads)
    addresses, threads = interleave([stream[part] for part in parts], quantum=64)
    kinds = np.empty_like(pcs)
    for thread, part in enumerate(parts):
        kinds[threads == thread] = pcs[part]
    off_rate = None
    for label, prefetchers in setups.items():
        machine = SharedHierarchy(with_prefetchers(get_hierarchy("modern"), prefetchers), n_cores=n_threads,
                                  shared_by=("core", "core", "machine"))
        simulate_threads(addresses[:1000], threads[:1000], machine, kinds=kinds[:1000])
        seconds, result = best_of(args.repeats, lambda: simulate_threads(addresses, threads, machine, kinds=kinds))
        rate = addresses.size / seconds / 1e6
        off_rate = rate if off_rate is None else off_rate
        totals = result.level_counts()
        line = (f"8 threads   {label:26s} {rate:7.2f} M accesses/s ({rate / off_rate:5.2f} x off)  "
                f"L1 misses {totals[0, 2]:>9,}  memory {totals[-1, 2]:>8,}")
        if result.prefetch_counts is not None:
            issued, useful, useless = result.prefetch_counts.sum(axis=(0, 1))
            line += f"  prefetches issued {issued:,} useful {useful:,} useless {useless:,}"
        print(line, flush=True)
        figures[f"8 threads Q=64 {label}"] = {"maccesses_per_s": rate, "l1_misses": int(totals[0, 2]),
                                              "memory_accesses": int(totals[-1, 2])}
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
