"""The report's miss-ratio curves: exact fully associative LRU misses of the one-process streams.

:func:`miss_ratio_curves` takes every distinct one-process pixel order of the
compared mappings (S, P and R share the scan order) and, for each line size
of the hierarchy, counts the reuse distances of that order's stream
(:class:`cachesim.ReuseCounter`), fed in pieces of :data:`CURVE_PIECE`
records so that memory stays small whatever the trace's length. The curves
run two at a time: the compiled steps release the GIL.
"""
from __future__ import annotations

import math
import os
import sys

import numpy as np
import pandas as pd

from coherence.kind_misses import gather_records


def one_process_orders(mapping_objects, width, height) -> list[tuple[str, np.ndarray]]:
    """Distinct pixel orders of the mappings run by one process, labelled by the mappings sharing them."""
    orders = []
    for mapping in mapping_objects:
        order = np.ascontiguousarray(mapping.build(width, height, 1).task_pixels, dtype=np.int64)
        for entry in orders:
            if np.array_equal(entry[1], order):
                entry[2].append(mapping.name)
                break
        else:
            orders.append([None, order, [mapping.name]])
    scan = np.arange(width * height, dtype=np.int64)
    labelled = []
    for _, order, users in orders:
        base = "scan" if np.array_equal(order, scan) else f"{users[0]} order"
        labelled.append((f"{base} ({' '.join(users)})", order))
    return labelled


#: Records per piece of a miss-ratio curve's stream (16 MB of records, 32-64 MB of addresses).
CURVE_PIECE = 1 << 22


def pieces(lengths, budget):
    """``(first, stop)`` ranges of consecutive entries of ``lengths`` (records per pixel) holding
    about ``budget`` records each (at least one pixel per piece)."""
    ends = np.cumsum(lengths)
    first = 0
    while first < lengths.size:
        base = ends[first - 1] if first else 0
        stop = max(first + 1, int(np.searchsorted(ends, base + budget, side="right")))
        yield first, stop
        first = stop


def curve_sizes(line_size: int, hierarchy, top_bytes: int) -> np.ndarray:
    top = max(top_bytes, max(level.size for level in hierarchy.levels)) * 2
    powers = line_size * 2 ** np.arange(int(math.ceil(math.log2(max(top / line_size, 2)))) + 1)
    return np.unique(np.concatenate([powers, [level.size for level in hierarchy.levels]]).astype(np.int64))


def miss_ratio_curves(trace, placed, mapping_objects, hierarchy, progress) -> pd.DataFrame:
    from concurrent.futures import ThreadPoolExecutor

    from tqdm.auto import tqdm

    from cachesim import ReuseCounter

    orders = one_process_orders(mapping_objects, trace.width, trace.height)
    line_sizes = sorted({level.line_size for level in hierarchy.levels}, reverse=True)
    offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    bar = tqdm(total=len(orders) * len(line_sizes), desc="reuse distances", unit="curve",
               disable=not progress, leave=False, file=sys.stderr)

    records = np.asarray(trace.records)
    lengths = np.diff(offsets)

    def curve_of(label, order, line_size):
        # The stream is fed in pieces of about CURVE_PIECE records, so memory stays small whatever the
        # trace's length; the compiled steps release the GIL, so two curves run side by side.
        counter = ReuseCounter(line_size)
        buffer = np.empty(0, dtype=np.uint32)
        for first, stop in pieces(lengths[order], CURVE_PIECE):
            n = int(lengths[order[first:stop]].sum())
            if n > buffer.size:
                buffer = np.empty(n, dtype=np.uint32)
            gather_records(offsets, records, order[first:stop], buffer)
            counter.update(placed.addresses(buffer[:n], line_size))
        curve = counter.profile().miss_ratio_curve(curve_sizes(line_size, hierarchy, placed.scene_bytes))
        bar.update(1)
        return curve.assign(order=label, line_size=line_size)

    for line_size in line_sizes:  # compile the steps once, before the threads race to
        empty = np.empty(0, dtype=np.uint32)
        gather_records(offsets, records, orders[0][1][:0], empty)
        ReuseCounter(line_size).update(placed.addresses(empty, line_size))
    jobs = [(label, order, line_size) for label, order in orders for line_size in line_sizes]
    workers = max(1, min(2, os.cpu_count() or 1, len(jobs)))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        frames = list(pool.map(lambda job: curve_of(*job), jobs))
    bar.close()
    curves = pd.concat(frames, ignore_index=True)
    return curves[["order", "line_size", "size", "capacity_lines", "misses", "miss_ratio"]]
