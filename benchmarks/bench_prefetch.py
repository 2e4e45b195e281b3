"""Throughput of the cache simulator with prefetchers on against off, on one stream.

The stream is bench_cachesim's seeded ray-tracer-like one (bursts of consecutive
8-byte reads around a drifting position in a 4 MB scene, occasional far jumps).
It runs through the ``modern`` hierarchy (32 KB / 1 MB / 32 MB, non-inclusive)
and the inclusive ``alpha21164``: without prefetchers (the default kernels),
with a next-line prefetcher (tagged, degree 1) on L1, and with a stride
prefetcher (degree 2) on L1 and a next-line one on L2. The PC-like id of an
access is its 1 MB region of the scene (four ids), a stand-in for record kinds.
Prints accesses/s, L1 and last-level misses and the prefetchers' counts, then
one JSON line.

    python benchmarks/bench_prefetch.py [--accesses N] [--repeats R]
"""
import argparse
import json
from dataclasses import replace

import numpy as np

from bench_cachesim import ray_tracer_like_stream
from cachesim import Hierarchy, Prefetcher, get_hierarchy, simulate
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
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
