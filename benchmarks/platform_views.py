"""How far a platform's per-thread view is from its shared levels: misses per level, both ways.

Until the schedule interleaves threads at shared levels, a run under
``--platform`` gives each hardware thread its own copy of every level, a
shared level cut to the thread's share (:meth:`coherence.platforms.Platform.thread_view`).
This script measures what that misses. The stream: balls rendered by the
study-era workload (which logs its per-ray data and frame-buffer writes),
a static mapping's pixels on ``n`` hardware threads taking turns one pixel
at a time (:func:`coherence.thread_streams.thread_stream`, alpha1997
layout). It is replayed twice: exactly, through the platform's shared
hierarchy with write-invalidate coherence
(:func:`cachesim.multicore.simulate_threads`), and per thread through the
thread view (:func:`cachesim.simulate` on each thread's own accesses),
summed. Printed per platform, mapping, thread count and level: misses both
ways and their ratio, and the exact run's coherence misses. No timing.

    python benchmarks/platform_views.py [--size 64] [--mappings S P] [--threads 4 8 16] [--cache DIR]
"""
import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from analyses.traces import cached_trace
from cachesim import simulate
from cachesim.multicore import simulate_threads
from coherence.layout import get_layout
from coherence.platforms import PLATFORMS, get_platform
from coherence.studies import place_layout
from coherence.thread_streams import thread_stream


def compare(platform, trace, placed, mapping: str, n_threads: int) -> list[dict]:
    """Per level: misses through the shared hierarchy and through the per-thread view, for one stream."""
    line = platform.hierarchy.hierarchy.levels[0].line_size
    stream = thread_stream(trace, placed, mapping, n_threads, line_size=line)
    exact = simulate_threads(stream.addresses, stream.threads, platform.hierarchy, writes=stream.writes,
                             sizes=stream.sizes, kinds=stream.kinds).level_frame()
    view = platform.thread_view()
    view_misses = np.zeros(len(view.levels), dtype=np.int64)
    for thread in range(n_threads):
        mine = stream.threads == thread
        result = simulate(stream.addresses[mine], view, writes=stream.writes[mine])
        view_misses += result.counts[:, 2]
    rows = []
    for index, level in enumerate(view.level_names):
        shared = int(exact["misses"][index])
        rows.append({"platform": platform.name, "mapping": mapping, "threads": n_threads, "level": level,
                     "shared_by": platform.hierarchy.shared_by[index], "exact_misses": shared,
                     "view_misses": int(view_misses[index]),
                     "view_over_exact": float(view_misses[index] / shared) if shared else float("nan"),
                     "coherence_misses": int(exact["coherence_misses"][index])})
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--mappings", nargs="+", default=["S", "P"])
    parser.add_argument("--threads", type=int, nargs="+", default=[4, 8, 16])
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "coherence-bench")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    scene, trace, _ = cached_trace("balls", args.size, cache_dir=args.cache, progress=False, workload="study1997")
    placed = place_layout(get_layout("alpha1997"), trace, scene)
    rows = []
    print("platform    mapping threads level shared_by  exact_misses  view_misses  view/exact  coherence")
    for name in PLATFORMS:
        platform = get_platform(name)
        for mapping in args.mappings:
            for n_threads in args.threads:
                if n_threads > platform.n_threads:
                    continue
                for row in compare(platform, trace, placed, mapping, n_threads):
                    rows.append(row)
                    print(f"{row['platform']:11s} {mapping:7s} {n_threads:7d} {row['level']:5s} "
                          f"{row['shared_by']:9s} {row['exact_misses']:13,d} {row['view_misses']:12,d} "
                          f"{row['view_over_exact']:11.2f} {row['coherence_misses']:10,d}", flush=True)
    print(json.dumps({"size": args.size, "rows": rows}))


if __name__ == "__main__":
    main()
