"""kd-tree split kernels: primitives clipped to a node, SAH event sweeps and costs.

Used by the builders of :mod:`tracer.kd.build` and :mod:`tracer.kd.sah` (and
the per-node SAH peer in ``tests/naive_kdtree.py``); see :mod:`tracer.kd.tree`
for the rules. The
kernels take the scene as :class:`BuildInputs`, the configuration as
:class:`BuildParams` and (3,) boxes to clip into as :class:`ClipScratch`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.kd.nodes import LINK_WORD

# SAH event types, in the order the sweep takes events at one position
EVENT_END = 0     # a box ends there
EVENT_PLANAR = 1  # a flat box lies there
EVENT_START = 2   # a box starts there


class BuildInputs(NamedTuple):
    """What the builders read of a scene (see :func:`tracer.kd.tree.builder_inputs`).

    n elements; float64 but where noted.
    """

    prim_lo: np.ndarray        #: (n, 3) element box corners
    prim_hi: np.ndarray        #: (n, 3)
    clip_offsets: np.ndarray   #: (n + 1,) int64 CSR offsets into ``clip_vertices`` (planar elements)
    clip_vertices: np.ndarray  #: (V, 3)
    spheres: np.ndarray        #: (n, 4) centre and radius of spheres, radius -1 for other kinds
    root_lo: np.ndarray        #: (3,) root box corners
    root_hi: np.ndarray        #: (3,)


class BuildParams(NamedTuple):
    """A :class:`~tracer.kd.tree.KdTreeConfig` as the builders read it (``tree_depth`` resolved)."""

    tree_depth: int
    leaf_size: int
    traversal_cost: float
    intersection_cost: float
    empty_bonus: float
    clip: bool
    force_split: int  #: ``2**62`` when off
    cycle_axes: bool  #: median builder: split axis ``depth % 3`` instead of the longest
    split_to_depth: bool  #: median builder: split even where the plane separates no primitive


class ClipScratch(NamedTuple):
    """(3,) float64 boxes the split kernels clip into."""

    out_lo: np.ndarray
    out_hi: np.ndarray
    child_lo: np.ndarray
    child_hi: np.ndarray


@njit(cache=True)
def new_clip_scratch():
    """A :class:`ClipScratch`."""
    return ClipScratch(np.empty(3), np.empty(3), np.empty(3), np.empty(3))

@njit(cache=True)
def _clip_polygon_bounds(verts, a, b, lo, hi, out_lo, out_hi):
    # Sutherland-Hodgman clip of polygon verts[a:b] against the box; writes the
    # bounds of the clipped polygon and returns False when nothing is left.
    n = b - a
    cap = n + 8
    cur = np.empty((cap, 3))
    nxt = np.empty((cap, 3))
    for k in range(n):
        cur[k, 0] = verts[a + k, 0]
        cur[k, 1] = verts[a + k, 1]
        cur[k, 2] = verts[a + k, 2]
    m = n
    for plane in range(6):
        axis = plane >> 1
        upper = plane & 1
        bound = hi[axis] if upper else lo[axis]
        cnt = 0
        for k in range(m):
            k1 = k + 1 if k + 1 < m else 0
            pa = cur[k, axis]
            pb = cur[k1, axis]
            ina = pa <= bound if upper else pa >= bound
            inb = pb <= bound if upper else pb >= bound
            if ina:
                for c in range(3):
                    nxt[cnt, c] = cur[k, c]
                cnt += 1
            if ina != inb:
                s = (bound - pa) / (pb - pa)
                for c in range(3):
                    nxt[cnt, c] = cur[k, c] + s * (cur[k1, c] - cur[k, c])
                nxt[cnt, axis] = bound
                cnt += 1
        tmp = cur
        cur = nxt
        nxt = tmp
        m = cnt
        if m == 0:
            return False
    for c in range(3):
        mn = cur[0, c]
        mx = cur[0, c]
        for k in range(1, m):
            mn = min(mn, cur[k, c])
            mx = max(mx, cur[k, c])
        out_lo[c] = max(mn, lo[c])
        out_hi[c] = min(mx, hi[c])
    return True


@njit(cache=True)
def _overlap_bounds(p, prim_lo, prim_hi, lo, hi, out_lo, out_hi):
    # the box of element p cut to the box lo/hi into out_lo/out_hi; returns
    # (whether they overlap, whether the element's box lies inside lo/hi)
    inside = True
    for c in range(3):
        a = max(prim_lo[p, c], lo[c])
        b = min(prim_hi[p, c], hi[c])
        if a > b:
            return False, False
        if prim_lo[p, c] < lo[c] or prim_hi[p, c] > hi[c]:
            inside = False
        out_lo[c] = a
        out_hi[c] = b
    return True, inside


@njit(cache=True)
def _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, lo, hi, out_lo, out_hi):
    # the bounds of element p's shape clipped to the box lo/hi into
    # out_lo/out_hi; False when nothing of it is left there. Hot: the
    # arrays come one by one (a bundle would be taken apart, with reference
    # counting, on every call; BuildInputs callers unpack it once).
    overlaps, inside = _overlap_bounds(p, prim_lo, prim_hi, lo, hi, out_lo, out_hi)
    if not overlaps:
        return False
    if inside:
        return True
    r = spheres[p, 3]
    if r >= 0.0:
        near = 0.0
        far = 0.0
        for c in range(3):
            x = spheres[p, c]
            d = 0.0
            if x < lo[c]:
                d = lo[c] - x
            elif x > hi[c]:
                d = x - hi[c]
            near += d * d
            e = max(abs(x - lo[c]), abs(hi[c] - x))
            far += e * e
        if near > r * r:
            return False
        if far < r * r:
            return False  # box strictly inside the ball: no surface here
        return True
    a = clip_off[p]
    b = clip_off[p + 1]
    if b - a >= 3:
        return _clip_polygon_bounds(clip_v, a, b, lo, hi, out_lo, out_hi)
    return True


@njit(cache=True)
def _area(dx, dy, dz):
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@njit(cache=True, inline="always")
def _root_area(root_lo, root_hi):
    # the root box's surface area, the SAH's denominator (1 for a flat or empty scene)
    area = _area(root_hi[0] - root_lo[0], root_hi[1] - root_lo[1], root_hi[2] - root_lo[2])
    return 1.0 if area <= 0.0 else area


@njit(cache=True)
def _grow_nodes(a, need):
    if need <= a.shape[0]:
        return a
    b = np.zeros((max(need, 2 * a.shape[0]), LINK_WORD + 1), np.uint32)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_1d(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), a.dtype)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _axis_events(box_lo, box_hi, ids, k, axis, pos, typ, prim):
    # Events of the boxes of primitives ids[:k] (rows of box_lo/box_hi are
    # primitive ids) on one axis, unsorted but laid out end, planar, start
    # and by ids order within a type, so that a stable sort by position
    # gives the sweep order (position, type, then ids order). Returns the count.
    ne = 0
    for t in (EVENT_END, EVENT_PLANAR, EVENT_START):
        for j in range(k):
            p = ids[j]
            a = box_lo[p, axis]
            b = box_hi[p, axis]
            if t == EVENT_END and a != b:
                pos[ne] = b
            elif t == EVENT_PLANAR and a == b:
                pos[ne] = a
            elif t == EVENT_START and a != b:
                pos[ne] = a
            else:
                continue
            typ[ne] = t
            prim[ne] = p
            ne += 1
    return ne


@njit(cache=True)
def _sah_sweep(ev_pos, ev_typ, e0, counts, m, lo, hi, params):
    # Best split (cost, axis, position, planar_left) of a node holding m
    # primitives, from its events: counts[a] events of axis a, the axes one
    # after the other from e0, each sorted by position with end (type 0) <
    # planar (1) < start (2) at equal positions. Cost inf when no valid plane
    # exists; among equal costs the first in (axis, position, planar side)
    # order wins.
    ct = params.traversal_cost
    ci = params.intersection_cost
    eb = params.empty_bonus
    d0 = hi[0] - lo[0]
    d1 = hi[1] - lo[1]
    d2 = hi[2] - lo[2]
    area = _area(d0, d1, d2)
    best = np.inf
    best_axis = -1
    best_pos = 0.0
    best_left = True
    if area <= 0.0:
        return best, best_axis, best_pos, best_left
    inv_area = 1.0 / area
    base = e0
    for axis in range(3):
        ne = counts[axis]
        q0 = base
        base += ne
        if hi[axis] <= lo[axis]:
            continue
        # dimensions of the node orthogonal to the axis
        if axis == 0:
            u, v = d1, d2
        elif axis == 1:
            u, v = d0, d2
        else:
            u, v = d0, d1
        nl = 0
        nr = m
        i = q0
        end = q0 + ne
        while i < end:
            p = ev_pos[i]
            pe = 0
            pp = 0
            ps = 0
            while i < end and ev_pos[i] == p and ev_typ[i] == EVENT_END:
                pe += 1
                i += 1
            while i < end and ev_pos[i] == p and ev_typ[i] == EVENT_PLANAR:
                pp += 1
                i += 1
            while i < end and ev_pos[i] == p and ev_typ[i] == EVENT_START:
                ps += 1
                i += 1
            nr -= pp + pe
            # the tree stores float32 planes: judge the plane that will be
            # used (its areas; the counts are the event's, so where rounding
            # moves the plane past box sides, e.g. one on a face of the
            # float64 root box, the partition differs from the counts)
            p32 = np.float64(np.float32(p))
            if p32 > lo[axis] and p32 < hi[axis]:
                wl = p32 - lo[axis]
                wr = hi[axis] - p32
                pl = (2.0 * (u * v) + 2.0 * wl * (u + v)) * inv_area
                pr = (2.0 * (u * v) + 2.0 * wr * (u + v)) * inv_area
                for side in range(2):
                    l = nl + pp if side == 0 else nl
                    r = nr if side == 0 else nr + pp
                    c = pl * l + pr * r
                    if l == 0 or r == 0:
                        c *= 1.0 - eb
                    c = ct + ci * c
                    if c < best:
                        best = c
                        best_axis = axis
                        best_pos = p32
                        best_left = side == 0
            nl += ps + pp
    return best, best_axis, best_pos, best_left


@njit(cache=True)
def _child_count_area(members, inputs, lo, hi, axis, split, above, scratch):
    # elements of ``members`` left in the child below (or above) the plane
    # after clipping them to it, and the child's surface area
    clo = scratch.child_lo
    chi = scratch.child_hi
    clo[:] = lo
    chi[:] = hi
    if above:
        clo[axis] = split
    else:
        chi[axis] = split
    n = 0
    prim_lo, prim_hi, spheres = inputs.prim_lo, inputs.prim_hi, inputs.spheres
    clip_off, clip_v = inputs.clip_offsets, inputs.clip_vertices
    out_lo, out_hi = scratch.out_lo, scratch.out_hi
    for j in range(members.shape[0]):
        if _clipped_bounds(members[j], prim_lo, prim_hi, clip_off, clip_v, spheres, clo, chi, out_lo, out_hi):
            n += 1
    return n, _area(chi[0] - clo[0], chi[1] - clo[1], chi[2] - clo[2])


@njit(cache=True)
def _exact_cost(members, inputs, lo, hi, axis, split, params, scratch):
    # SAH cost of a split with primitives clipped to each child, which the
    # event sweep (node-clipped boxes only) cannot see: a sphere enclosing a
    # child is dropped from it.
    d0 = hi[0] - lo[0]
    d1 = hi[1] - lo[1]
    d2 = hi[2] - lo[2]
    area = _area(d0, d1, d2)
    if area <= 0.0 or not (split > lo[axis] and split < hi[axis]):
        return np.inf
    nl, al = _child_count_area(members, inputs, lo, hi, axis, split, False, scratch)
    nr, ar = _child_count_area(members, inputs, lo, hi, axis, split, True, scratch)
    c = (al * nl + ar * nr) / area
    if nl == 0 or nr == 0:
        c *= 1.0 - params.empty_bonus
    return params.traversal_cost + params.intersection_cost * c


@njit(cache=True)
def _settle_split(best, members, inputs, lo, hi, params, scratch):
    # From the sweep's best plane ``best`` = (cost, axis, position,
    # planar_left) of a node holding ``members`` to the plane used:
    # (axis, position, planar_left), axis -1 for a leaf.
    cost, axis, pos, planar_left = best
    m = members.shape[0]
    ci = params.intersection_cost
    if params.clip and m >= 8 and not cost < ci * m:
        # the sweep sees node-clipped boxes only; where it gives up on many
        # primitives, judge the midplanes (and its own best plane) with
        # primitives clipped to the children
        exact = np.inf
        if axis >= 0:
            exact = _exact_cost(members, inputs, lo, hi, axis, pos, params, scratch)
        for a in range(3):
            mid = np.float64(np.float32(0.5 * (lo[a] + hi[a])))
            c = _exact_cost(members, inputs, lo, hi, a, mid, params, scratch)
            if c < exact:
                exact = c
                axis = a
                pos = mid
                planar_left = True
        cost = exact
    if not cost < ci * m and not (m > params.force_split and cost < np.inf):
        axis = -1
    return axis, pos, planar_left
