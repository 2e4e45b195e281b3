"""False sharing, counter traffic and SMT on a platform's shared levels: the numbers of the "today" page.

Balls, rendered by today's tracer with its per-ray data and frame-buffer
writes logged (as every run under a platform renders it), the compact layout
with frame-buffer pixels of 3, 4 or 16 bytes. For each mapping and thread
count, the threads take turns of one pixel
(:func:`coherence.thread_streams.thread_stream`; DB's tasks round-robin,
each after a write of the shared task counter) and the interleaved stream
is replayed through the platform's shared hierarchy with write-invalidate
coherence (:func:`cachesim.multicore.simulate_threads`). SMT ``on`` packs
the threads two to a core (the platform's own machine); ``off`` gives each
its own core (:meth:`coherence.platforms.Platform.variant`), so only thread
counts up to the cores are run without SMT.

Writes ``OUT/sharing.csv``, one row per (mapping, threads, smt, pixel
size): misses per level, coherence and false-sharing misses summed over
levels, the counter's accesses and its coherence misses summed over levels
(a copy evicted before another thread's write is a capacity miss, not a
coherence miss, when its thread comes back), and
``memory_cycles``: every access's latency at the level that served it
(memory's past the last level), summed over threads.

    python docs/results/today_sharing.py --size 64 --platform zen4-7950x --out DIR
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
MAPPINGS = ("S", "P", "R", "B", "DB")
THREADS = (8, 16, 32)


def _row(platform, trace, placed, mapping: str, n_threads: int) -> dict:
    """One stream's counts on ``platform``'s machine."""
    from cachesim.multicore import COHERENCE_MISSES, FALSE_SHARING_MISSES, MISSES, simulate_threads
    from coherence.thread_streams import thread_stream
    from tracer.trace.records import AUXILIARY_KIND

    machine = platform.hierarchy
    stream = thread_stream(trace, placed, mapping, n_threads, line_size=machine.hierarchy.levels[0].line_size)
    result = simulate_threads(stream.addresses, stream.threads, machine, writes=stream.writes,
                              sizes=stream.sizes, kinds=stream.kinds)
    totals = result.level_counts()
    latencies = [level.latency for level in machine.hierarchy.levels] + [machine.hierarchy.memory_latency]
    counter = result.counts[:, :, AUXILIARY_KIND].sum(axis=(0, 1))
    row = {f"{name}_misses": int(totals[index, MISSES]) for index, name in enumerate(machine.hierarchy.level_names)}
    return {**row, "coherence_misses": int(totals[:, COHERENCE_MISSES].sum()),
            "false_sharing_misses": int(totals[:, FALSE_SHARING_MISSES].sum()),
            "counter_accesses": int((stream.kinds == AUXILIARY_KIND).sum()),
            "counter_coherence_misses": int(counter[COHERENCE_MISSES]),
            "memory_cycles": float(result.served.sum(axis=0) @ np.asarray(latencies, dtype=float))}


def sharing_table(size: int, platform_name: str, cache_dir) -> pd.DataFrame:
    """Every row of ``sharing.csv`` (see the module docstring)."""
    from analyses.experiment import Experiment
    from analyses.traces import cached_trace
    from coherence.layout import get_layout
    from coherence.platforms import get_platform
    from coherence.studies import place_layout

    experiment = Experiment(scene="balls", size=size, platform=platform_name, cache_dir=cache_dir, progress=False)
    scene, trace, _ = cached_trace("balls", size, cache_dir=cache_dir, progress=False,
                                   workload=experiment.trace_workload())
    platform = get_platform(platform_name)
    machines = {"on": platform, "off": platform.variant(smt=False)}
    rows = []
    for pixel_bytes in (3, 4, 16):
        placed = place_layout(get_layout("compact").with_frame_buffer(pixel_bytes), trace, scene)
        for n_threads in THREADS:
            for smt, machine in machines.items():
                if n_threads > machine.n_threads or (smt == "off" and machine is platform):
                    continue
                # every mapping at 3-byte pixels; the pixel size's effect on S and P only
                for mapping in MAPPINGS if pixel_bytes == 3 else ("S", "P"):
                    rows.append({"mapping": mapping, "threads": n_threads, "smt": smt,
                                 "frame_buffer_bytes": pixel_bytes,
                                 **_row(machine, trace, placed, mapping, n_threads)})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=64, help="image width and height (default 64)")
    parser.add_argument("--platform", default="zen4-7950x", help="a coherence.platforms preset")
    parser.add_argument("--cache", default=None, help="trace cache folder (default the toolkit's)")
    parser.add_argument("--out", type=Path, required=True, help="folder for sharing.csv")
    args = parser.parse_args(argv)
    if args.size < 1:
        parser.error(f"--size must be >= 1, got {args.size}")
    sys.path.insert(0, str(ROOT))
    from rtcommon.files import write_files_atomic

    table = sharing_table(args.size, args.platform, args.cache)
    args.out.mkdir(parents=True, exist_ok=True)
    write_files_atomic({args.out / "sharing.csv": table.to_csv(index=False).encode()})
    print(table.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
