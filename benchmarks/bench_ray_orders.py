"""Ray orders: how long each takes to order a path-traced trace, and its misses per ray on one process.

Run:  python3 benchmarks/bench_ray_orders.py [--scene balls] [--size 64] [--spp 2] [--processes 8]
      [--treelet-bytes 8192] [--hierarchy alpha21164]

Path-traces the scene once (logged), then for every order of
:data:`coherence.ray_orders.RAY_ORDERS` (the treelet queues at ``--treelet-bytes``): the wall
time of :func:`~coherence.ray_orders.order_pieces` over the rays of
``--processes`` strips (the units a static mapping gives, each ordered on
its own: the work the report does per order), best of ``--repeats``; then
process 0's strip replayed through the hierarchy from empty caches
(:func:`~coherence.ray_orders.replay_order`), misses per ray (every segment
a ray, shadow rays included) at each level, with and without the order's
own records (the scene's misses alone in brackets), and those records.
The peer in the same run is the depth-first order, which adds nothing. The
last line printed is one JSON object with every figure.
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from benchmarks.timing import best_of
from cachesim import get_hierarchy
from coherence.layout import get_layout, record_counts_of
from coherence.mappings import Strip
from coherence.ray_orders import RAY_ORDERS, TreeletQueues, order_pieces, replay_order, scene_bounds_of
from tracer.kd.tree import build_kdtree
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import load
from tracer.trace.segments import SegmentColumn


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="balls")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=2)
    parser.add_argument("--max-depth", type=int, default=None)
    parser.add_argument("--processes", type=int, default=8)
    parser.add_argument("--treelet-bytes", type=int, default=8192)
    parser.add_argument("--hierarchy", default="alpha21164")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    scene = load(args.scene, max_depth=args.max_depth)
    tree = build_kdtree(scene)
    result = render(scene, tree, RenderOptions(size=args.size, workload="pathtrace", spp=args.spp, log=True))
    trace = result.trace
    segments, records = trace.segments, np.asarray(trace.records)
    layout = get_layout("compact")
    placed = layout.place(record_counts_of(trace))
    hierarchy = get_hierarchy(args.hierarchy)
    bounds = scene_bounds_of(segments)
    distribution = Strip().build(trace.width, trace.height, args.processes)
    seg_offsets = np.searchsorted(segments.ints[:, SegmentColumn.PIXEL], np.arange(trace.width * trace.height + 1))
    units = []
    for process in range(args.processes):
        pixels = distribution.process_pixels(process)
        units.append(np.concatenate([np.arange(seg_offsets[p], seg_offsets[p + 1]) for p in pixels]))
    figures = {"scene": scene.name, "size": args.size, "spp": args.spp, "processes": args.processes,
               "segments": segments.n_segments, "records": int(trace.n_records), "hierarchy": hierarchy.name,
               "orders": {}}
    print(f"{scene.name} {args.size}x{args.size} spp {args.spp}: {segments.n_segments:,} rays, "
          f"{int(trace.n_records):,} records; {args.processes} strips, process 0 replayed on {hierarchy.name}")
    treelet = TreeletQueues(treelet_bytes=args.treelet_bytes, node_bytes=layout.record("kd_node").size)
    orders = [treelet if order.name == treelet.name else order for order in RAY_ORDERS.values()]
    for order in orders:
        def all_units():
            return [order_pieces(segments, rows, order, scene_bounds=bounds, tree=tree, records=records)
                    for rows in units]

        seconds, pieces = best_of(args.repeats, all_units)
        replay = replay_order(records, pieces[0], placed, hierarchy)
        # the same order without its own records: what the reordering does to the scene's misses alone
        bare = pieces[0]._replace(aux_records=np.zeros(0, np.uint32), aux_after=np.zeros(0, np.int64))
        scene_only = replay_order(records, bare, placed, hierarchy)
        n_rays = units[0].size
        misses = {level.name: int(replay.counts[i, 2]) / n_rays for i, level in enumerate(hierarchy.levels)}
        scene_misses = {level.name: int(scene_only.counts[i, 2]) / n_rays for i, level in enumerate(hierarchy.levels)}
        counts = pieces[0].aux_counts()
        figures["orders"][order.name] = {"order_seconds": seconds, "misses_per_ray": misses,
                                         "scene_misses_per_ray": scene_misses,
                                         "pieces": pieces[0].n_pieces, **counts,
                                         "sort_cycles": pieces[0].sort_cycles}
        shown = " ".join(f"{name} {value:.2f} ({scene_misses[name]:.2f})" for name, value in misses.items())
        print(f"{order.name:14s} ordered in {seconds:7.3f} s; process 0: misses/ray (scene's alone) {shown}; "
              f"{pieces[0].n_pieces:,} pieces, {pieces[0].aux_records.size:,} own records "
              f"(queue {counts['queue_reads'] + counts['queue_writes']:,}), sort {pieces[0].sort_cycles:,.0f} cycles")
    print(json.dumps(figures))
    return figures


if __name__ == "__main__":
    main()
