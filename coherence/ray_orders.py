"""Ray orders: in which order a process traces the rays of a path-traced trace.

A :class:`~coherence.ray_order_base.RayOrder` is a recipe (frozen,
validated parameters); :func:`order_pieces` applies it to the segments one
process owns and returns :class:`~coherence.ray_order_base.OrderedPieces`
(record ranges, the order's own buffer and queue records, sort cycles;
:mod:`coherence.ray_order_base` says what they are and where they live).
:func:`~coherence.ray_order_base.replay_order` runs them through a cache
hierarchy. ``docs/ray_orders.md`` describes every order.

Built-in orders, by name in :data:`RAY_ORDERS`:

* ``depth-first``: each pixel's rays as traced (today's order), no record of
  its own; replaying it equals replaying the pixels in order.
* ``wavefront``: breadth-first by bounce, first in, first out
  (:func:`~coherence.ray_order_base.wavefront_pieces`).
* ``morton-origin``, ``octant-origin``, ``hit-point``: the wavefront with
  each phase sorted by a spatial key (:mod:`coherence.sorted_ray_orders`).
* ``treelet``: treelet queues (:class:`~coherence.treelet_orders.TreeletQueues`
  with 8 KB treelets of 8-byte nodes, the ``compact`` layout's); it needs
  the trace's kd-tree and records (``tree=``, ``records=``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rtcommon.validate import InputError
from tracer.trace.segments import RaySegments

from .ray_order_base import (OrderBuffers, OrderedPieces, RayOrder, depth_first_pieces, order_stream, replay_order,
                             wavefront_pieces)
from .sorted_ray_orders import HitPoint, MortonOrigin, OctantOrigin
from .treelet_orders import TreeletQueues

__all__ = ["RAY_ORDERS", "DepthFirst", "HitPoint", "MortonOrigin", "OctantOrigin", "OrderBuffers", "OrderedPieces",
           "RayOrder", "TreeletQueues", "Wavefront", "get_ray_order", "order_pieces", "order_stream", "replay_order",
           "scene_bounds_of"]


@dataclass(frozen=True)
class DepthFirst(RayOrder):
    """Each path's rays as the tracer traced them, pixel after pixel (no buffers, no queues)."""

    name = "depth-first"

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        return depth_first_pieces(segments, rows)


@dataclass(frozen=True)
class Wavefront(RayOrder):
    """Breadth-first by bounce: every bounce-``k`` ray before any of bounce ``k + 1``, queues first in, first out.

    Camera rays of every path run first (in depth-first order), then their
    shadow rays, then the first bounces, and so on; a ray runs only after the
    ray that spawned it, since its bounce's phase comes later.
    """

    name = "wavefront"

    def _order(self, segments, rows, scene_bounds, tree, records) -> OrderedPieces:
        return wavefront_pieces(segments, rows)


RAY_ORDERS: dict[str, RayOrder] = {
    order.name: order for order in (DepthFirst(), Wavefront(), MortonOrigin(), OctantOrigin(), HitPoint(),
                                    TreeletQueues())}


def get_ray_order(name_or_order) -> RayOrder:
    """A :class:`RayOrder` given itself or a name of :data:`RAY_ORDERS` (case ignored)."""
    if isinstance(name_or_order, RayOrder):
        return name_or_order
    if isinstance(name_or_order, str):
        folded = {name.lower(): order for name, order in RAY_ORDERS.items()}
        if name_or_order.lower() in folded:
            return folded[name_or_order.lower()]
    raise InputError(f"unknown ray order {name_or_order!r}; choose one of {', '.join(RAY_ORDERS)} "
                     "or pass a RayOrder")


def scene_bounds_of(segments: RaySegments) -> np.ndarray:
    """The box around every segment's origin and hit point: float64 (2, 3), lowest then highest corner.

    Orders that quantise positions use one box for all processes, so that a
    ray's key does not depend on which process owns it.
    """
    points = np.concatenate((segments.rays[:, 0:3], segments.rays[:, 6:9]))
    points = points[np.isfinite(points).all(axis=1)]
    if points.shape[0] == 0:
        return np.zeros((2, 3))
    return np.stack((points.min(axis=0), points.max(axis=0)))


def order_pieces(trace_segments: RaySegments, segment_rows, order, *, scene_bounds=None, tree=None,
                 records=None) -> OrderedPieces:
    """The pieces one process replays when it traces its segments in ``order``.

    Parameters
    ----------
    trace_segments : RaySegments
        The segments of a path-traced trace (``AccessTrace.segments``).
    segment_rows : array_like of int, shape (S,)
        The rows the process owns, in depth-first order: each path's rays
        consecutive and as traced (a pixel's rows as the trace holds them,
        pixels in the mapping's order).
    order : str or RayOrder
        A name of :data:`RAY_ORDERS` or an order.
    scene_bounds : array_like of float, shape (2, 3), optional
        The box orders quantise positions in; default :func:`scene_bounds_of`
        the whole trace's segments.
    tree : KdTree, optional
        The trace's kd-tree, for orders that need it (``needs_tree``: ``treelet``).
    records : ndarray of uint32, shape (R,), optional
        The trace's records, for orders that read them (``needs_records``: ``treelet``).

    Returns
    -------
    OrderedPieces

    Raises
    ------
    ValueError
        If a row is out of range or repeated, the rows are not in depth-first
        order, the order is unknown or needs a tree that is not given.
    """
    if not isinstance(trace_segments, RaySegments):
        raise InputError(f"trace_segments must be RaySegments (a path-traced trace's segments), "
                         f"got {type(trace_segments).__name__}")
    order = get_ray_order(order)
    rows = np.asarray(segment_rows)
    if rows.ndim != 1 or (rows.size and not np.issubdtype(rows.dtype, np.integer)):
        raise InputError("segment_rows must be a 1-d array of segment row numbers")
    rows = rows.astype(np.int64)
    n = trace_segments.n_segments
    if rows.size and (rows.min() < 0 or rows.max() >= n):
        raise InputError(f"segment_rows must be in 0..{n - 1}")
    if np.unique(rows).size != rows.size:
        raise InputError("segment_rows must not repeat a row")
    if scene_bounds is None:
        scene_bounds = scene_bounds_of(trace_segments)
    scene_bounds = np.asarray(scene_bounds, dtype=np.float64)
    if scene_bounds.shape != (2, 3) or not np.isfinite(scene_bounds).all() or np.any(scene_bounds[1] < scene_bounds[0]):
        raise InputError("scene_bounds must be finite, shape (2, 3): the lowest corner, then the highest")
    if order.needs_tree and tree is None:
        raise InputError(f"ray order {order.name!r} needs the trace's kd-tree (tree=...)")
    if order.needs_records and records is None:
        raise InputError(f"ray order {order.name!r} needs the trace's records (records=...)")
    return order._order(trace_segments, rows, scene_bounds, tree, records)
