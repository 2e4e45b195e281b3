"""The O(N log N) SAH kd-tree builder: events of all three axes sorted once, then partitioned in order.

:func:`_build_sah` emits the flat arrays of :mod:`tracer.kd.nodes` from a
:class:`~tracer.kd.split.BuildInputs` and a
:class:`~tracer.kd.split.BuildParams`, as :func:`tracer.kd.build._build_median`
does.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from tracer.kd.build import DEEPEST, EMPTY_LEAVES, LEAVES, _close_leaf
from tracer.kd.nodes import NODE_WORDS, set_above_child, set_interior
from tracer.kd.split import (_area, _axis_events, _clipped_bounds, _grow_1d, _grow_nodes, _overlap_bounds, _root_area,
                             _sah_sweep, _settle_split, new_clip_scratch)


class Events(NamedTuple):
    """SAH events: plane position, type (0 end, 1 planar, 2 start) and element id."""

    pos: np.ndarray   #: (E,) float64
    typ: np.ndarray   #: (E,) int8
    prim: np.ndarray  #: (E,) int32


@njit(cache=True)
def _sort_events(pos, typ, prim, k, order):
    # order[:k] = the events pos/typ/prim[:k] sorted by (position, type,
    # primitive). Straddlers are few per node: insertion sort below a
    # handful, else a stable sort by position of the type-major layout of
    # _axis_events (which gives the same order).
    if k > 24:
        order[:k] = np.argsort(pos[:k], kind="mergesort")
        return
    for i in range(k):
        x = pos[i]
        t = typ[i]
        q = prim[i]
        j = i
        while j > 0:
            o = order[j - 1]
            if pos[o] < x or (pos[o] == x and (typ[o] < t or (typ[o] == t and prim[o] < q))):
                break
            order[j] = o
            j -= 1
        order[j] = i


@njit(cache=True)
def _merge_events(events, q0, nq, side, keep, new, order, k, w):
    # Writes, from events[w] on, the events[q0:q0+nq] of primitives with
    # side == keep merged with the k events new[order[:k]] (w > q0 + nq,
    # or w <= q0 for the output not to overtake the input); both inputs and
    # the output are in (position, type, primitive) order. Returns the new w.
    ev_pos, ev_typ, ev_prim = events.pos, events.typ, events.prim
    tpos, ttyp, tprim = new.pos, new.typ, new.prim
    i = q0
    end = q0 + nq
    j = 0
    while True:
        while i < end and side[ev_prim[i]] != keep:
            i += 1
        if i < end and j < k:
            o = order[j]
            a = ev_pos[i]
            b = tpos[o]
            take_old = a < b or (a == b and (ev_typ[i] < ttyp[o]
                                             or (ev_typ[i] == ttyp[o] and ev_prim[i] < tprim[o])))
        elif i < end:
            take_old = True
        elif j < k:
            take_old = False
        else:
            break
        if take_old:
            ev_pos[w] = ev_pos[i]
            ev_typ[w] = ev_typ[i]
            ev_prim[w] = ev_prim[i]
            i += 1
        else:
            o = order[j]
            ev_pos[w] = tpos[o]
            ev_typ[w] = ttyp[o]
            ev_prim[w] = tprim[o]
            j += 1
        w += 1
    return w


@njit(cache=True)
def _build_sah(inputs, params):
    # SAH build with events sorted once (Wald & Havran 2006). A node owns a
    # segment of ``ids`` (its primitives, ascending) with their node-clipped
    # boxes in ``box_lo``/``box_hi``, and a segment of the event arrays (axis
    # 0, 1, 2 one after the other, each in (position, type, primitive) order:
    # the per-node builder's sort order, so the sweep sees the same sequence
    # and breaks ties alike). Splitting a node keeps the events of primitives
    # on one side and makes new events only for primitives straddling the
    # plane, clipped to each child (and for the rare one-sided primitive whose
    # box a second clip changes, see below): few, sorted on their own, merged
    # with the kept ones. Children's segments replace the parent's (right
    # then left), so the node being split is always on top.
    # arrays taken out of the bundle once: the hot calls below take them
    # one by one (see _clipped_bounds)
    prim_lo = inputs.prim_lo
    prim_hi = inputs.prim_hi
    clip_off = inputs.clip_offsets
    clip_v = inputs.clip_vertices
    spheres = inputs.spheres
    root_lo = inputs.root_lo.copy()
    root_hi = inputs.root_hi.copy()
    tree_depth = params.tree_depth
    ct = params.traversal_cost
    ci = params.intersection_cost
    clip = params.clip
    n = prim_lo.shape[0]
    nn = max(n, 1)
    nodes = np.zeros((max(16, 2 * n + 1), NODE_WORDS), np.uint32)
    n_nodes = 0
    pidx = np.empty(max(16, 2 * n), np.int32)
    n_pidx = 0
    ids = np.empty(max(16, 4 * n), np.int32)
    box_lo = np.empty((max(16, 4 * n), 3))
    box_hi = np.empty((max(16, 4 * n), 3))
    ev_pos = np.empty(max(16, 12 * n))
    ev_typ = np.empty(max(16, 12 * n), np.int8)
    ev_prim = np.empty(max(16, 12 * n), np.int32)
    tpos = np.empty(max(16, 2 * n))
    ttyp = np.empty(max(16, 2 * n), np.int8)
    tprim = np.empty(max(16, 2 * n), np.int32)
    order = np.empty(max(16, 2 * n), np.int64)
    # per-primitive scratch for the node being split (rows are primitive ids):
    # boxes of the primitives given new events in each child, and the side
    side = np.zeros(nn, np.int8)  # 1 left, 2 right; 4 | children for new events
    lbox_lo = np.empty((nn, 3))
    lbox_hi = np.empty((nn, 3))
    rbox_lo = np.empty((nn, 3))
    rbox_hi = np.empty((nn, 3))
    new_l = np.empty(nn, np.int32)
    new_r = np.empty(nn, np.int32)
    lo = np.empty(3)
    hi = np.empty(3)
    scratch = new_clip_scratch()
    tlo = scratch.out_lo
    thi = scratch.out_hi
    llo = np.empty(3)
    lhi = np.empty(3)
    rlo = np.empty(3)
    rhi = np.empty(3)
    cnt = np.zeros(3, np.int64)
    cnt_l = np.zeros(3, np.int64)
    cnt_r = np.zeros(3, np.int64)
    split32 = np.empty(1, np.float32)

    # root: primitives clipped to the root box (a no-op but for its rules),
    # and the one sort of all events
    m0 = 0
    for p in range(n):
        if clip:
            kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, root_lo, root_hi, tlo, thi)
        else:
            kept = _overlap_bounds(p, prim_lo, prim_hi, root_lo, root_hi, tlo, thi)[0]
        if kept:
            ids[m0] = p
            box_lo[m0, :] = tlo
            box_hi[m0, :] = thi
            lbox_lo[p, :] = tlo
            lbox_hi[p, :] = thi
            m0 += 1
    w = 0
    for axis in range(3):
        ne = _axis_events(lbox_lo, lbox_hi, ids, m0, axis, tpos, ttyp, tprim)
        _sort_events(tpos, ttyp, tprim, ne, order)
        for i in range(ne):
            ev_pos[w] = tpos[order[i]]
            ev_typ[w] = ttyp[order[i]]
            ev_prim[w] = tprim[order[i]]
            w += 1
        cnt[axis] = ne

    S = tree_depth + 4
    s_lo = np.empty((S, 3))
    s_hi = np.empty((S, 3))
    s_depth = np.empty(S, np.int64)
    s_parent = np.empty(S, np.int64)
    s_i0 = np.empty(S, np.int64)
    s_m = np.empty(S, np.int64)
    s_e0 = np.empty(S, np.int64)
    s_cnt = np.empty((S, 3), np.int64)
    s_lo[0, :] = root_lo
    s_hi[0, :] = root_hi
    s_depth[0] = 0
    s_parent[0] = -1
    s_i0[0] = 0
    s_m[0] = m0
    s_e0[0] = 0
    s_cnt[0, :] = cnt
    sp = 1
    root_area = _root_area(root_lo, root_hi)
    stats = np.zeros(3, dtype=np.int64)
    sah_cost = 0.0
    while sp > 0:
        sp -= 1
        lo[:] = s_lo[sp]
        hi[:] = s_hi[sp]
        depth = s_depth[sp]
        parent = s_parent[sp]
        i0 = s_i0[sp]
        m = s_m[sp]
        e0 = s_e0[sp]
        cnt[:] = s_cnt[sp]
        node = n_nodes
        n_nodes += 1
        nodes = _grow_nodes(nodes, n_nodes)
        if parent >= 0:
            set_above_child(nodes, parent, node)
        area_frac = _area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / root_area
        axis = -1
        pos = 0.0
        planar_left = True
        if m > params.leaf_size and depth < tree_depth:
            best = _sah_sweep(ev_pos, ev_typ, e0, cnt, m, lo, hi, params)
            axis, pos, planar_left = _settle_split(best, ids[i0:i0 + m], inputs, lo, hi, params, scratch)
        split = 0.0
        if axis >= 0:
            split32[0] = pos
            split = np.float64(split32[0])
            if not (split > lo[axis] and split < hi[axis]):
                axis = -1
        if axis < 0:
            pidx, n_pidx = _close_leaf(nodes, node, pidx, n_pidx, ids[i0:i0 + m], depth, stats)
            sah_cost += ci * m * area_frac
            continue
        sah_cost += ct * area_frac
        set_interior(nodes, node, split32.view(np.uint32)[0], axis)

        llo[:] = lo
        lhi[:] = hi
        lhi[axis] = split
        rlo[:] = lo
        rhi[:] = hi
        rlo[axis] = split
        # classify as the per-node builder partitions. A straddler is clipped
        # to each child from its original shape, as that builder does on
        # entering the child, and may leave either.
        nl = 0
        nr = 0
        k_l = 0
        k_r = 0
        for j in range(m):
            p = ids[i0 + j]
            a = box_lo[i0 + j, axis]
            b = box_hi[i0 + j, axis]
            on_plane = a == b and a == split
            left = a < split or (on_plane and planar_left)
            right = b > split or (on_plane and not planar_left)
            if left and right:
                s = 4
                if clip:
                    in_l = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, llo, lhi, tlo, thi)
                else:
                    in_l = _overlap_bounds(p, prim_lo, prim_hi, llo, lhi, tlo, thi)[0]
                if in_l:
                    lbox_lo[p, :] = tlo
                    lbox_hi[p, :] = thi
                    new_l[k_l] = p
                    k_l += 1
                    s |= 1
                if clip:
                    in_r = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, rlo, rhi, tlo, thi)
                else:
                    in_r = _overlap_bounds(p, prim_lo, prim_hi, rlo, rhi, tlo, thi)[0]
                if in_r:
                    rbox_lo[p, :] = tlo
                    rbox_hi[p, :] = thi
                    new_r[k_r] = p
                    k_r += 1
                    s |= 2
            else:
                s = 1 if left else 2
                # Its box lies within the child, and clipping it to the child
                # (as the per-node builder does) gives the box back in exact
                # arithmetic. In floating point, only the split face is new,
                # and it cuts nothing unless the original shape reaches it:
                # the other faces are the node's, and Sutherland-Hodgman's
                # interpolated coordinates stay within the shape's extent up
                # to a few ulps (margin below); a sphere short of the face
                # cannot enclose the child. A shape that reaches the face is
                # clipped again, and where the box differs (a last bit, or a
                # sphere enclosing a flat child) the fresh box is taken: the
                # per-node builder's boxes in every node, so its trees.
                margin = 64.0 * 2.220446049250313e-16 * max(abs(prim_lo[p, axis]), abs(prim_hi[p, axis]))
                if left:
                    reach = prim_hi[p, axis] + margin >= split
                else:
                    reach = prim_lo[p, axis] - margin <= split
                if clip and reach:
                    if left:
                        kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, llo, lhi, tlo, thi)
                    else:
                        kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, rlo, rhi, tlo, thi)
                    same = kept
                    for c in range(3):
                        same = same and tlo[c] == box_lo[i0 + j, c] and thi[c] == box_hi[i0 + j, c]
                    if not same:
                        if kept and left:
                            lbox_lo[p, :] = tlo
                            lbox_hi[p, :] = thi
                            new_l[k_l] = p
                            k_l += 1
                        elif kept:
                            rbox_lo[p, :] = tlo
                            rbox_hi[p, :] = thi
                            new_r[k_r] = p
                            k_r += 1
                        s = (4 | s) if kept else 4
            side[p] = s
            if s & 1:
                nl += 1
            if s & 2:
                nr += 1
        # children's primitives and boxes: right list then left list, written
        # after the segment and moved down to i0 (ascending order kept)
        need = i0 + m + nl + nr
        ids = _grow_1d(ids, need)
        if need > box_lo.shape[0]:
            grown = max(need, 2 * box_lo.shape[0])
            t_lo = np.empty((grown, 3))
            t_hi = np.empty((grown, 3))
            t_lo[:box_lo.shape[0]] = box_lo
            t_hi[:box_hi.shape[0]] = box_hi
            box_lo = t_lo
            box_hi = t_hi
        w = i0 + m
        for child in range(2):
            bit = 2 if child == 0 else 1
            for j in range(m):
                p = ids[i0 + j]
                s = side[p]
                if s & bit:
                    ids[w] = p
                    for c in range(3):
                        if s & 4 and bit == 2:
                            box_lo[w, c] = rbox_lo[p, c]
                            box_hi[w, c] = rbox_hi[p, c]
                        elif s & 4:
                            box_lo[w, c] = lbox_lo[p, c]
                            box_hi[w, c] = lbox_hi[p, c]
                        else:
                            box_lo[w, c] = box_lo[i0 + j, c]
                            box_hi[w, c] = box_hi[i0 + j, c]
                    w += 1
        for j in range(nl + nr):
            ids[i0 + j] = ids[i0 + m + j]
            for c in range(3):
                box_lo[i0 + j, c] = box_lo[i0 + m + j, c]
                box_hi[i0 + j, c] = box_hi[i0 + m + j, c]
        # children's events, likewise after the node's and moved down to e0
        ne = cnt[0] + cnt[1] + cnt[2]
        need = e0 + 2 * ne + 6 * (k_l + k_r)
        ev_pos = _grow_1d(ev_pos, need)
        ev_typ = _grow_1d(ev_typ, need)
        ev_prim = _grow_1d(ev_prim, need)
        kt = 2 * max(k_l, k_r)
        tpos = _grow_1d(tpos, kt)
        ttyp = _grow_1d(ttyp, kt)
        tprim = _grow_1d(tprim, kt)
        order = _grow_1d(order, kt)
        events = Events(ev_pos, ev_typ, ev_prim)
        new_events = Events(tpos, ttyp, tprim)
        w = e0 + ne
        for child in range(2):
            keep = 2 if child == 0 else 1
            q = e0
            for a in range(3):
                w0 = w
                if child == 0:
                    k = _axis_events(rbox_lo, rbox_hi, new_r, k_r, a, tpos, ttyp, tprim)
                else:
                    k = _axis_events(lbox_lo, lbox_hi, new_l, k_l, a, tpos, ttyp, tprim)
                _sort_events(tpos, ttyp, tprim, k, order)
                w = _merge_events(events, q, cnt[a], side, keep, new_events, order, k, w)
                q += cnt[a]
                if child == 0:
                    cnt_r[a] = w - w0
                else:
                    cnt_l[a] = w - w0
        for j in range(w - e0 - ne):
            ev_pos[e0 + j] = ev_pos[e0 + ne + j]
            ev_typ[e0 + j] = ev_typ[e0 + ne + j]
            ev_prim[e0 + j] = ev_prim[e0 + ne + j]
        # push above (right) child, then below (left) child
        s_lo[sp, :] = rlo
        s_hi[sp, :] = rhi
        s_depth[sp] = depth + 1
        s_parent[sp] = node
        s_i0[sp] = i0
        s_m[sp] = nr
        s_e0[sp] = e0
        s_cnt[sp, :] = cnt_r
        sp += 1
        s_lo[sp, :] = llo
        s_hi[sp, :] = lhi
        s_depth[sp] = depth + 1
        s_parent[sp] = -1
        s_i0[sp] = i0 + nr
        s_m[sp] = nl
        s_e0[sp] = e0 + cnt_r[0] + cnt_r[1] + cnt_r[2]
        s_cnt[sp, :] = cnt_l
        sp += 1
    return (nodes[:n_nodes].copy(), pidx[:n_pidx].copy(), stats[LEAVES], stats[EMPTY_LEAVES], stats[DEEPEST],
            sah_cost)
