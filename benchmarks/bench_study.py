"""Whole-study throughput: balls at 512x512, every built-in mapping, n = 1, 2, 4, 8, 16.

Renders the trace once (not timed; kept in a cache folder between runs), then
times ``coherence.study()`` with the alpha21164 hierarchy on 8 CPUs (n = 16
time-slices two processes per CPU), and prints the time and the accesses
simulated per second. As a peer, one run (R, 8 processes) is also simulated
the obvious way: materialise each process's address stream and run
``cachesim.simulate_many``. Then one run (R, 16 processes, 2 background
processes) under each scheduler, to show what the background's cache streams
and the shared run queue cost. Ends with one JSON line.

    python benchmarks/bench_study.py [--size 512] [--cache DIR]
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from analyses.traces import cached_trace
from cachesim import alpha21164, simulate_many
from coherence.layout import get_layout
from coherence.mappings import MAPPINGS, get_mapping
from coherence.simulation import SCHEDULERS, Machine, simulate_run
from coherence.studies import place_layout, study
from tracer.trace.access import AccessTrace


def balls_trace(size: int, folder: Path):
    """Balls and its trace, from the project's trace cache in ``folder`` (keyed
    by the tracer's source, so an older tracer's trace is never reused)."""
    scene, trace, info = cached_trace("balls", size, cache_dir=folder, progress=False)
    if not info.get("cached"):
        print(f"rendered balls {size}x{size} into {folder}", file=sys.stderr)
    return scene, trace


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "coherence-bench")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    scene, trace = balls_trace(args.size, args.cache)
    hierarchy = alpha21164()
    mappings = list(MAPPINGS)
    counts = [1, 2, 4, 8, 16]

    small = AccessTrace(trace.pixel_offsets[:1025] - 0, np.asarray(trace.records[:trace.pixel_offsets[1024]]),
                        np.asarray(trace.counters[:1024]), 32, 32, {})
    study(small, mappings, counts, hierarchy=hierarchy, progress=False)  # compile outside the timing

    start = time.perf_counter()
    result = study(trace, mappings, counts, hierarchy=hierarchy, scene=scene, progress=True)
    seconds = time.perf_counter() - start
    accesses = int(result.runs["L1_accesses"].sum())
    print(f"study: {len(mappings)} mappings x n = {counts}: {len(result.runs)} runs, {trace.n_records:,} "
          f"records each, {accesses:,} accesses in {seconds:.1f} s = {accesses / seconds / 1e6:.1f} M accesses/s")

    # Peer: materialise the streams of one run, then simulate_many.
    placed = place_layout(get_layout("compact"), trace, scene)
    distribution = get_mapping("R").build(trace.width, trace.height, 8)
    start = time.perf_counter()
    streams = []
    for process in range(8):
        pixels = distribution.process_pixels(process)
        records = np.concatenate([trace.records[trace.pixel_offsets[p]:trace.pixel_offsets[p + 1]]
                                  for p in pixels])
        streams.append(placed.addresses(records, 32))
    simulate_many(streams, hierarchy)
    peer_seconds = time.perf_counter() - start
    start = time.perf_counter()
    simulate_run(trace, distribution, hierarchy, placed, result_cost(result), Machine())
    ours_seconds = time.perf_counter() - start
    print(f"R x 8: ours {ours_seconds:.2f} s, materialise + simulate_many {peer_seconds:.2f} s "
          f"(ratio {peer_seconds / ours_seconds:.1f}x)")
    busy = {}
    for scheduler in SCHEDULERS:
        start = time.perf_counter()
        simulate_run(trace, get_mapping("R").build(trace.width, trace.height, 16), hierarchy, placed,
                     result_cost(result), Machine(scheduler=scheduler, background_load=2))
        busy[scheduler] = time.perf_counter() - start
    print("R x 16 with 2 background processes: " + ", ".join(f"{name} {value:.2f} s" for name, value in busy.items()))
    print(json.dumps({"size": args.size, "runs": len(result.runs), "study_seconds": seconds,
                      "accesses": accesses, "maccesses_per_s": accesses / seconds / 1e6,
                      "r8_ours_seconds": ours_seconds, "r8_peer_seconds": peer_seconds,
                      "peer_ratio": peer_seconds / ours_seconds,
                      **{f"r16_background_{name}_seconds": value for name, value in busy.items()}}))


def result_cost(result):
    from coherence.cost import CostModel

    return CostModel(**{key: value for key, value in result.parameters["cost"].items()})


if __name__ == "__main__":
    main()
