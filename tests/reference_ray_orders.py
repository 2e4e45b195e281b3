"""Slow, obvious references for the ray orders of coherence.ray_orders, and seeded random segments.

Events are tuples: ``("piece", first, stop)`` for a run of trace records,
``("state", slot, write)`` and ``("queue", slot, write)`` for the order's own
records.
"""
from __future__ import annotations

import numpy as np

from tracer.trace.segments import RaySegments, SegmentColumn, SegmentRayType


def random_segments(n_pixels=6, spp=2, seed=0, max_depth=4, max_shadows=2):
    """Seeded random segments of a path-traced trace, in depth-first order, tiling their records.

    Each path has 1..max_depth extension rays, each followed by 0..max_shadows
    shadow rays; segments read 0..5 records; origins, directions and hits
    are random (a hit is NaN one time in five).
    """
    rng = np.random.default_rng(seed)
    rows, position = [], 0
    for pixel in range(n_pixels):
        for sample in range(spp):
            for bounce in range(int(rng.integers(1, max_depth + 1))):
                kinds = [SegmentRayType.CAMERA if bounce == 0 else SegmentRayType.BOUNCE]
                kinds += [SegmentRayType.SHADOW] * int(rng.integers(0, max_shadows + 1))
                for kind in kinds:
                    length = int(rng.integers(0, 6))
                    rows.append((pixel, sample, bounce, int(kind), position, position + length))
                    position += length
    ints = np.array(rows, dtype=np.int64).reshape(-1, 6)
    rays = rng.uniform(-10.0, 10.0, (ints.shape[0], 9))
    rays[:, 3:6] /= np.linalg.norm(rays[:, 3:6], axis=1, keepdims=True)
    rays[rng.random(ints.shape[0]) < 0.2, 6:9] = np.nan
    return RaySegments(ints, rays), position


def path_walk(ints):
    """Each ray's path rank, whether it is an extension ray, its phase, and a function giving its children."""
    n = len(ints)
    path_of, paths, extension, phase = [], {}, [], []
    for row in ints:
        key = (int(row[SegmentColumn.PIXEL]), int(row[SegmentColumn.SAMPLE]))
        paths.setdefault(key, len(paths))
        path_of.append(paths[key])
        is_extension = int(row[SegmentColumn.RAY_TYPE]) != SegmentRayType.SHADOW
        extension.append(is_extension)
        phase.append(2 * int(row[SegmentColumn.BOUNCE]) + (0 if is_extension else 1))

    def children(i):
        found = []
        for j in range(i + 1, n):
            if path_of[j] != path_of[i]:
                break
            found.append(j)
            if extension[j]:
                break
        return found

    return path_of, extension, phase, children


def wavefront_events(ints, keys=None):
    """The wavefront walk, ray by ray with explicit queues: phases in order, FIFO or stable-sorted by ``keys``.

    ``ints`` are a process's segment rows in depth-first order; returns the
    list of events.
    """
    n = len(ints)
    path_of, extension, phase, children = path_walk(ints)

    capacity = max(phase.count(p) for p in set(phase))
    queues = {p: [] for p in range(max(phase) + 1)}
    events = []
    for i in range(n):
        if int(ints[i][SegmentColumn.RAY_TYPE]) == SegmentRayType.CAMERA:
            queues[0].append(i)
            events += [("queue", len(queues[0]) - 1, True), ("state", path_of[i], True)]
    for p in range(max(phase) + 1):
        queue = queues[p]
        run = list(range(len(queue)))
        if keys is not None:
            run.sort(key=lambda j: (int(keys[queue[j]]), j))
        for position, j in enumerate(run):
            i = queue[j]
            events += [("queue", (p % 3) * capacity + position, False), ("state", path_of[i], False),
                       ("piece", int(ints[i][SegmentColumn.FIRST]), int(ints[i][SegmentColumn.STOP])),
                       ("state", path_of[i], True)]
            if extension[i]:
                for c in children(i):
                    queues[phase[c]].append(c)
                    events.append(("queue", (phase[c] % 3) * capacity + len(queues[phase[c]]) - 1, True))
    return events


def events_of(pieces):
    """The events of an OrderedPieces, in replay order."""
    from tracer.trace.records import AUX_INDEX_MASK, AUX_KIND_SHIFT, INDEX_MASK, WRITE_FLAG, AuxKind

    names = {int(AuxKind.RAY_STATE): "state", int(AuxKind.QUEUE_ENTRY): "queue"}
    events, a = [], 0
    for q in range(pieces.n_pieces + 1):
        while a < len(pieces.aux_records) and pieces.aux_after[a] == q:
            record = int(pieces.aux_records[a])
            index = record & INDEX_MASK
            events.append((names[index >> AUX_KIND_SHIFT], index & AUX_INDEX_MASK, bool(record & WRITE_FLAG)))
            a += 1
        if q < pieces.n_pieces:
            events.append(("piece", int(pieces.piece_first[q]), int(pieces.piece_stop[q])))
    return events


def morton_key(point, lo, hi, bits):
    """Morton key of one point, bit by bit: axis a's bit i at bit 3 i + 2 - a (x most significant)."""
    key = 0
    for axis in range(3):
        extent = hi[axis] - lo[axis]
        cell = 0
        if extent > 0:
            cell = min(max(int(np.floor((point[axis] - lo[axis]) / extent * 2**bits)), 0), 2**bits - 1)
        for i in range(bits):
            if cell >> i & 1:
                key |= 1 << (3 * i + 2 - axis)
    return key


def order_keys(order_name, rays, lo, hi):
    """The sort key of each ray (rows of RaySegments.rays) for a sorted wavefront, one ray at a time."""
    keys = []
    diagonal = float(np.sqrt(((np.asarray(hi) - np.asarray(lo)) ** 2).sum()))
    for ray in rays:
        origin, direction, hit = ray[0:3], ray[3:6], ray[6:9]
        if order_name == "morton-origin":
            keys.append(morton_key(origin, lo, hi, 21))
        elif order_name == "octant-origin":
            octant = sum(1 << (2 - a) for a in range(3) if direction[a] < 0)
            keys.append(octant << 60 | morton_key(origin, lo, hi, 20))
        else:
            if not np.isfinite(hit).all():
                hit = [min(max(origin[a] + diagonal * direction[a], lo[a]), hi[a]) for a in range(3)]
            keys.append(morton_key(hit, lo, hi, 21))
    return keys
