"""Shared-cache simulator throughput: 8 hardware threads, a shared L3, coherence on, prefetchers off.

The machine: the ``modern`` hierarchy's three levels (32 KB 8-way L1, 1 MB
16-way L2, 32 MB 16-way L3, 64-byte lines), L1 and L2 private to each of 8
cores (SMT 1), L3 shared by all. Timed: :func:`cachesim.multicore.simulate_threads`
on a whole stream (compiled outside the timing; its validation of the
stream included), against the issue's target of 100 M accesses/s, and
beside the peer :func:`cachesim.simulate` on the same addresses and writes
through one private ``modern`` hierarchy. Three streams, each naming its
interleaving granularity Q:

1. balls at ``--size`` (64) rendered by the study-era workload (which logs
   its ray stack, hit records, shading temporaries and frame-buffer
   writes), pixel ``k`` on thread ``k mod 8`` (the P mapping) and the
   pixels in image order, so the threads take turns one pixel at a time
   (Q = one pixel), built by :func:`coherence.thread_streams.thread_stream`
   (alpha1997 layout): each record is one access per line it spans, with
   its bytes in that line and its kind; the per-ray data (kinds 9 to 11)
   gets a region of its own per thread, the scene and frame buffer stay
   shared;
2. the ray-tracer-like stream of ``bench_cachesim.py`` (10 M accesses, a
   seeded 5% of them 8-byte writes) cut into 8 consecutive parts, one per
   thread, interleaved 64 accesses at a time (Q = 64 accesses);
3. the stream a report's run makes: balls at ``--report-size`` (128) by the
   study-era workload in the report's layout (compact), the B mapping on 8
   processes, in the order :func:`coherence.shared_run.simulate_shared_run`
   served it on this machine with the ``modern`` cost model at the default
   Q (:data:`coherence.shared_run.DEFAULT_INTERLEAVE_CYCLES` cycles), without
   other users' load (a logged run has none); task hand-outs would be writes
   of the task counter (B has none). Its replay is checked to give the run's
   own counts.

Rates are given by wall time and by CPU time of this process (the best of
the repeats each): on a machine shared with other work they differ; the
target is judged by CPU time. Ends with one JSON line.

    python benchmarks/bench_multicore.py [--size 64] [--report-size 128] [--repeats 3] [--cache DIR]
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from analyses.traces import cached_trace  # noqa: E402
from bench_cachesim import ray_tracer_like_stream  # noqa: E402
from cachesim import modern, simulate  # noqa: E402
from cachesim.interleave import interleave_order  # noqa: E402
from cachesim.multicore import simulate_threads  # noqa: E402
from cachesim.sharing import SharedHierarchy  # noqa: E402
from coherence.cost import COST_MODELS  # noqa: E402
from coherence.layout import get_layout  # noqa: E402
from coherence.mappings import get_mapping  # noqa: E402
from coherence.shared_run import DEFAULT_INTERLEAVE_CYCLES, pixel_pieces, simulate_shared_run  # noqa: E402
from coherence.shared_schedule import COUNTER_ACCESS  # noqa: E402
from coherence.simulation import Machine  # noqa: E402
from coherence.studies import place_layout  # noqa: E402
from coherence.thread_streams import COUNTER_BYTES, thread_stream  # noqa: E402
from tracer.trace.records import AUXILIARY_KIND  # noqa: E402

THREADS = 8
LINE = 64


def p_mapping_stream(size: int, folder: Path):
    """Addresses, thread ids, writes, sizes and kinds of the stream the module docstring names."""
    scene, trace, _ = cached_trace("balls", size, cache_dir=folder, progress=False, workload="study1997")
    stream = thread_stream(trace, place_layout(get_layout("alpha1997"), trace, scene), "P", THREADS, line_size=LINE)
    return stream.addresses, stream.threads, stream.writes, stream.sizes, stream.kinds


def report_run_stream(size: int, folder: Path, machine: SharedHierarchy):
    """Stream 3 of the module docstring: addresses, thread ids, writes, sizes and kinds in the order the run
    served them, and the run's counts per level, instance, kind and column."""
    scene, trace, _ = cached_trace("balls", size, cache_dir=folder, progress=False, workload="study1997")
    placed = place_layout(get_layout("compact"), trace, scene)
    run = simulate_shared_run(trace, get_mapping("B").build(size, size, THREADS), machine, placed,
                              COST_MODELS["modern"](), Machine(n_cpus=THREADS), record=("log",))
    pieces = pixel_pieces(trace, placed, LINE)
    addresses, threads, piece = run.log
    counter = piece == COUNTER_ACCESS
    writes = np.where(counter, True, pieces.writes[piece])
    sizes = np.where(counter, COUNTER_BYTES, pieces.sizes[piece])
    kinds = np.where(counter, AUXILIARY_KIND, pieces.kinds[piece]).astype(np.uint8)
    return addresses, threads, writes, sizes, kinds, run.shared.counts


def best_rates(repeats, n_accesses, function):
    """Accesses per second of ``function()`` by wall time and by CPU time, the best of ``repeats`` each."""
    wall = cpu = float("inf")
    result = None
    for _ in range(max(1, repeats)):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = function()
        wall = min(wall, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return n_accesses / wall, n_accesses / cpu, result


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--report-size", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "coherence-bench")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    machine = SharedHierarchy(modern(), n_cores=THREADS, smt=1, shared_by=("thread", "thread", "machine"))
    print(f"machine: modern levels, L1 and L2 private to each of {THREADS} cores, L3 shared by all; "
          "coherence on, prefetchers off")
    addresses, threads, writes, sizes, kinds = p_mapping_stream(args.size, args.cache)
    simulate_threads(addresses[:1000], threads[:1000], machine, writes=writes[:1000], sizes=sizes[:1000],
                     kinds=kinds[:1000])  # compile outside the timing
    print(f"\nstream 1: balls {args.size}x{args.size} (study1997 workload, alpha1997 layout), P mapping on "
          f"{THREADS} threads, Q = 1 pixel (a pixel per turn): {addresses.size:,} accesses, "
          f"{int(writes.sum()):,} writes")
    figures = timed(args.repeats, machine, (addresses, threads, writes, sizes, kinds), "", "stream 1 (Q = 1 pixel)")
    rng = np.random.default_rng(7)
    stream = ray_tracer_like_stream(10_000_000)
    flags = rng.random(stream.size) < 0.05
    order, threads = interleave_order([part.size for part in np.array_split(stream, THREADS)], quantum=64)
    addresses, writes = stream[order], flags[order]
    print(f"\nstream 2: bench_cachesim's ray-tracer-like stream, 8 consecutive parts on {THREADS} threads, "
          f"Q = 64 accesses: {addresses.size:,} accesses ({int(writes.sum()):,} writes)")
    figures.update(timed(args.repeats, machine, (addresses, threads, writes, np.where(writes, 8, 1), None),
                         "raytracer_like_", "stream 2 (Q = 64 accesses)"))
    *stream, run_counts = report_run_stream(args.report_size, args.cache, machine)
    print(f"\nstream 3: a report's run: balls {args.report_size}x{args.report_size} (study1997 workload, compact "
          f"layout), B mapping on {THREADS} processes, Q = {DEFAULT_INTERLEAVE_CYCLES} cycles, in the order "
          f"the shared schedule served it: {stream[0].size:,} accesses, {int(stream[2].sum()):,} writes")
    figures.update(timed(args.repeats, machine, stream, "report_run_",
                         f"stream 3 (Q = {DEFAULT_INTERLEAVE_CYCLES} cycles)", run_counts))
    print("\nby CPU time (M accesses/s; target 100): "
          + ", ".join(f"stream {number} {figures[prefix + 'cpu_maccesses_per_s']:.1f} "
                      f"(peer {figures[prefix + 'peer_cpu_maccesses_per_s']:.1f})"
                      for number, prefix in ((1, ""), (2, "raytracer_like_"), (3, "report_run_"))))
    print(json.dumps(figures))


def timed(repeats, machine, stream, prefix, name, run_counts=None):
    """Time simulate_threads on ``stream`` (addresses, threads, writes, sizes, kinds) and the peer; print
    and return the figures (``name``: the stream and its Q; ``run_counts``: the counts the stream's run gave,
    which the replay must equal)."""
    addresses, threads, writes, sizes, kinds = stream
    rate, cpu_rate, result = best_rates(repeats, addresses.size, lambda: simulate_threads(
        addresses, threads, machine, writes=writes, sizes=sizes, kinds=kinds))
    if run_counts is not None:
        same = np.array_equal(result.counts, run_counts)
        print(f"replay's counts equal the run's (every level, instance, kind and column): {'yes' if same else 'NO'}")
        if not same:
            raise SystemExit("the logged order does not replay to the run's counts")
    return report(result, rate, cpu_rate, peer_rates(repeats, addresses, writes), prefix, name)


def peer_rates(repeats, addresses, writes):
    """The peer's rates (wall, CPU): cachesim.simulate on the same addresses and writes, one private hierarchy."""
    simulate(addresses[:1000], modern(), writes=writes[:1000])
    wall, cpu, _ = best_rates(repeats, addresses.size, lambda: simulate(addresses, modern(), writes=writes))
    return wall, cpu


def report(result, rate, cpu_rate, peer, prefix, name):
    """Print one stream's counts, rates and target (``name``: the stream and its Q); return its figures."""
    counts = result.level_frame().set_index("level")
    print(counts[["accesses", "misses", "coherence_invalidations", "coherence_misses",
                  "false_sharing_misses"]].to_string())
    print(f"simulate_threads : {rate / 1e6:6.1f} M accesses/s wall, {cpu_rate / 1e6:6.1f} by CPU time  "
          "(8 threads, coherence on)")
    print(f"simulate (peer)  : {peer[0] / 1e6:6.1f} M accesses/s wall, {peer[1] / 1e6:6.1f} by CPU time  "
          "(the same addresses and writes, one private hierarchy)")
    print(f"ratio to the peer: {cpu_rate / peer[1]:.2f} by CPU time, {rate / peer[0]:.2f} wall")
    met = cpu_rate >= 100e6
    print(f"target: >= 100 M accesses/s with a shared L3 across 8 threads, coherence on, prefetchers off, on "
          f"{name}: {cpu_rate / 1e6:.1f} M/s by CPU time: {'met' if met else 'not met'}")
    return {f"{prefix}stream": name, f"{prefix}accesses": int(counts.accesses.iloc[0]), f"{prefix}maccesses_per_s": rate / 1e6,
            f"{prefix}cpu_maccesses_per_s": cpu_rate / 1e6, f"{prefix}peer_maccesses_per_s": peer[0] / 1e6,
            f"{prefix}peer_cpu_maccesses_per_s": peer[1] / 1e6, f"{prefix}cpu_ratio_to_peer": cpu_rate / peer[1],
            f"{prefix}target_met": bool(met),
            f"{prefix}coherence_misses": int(counts.coherence_misses.sum()),
            f"{prefix}false_sharing_misses": int(counts.false_sharing_misses.sum())}


if __name__ == "__main__":
    main()
