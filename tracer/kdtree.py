"""kd-tree (the study's "BSP"): SAH and spatial-median builders, flat arrays.

Node layout (pbrt style, 8 bytes): ``nodes`` is (N, 2) uint32.

* interior node: ``word0`` = the split position as float32 bits, ``word1`` =
  ``above_child << 2 | axis`` (axis 0, 1, 2); the below child is the next
  node (``index + 1``).
* leaf: ``word0`` = offset of its first entry in ``primitive_indices``,
  ``word1`` = ``count << 2 | 3``.

``primitive_indices`` (int32) holds element ids; a leaf's entries are
``primitive_indices[word0 : word0 + count]``. Split positions are rounded to
float32 *before* primitives are partitioned, so the stored plane is the plane
the build used.

Builders (``KdTreeConfig.builder``):

* ``"sah"``: surface area heuristic with an event sweep, built in
  O(N log N) as in Wald & Havran 2006 ("On building fast kd-trees for ray
  tracing, and on doing that in O(N log N)"). The events (box starts, ends,
  and flat boxes) of all three axes are sorted once, at the root. Splitting a
  node partitions its sorted event lists into the two children in order:
  a primitive entirely on one side keeps its events; a primitive straddling
  the plane is clipped to each child again, and only its new events are
  sorted (few per node) and merged with the kept ones. Leaves list element
  ids in ascending order.
  With ``clip`` on, each primitive's box is clipped to the node: polygons are
  clipped exactly (Sutherland-Hodgman), and a sphere is dropped from a node
  whose box lies entirely inside it (its surface cannot be hit there) or
  outside it. That keeps heavily overlapping spheres (SPD shells) from
  filling every leaf. Where the sweep finds no plane worth it for 8 or more
  primitives, the midplanes are also judged with the primitives clipped to
  each child.
  The trees are those of the earlier builder, which clipped every primitive
  to every node and sorted events per node (O(N log^2 N)); it is kept as
  the peer in tests and benchmarks. A one-sided primitive's box lies within
  the child, so clipping it again would give it back in exact arithmetic; in
  floating point, Sutherland-Hodgman against the child's faces can end a
  last bit off, so a shape reaching the split face is clipped again and a
  changed box (rare) gets new events like a straddler.
* ``"median"``: the node's longest axis is halved, as a 1990s BSP did; a
  node stops at ``leaf_size`` primitives, at ``max_depth``, or when a split
  would not separate any primitive.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from numba import njit

from tracer.geometry import element_bounds, element_clip_shapes
from tracer.scene import Scene

LEAF_FLAG = 3
BUILDERS = ("sah", "median")
MAX_TREE_DEPTH = 60  # the traversal stack holds 64 entries


def default_max_depth(n_primitives: int) -> int:
    """pbrt's depth rule ``round(8 + 1.3 log2 N)``, capped at 60."""
    return int(min(MAX_TREE_DEPTH, round(8 + 1.3 * math.log2(max(n_primitives, 1)))))


@dataclass(frozen=True)
class KdTreeConfig:
    """How to build a kd-tree.

    Parameters
    ----------
    builder : {"sah", "median"}
        Surface area heuristic or spatial median (see module docstring).
    max_depth : int or None
        Deepest node level (root 0), 1..60; ``None`` means
        :func:`default_max_depth` of the scene's element count.
    leaf_size : int
        A node with at most this many primitives becomes a leaf (>= 1).
    traversal_cost, intersection_cost : float
        SAH costs of an interior-node step and of one intersection test (> 0).
    empty_bonus : float
        In [0, 1): fraction of the intersection cost forgiven for a split
        with an empty side.
    clip : bool
        Clip primitives to the node (see module docstring).
    force_split : int
        SAH only: a node holding more than this many primitives is split at
        its best plane even when the one-level cost estimate says a leaf is
        cheaper (like pbrt's "bad refines"), down to ``max_depth``. Heavily
        overlapping primitives (SPD shells: about 90 spheres cover every
        point) only separate after several levels, which a greedy estimate
        cannot see. ``0`` disables it.
    """

    builder: str = "sah"
    max_depth: int | None = None
    leaf_size: int = 1
    traversal_cost: float = 1.0
    intersection_cost: float = 1.5
    empty_bonus: float = 0.5
    clip: bool = True
    force_split: int = 0

    def __post_init__(self):
        if self.builder not in BUILDERS:
            raise ValueError(f"KdTreeConfig.builder must be one of {BUILDERS}, got {self.builder!r}")
        if self.max_depth is not None:
            if int(self.max_depth) != self.max_depth or not 1 <= self.max_depth <= MAX_TREE_DEPTH:
                raise ValueError(f"KdTreeConfig.max_depth must be an int in 1..{MAX_TREE_DEPTH} or None, got {self.max_depth!r}")
            object.__setattr__(self, "max_depth", int(self.max_depth))
        if int(self.leaf_size) != self.leaf_size or self.leaf_size < 1:
            raise ValueError(f"KdTreeConfig.leaf_size must be an int >= 1, got {self.leaf_size!r}")
        object.__setattr__(self, "leaf_size", int(self.leaf_size))
        for name in ("traversal_cost", "intersection_cost"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"KdTreeConfig.{name} must be a finite number > 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        eb = float(self.empty_bonus)
        if not 0.0 <= eb < 1.0:
            raise ValueError(f"KdTreeConfig.empty_bonus must be in [0, 1), got {self.empty_bonus!r}")
        object.__setattr__(self, "empty_bonus", eb)
        object.__setattr__(self, "clip", bool(self.clip))
        if int(self.force_split) != self.force_split or self.force_split < 0:
            raise ValueError(f"KdTreeConfig.force_split must be an int >= 0, got {self.force_split!r}")
        object.__setattr__(self, "force_split", int(self.force_split) if self.force_split else 2**62)

    def to_dict(self) -> dict:
        """The configuration as plain Python values."""
        return asdict(self)


@dataclass(eq=False)
class KdTree:
    """A built kd-tree (see module docstring for the node layout).

    Attributes
    ----------
    nodes : ndarray, shape (N, 2) uint32
    primitive_indices : ndarray, shape (E,) int32
        Element ids referenced by leaves.
    bounds : ndarray, shape (2, 3) float64
        Root box (lo, hi).
    config : KdTreeConfig
        The configuration used, with ``max_depth`` resolved.
    stats : dict
        ``nodes``, ``leaves``, ``empty_leaves``, ``depth`` (deepest leaf),
        ``mean_primitives_per_leaf`` (over non-empty leaves), ``references``
        (entries in ``primitive_indices``), ``sah_cost`` (expected cost of a
        ray through the root under the configured costs), ``build_seconds``.
    """

    nodes: np.ndarray
    primitive_indices: np.ndarray
    bounds: np.ndarray
    config: KdTreeConfig
    stats: dict = field(default_factory=dict)

    @property
    def split_view(self) -> np.ndarray:
        """``nodes`` viewed as float32 (N, 2); column 0 holds interior splits."""
        return self.nodes.view(np.float32)


# --------------------------------------------------------------------------
# build
# --------------------------------------------------------------------------

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
def _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, lo, hi, clip, out_lo, out_hi):
    inside = True
    for c in range(3):
        a = max(prim_lo[p, c], lo[c])
        b = min(prim_hi[p, c], hi[c])
        if a > b:
            return False
        if prim_lo[p, c] < lo[c] or prim_hi[p, c] > hi[c]:
            inside = False
        out_lo[c] = a
        out_hi[c] = b
    if not clip or inside:
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


@njit(cache=True)
def _grow_nodes(a, need):
    if need <= a.shape[0]:
        return a
    b = np.zeros((max(need, 2 * a.shape[0]), 2), np.uint32)
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
    for t in range(3):
        for j in range(k):
            p = ids[j]
            a = box_lo[p, axis]
            b = box_hi[p, axis]
            if t == 0 and a != b:
                pos[ne] = b
            elif t == 1 and a == b:
                pos[ne] = a
            elif t == 2 and a != b:
                pos[ne] = a
            else:
                continue
            typ[ne] = t
            prim[ne] = p
            ne += 1
    return ne


@njit(cache=True)
def _sah_sweep(ev_pos, ev_typ, e0, counts, m, lo, hi, ct, ci, eb):
    # Best split (cost, axis, position, planar_left) of a node holding m
    # primitives, from its events: counts[a] events of axis a, the axes one
    # after the other from e0, each sorted by position with end (type 0) <
    # planar (1) < start (2) at equal positions. Cost inf when no valid plane
    # exists; among equal costs the first in (axis, position, planar side)
    # order wins.
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
            while i < end and ev_pos[i] == p and ev_typ[i] == 0:
                pe += 1
                i += 1
            while i < end and ev_pos[i] == p and ev_typ[i] == 1:
                pp += 1
                i += 1
            while i < end and ev_pos[i] == p and ev_typ[i] == 2:
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
def _sah_split(clo, chi, m, lo, hi, ct, ci, eb, rows, tpos, ttyp, tprim, pos, typ, counts):
    # The per-node sort the presorted builder replaced (O(m log m) in every
    # node, O(N log^2 N) in all): events of the node-clipped boxes clo/chi
    # (m, 3), sorted here, then swept. ``rows`` is 0, 1, ...; the other
    # arrays are scratch of at least 2 m (t*) and 6 m (pos, typ) entries.
    # Used by _build for the comparison with _build_sah (tests, benchmarks).
    w = 0
    for axis in range(3):
        ne = _axis_events(clo, chi, rows, m, axis, tpos, ttyp, tprim)
        order = np.argsort(tpos[:ne], kind="mergesort")
        for i in range(ne):
            pos[w] = tpos[order[i]]
            typ[w] = ttyp[order[i]]
            w += 1
        counts[axis] = ne
    return _sah_sweep(pos, typ, 0, counts, m, lo, hi, ct, ci, eb)


@njit(cache=True)
def _exact_cost(work, seg0, m, prim_lo, prim_hi, clip_off, clip_v, spheres, lo, hi,
                axis, split, ct, ci, eb, tlo, thi, clo_buf, chi_buf):
    # SAH cost of a split with primitives clipped to each child, which the
    # event sweep (node-clipped boxes only) cannot see: a sphere enclosing a
    # child is dropped from it.
    d0 = hi[0] - lo[0]
    d1 = hi[1] - lo[1]
    d2 = hi[2] - lo[2]
    area = _area(d0, d1, d2)
    if area <= 0.0 or not (split > lo[axis] and split < hi[axis]):
        return np.inf
    clo_buf[:] = lo
    chi_buf[:] = hi
    chi_buf[axis] = split
    nl = 0
    for j in range(m):
        if _clipped_bounds(work[seg0 + j], prim_lo, prim_hi, clip_off, clip_v, spheres,
                           clo_buf, chi_buf, True, tlo, thi):
            nl += 1
    al = _area(chi_buf[0] - clo_buf[0], chi_buf[1] - clo_buf[1], chi_buf[2] - clo_buf[2])
    clo_buf[:] = lo
    chi_buf[:] = hi
    clo_buf[axis] = split
    nr = 0
    for j in range(m):
        if _clipped_bounds(work[seg0 + j], prim_lo, prim_hi, clip_off, clip_v, spheres,
                           clo_buf, chi_buf, True, tlo, thi):
            nr += 1
    ar = _area(chi_buf[0] - clo_buf[0], chi_buf[1] - clo_buf[1], chi_buf[2] - clo_buf[2])
    c = (al * nl + ar * nr) / area
    if nl == 0 or nr == 0:
        c *= 1.0 - eb
    return ct + ci * c


@njit(cache=True)
def _settle_split(cost, axis, pos, planar_left, work, seg0, m, prim_lo, prim_hi, clip_off, clip_v,
                  spheres, lo, hi, ct, ci, eb, clip, force, tlo, thi, blo, bhi):
    # From the sweep's best plane to the plane used, or axis -1 for a leaf.
    if clip and m >= 8 and not cost < ci * m:
        # the sweep sees node-clipped boxes only; where it gives up on many
        # primitives, judge the midplanes (and its own best plane) with
        # primitives clipped to the children
        best = np.inf
        if axis >= 0:
            best = _exact_cost(work, seg0, m, prim_lo, prim_hi, clip_off, clip_v, spheres,
                               lo, hi, axis, pos, ct, ci, eb, tlo, thi, blo, bhi)
        for a in range(3):
            mid = np.float64(np.float32(0.5 * (lo[a] + hi[a])))
            c = _exact_cost(work, seg0, m, prim_lo, prim_hi, clip_off, clip_v, spheres,
                            lo, hi, a, mid, ct, ci, eb, tlo, thi, blo, bhi)
            if c < best:
                best = c
                axis = a
                pos = mid
                planar_left = True
        cost = best
    if not cost < ci * m and not (m > force and cost < np.inf):
        axis = -1
    return axis, pos, planar_left


@njit(cache=True)
def _build(prim_lo, prim_hi, clip_off, clip_v, spheres, root_lo, root_hi,
           median, max_depth, leaf_size, ct, ci, eb, clip, force):
    n = prim_lo.shape[0]
    nodes = np.zeros((max(16, 2 * n + 1), 2), np.uint32)
    n_nodes = 0
    pidx = np.empty(max(16, 2 * n), np.int32)
    n_pidx = 0
    work = np.empty(max(16, 4 * n), np.int32)
    for j in range(n):
        work[j] = j
    S = max_depth + 4
    s_lo = np.empty((S, 3))
    s_hi = np.empty((S, 3))
    s_depth = np.empty(S, np.int64)
    s_parent = np.empty(S, np.int64)
    s_seg0 = np.empty(S, np.int64)
    s_seg1 = np.empty(S, np.int64)
    sp = 0
    s_lo[0, :] = root_lo
    s_hi[0, :] = root_hi
    s_depth[0] = 0
    s_parent[0] = -1
    s_seg0[0] = 0
    s_seg1[0] = n
    sp = 1
    root_area = _area(root_hi[0] - root_lo[0], root_hi[1] - root_lo[1], root_hi[2] - root_lo[2])
    if root_area <= 0.0:
        root_area = 1.0
    leaves = 0
    empty_leaves = 0
    deepest = 0
    sah_cost = 0.0
    lo = np.empty(3)
    hi = np.empty(3)
    tlo = np.empty(3)
    thi = np.empty(3)
    blo = np.empty(3)
    bhi = np.empty(3)
    clo = np.empty((max(n, 1), 3))
    chi = np.empty((max(n, 1), 3))
    split32 = np.empty(1, np.float32)
    rows = np.arange(max(n, 1))
    tpos = np.empty(2 * max(n, 1))
    ttyp = np.empty(2 * max(n, 1), np.int8)
    tprim = np.empty(2 * max(n, 1), np.int32)
    ev_pos = np.empty(6 * max(n, 1))
    ev_typ = np.empty(6 * max(n, 1), np.int8)
    counts = np.zeros(3, np.int64)
    while sp > 0:
        sp -= 1
        lo[:] = s_lo[sp]
        hi[:] = s_hi[sp]
        depth = s_depth[sp]
        parent = s_parent[sp]
        seg0 = s_seg0[sp]
        seg1 = s_seg1[sp]
        node = n_nodes
        n_nodes += 1
        nodes = _grow_nodes(nodes, n_nodes)
        if parent >= 0:
            nodes[parent, 1] |= np.uint32(node << 2)
        m = 0
        for j in range(seg1 - seg0):
            p = work[seg0 + j]
            if _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, lo, hi, clip, tlo, thi):
                work[seg0 + m] = p
                clo[m, :] = tlo
                chi[m, :] = thi
                m += 1
        area_frac = _area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / root_area
        axis = -1
        pos = 0.0
        planar_left = True
        if m > leaf_size and depth < max_depth:
            if median:
                d0 = hi[0] - lo[0]
                d1 = hi[1] - lo[1]
                d2 = hi[2] - lo[2]
                axis = 0
                if d1 > d0 and d1 >= d2:
                    axis = 1
                elif d2 > d0 and d2 > d1:
                    axis = 2
                pos = 0.5 * (lo[axis] + hi[axis])
            else:
                cost, axis, pos, planar_left = _sah_split(clo, chi, m, lo, hi, ct, ci, eb, rows, tpos, ttyp,
                                                         tprim, ev_pos, ev_typ, counts)
                axis, pos, planar_left = _settle_split(
                    cost, axis, pos, planar_left, work, seg0, m, prim_lo, prim_hi, clip_off, clip_v,
                    spheres, lo, hi, ct, ci, eb, clip, force, tlo, thi, blo, bhi)
        split = 0.0
        nl = 0
        nr = 0
        if axis >= 0:
            split32[0] = pos
            split = np.float64(split32[0])
            if not (split > lo[axis] and split < hi[axis]):
                axis = -1
        if axis >= 0:
            for j in range(m):
                a = clo[j, axis]
                b = chi[j, axis]
                if a == b and a == split:
                    if planar_left:
                        nl += 1
                    else:
                        nr += 1
                else:
                    if a < split:
                        nl += 1
                    if b > split:
                        nr += 1
            if median and nl == m and nr == m:
                axis = -1
        if axis < 0:
            # leaf
            nodes[node, 0] = np.uint32(n_pidx)
            nodes[node, 1] = np.uint32((m << 2) | 3)
            pidx = _grow_1d(pidx, n_pidx + m)
            for j in range(m):
                pidx[n_pidx + j] = work[seg0 + j]
            n_pidx += m
            leaves += 1
            if m == 0:
                empty_leaves += 1
            deepest = max(deepest, depth)
            sah_cost += ci * m * area_frac
            continue
        sah_cost += ct * area_frac
        nodes[node, 0] = split32.view(np.uint32)[0]
        nodes[node, 1] = np.uint32(axis)
        # right list first, then left list, written after this segment and
        # moved down to seg0 (the segment is on top of the work stack)
        need = seg0 + m + nl + nr
        if need > work.shape[0] or seg0 + 2 * m > work.shape[0]:
            grown = np.empty(max(2 * work.shape[0], seg0 + 2 * m + 16), np.int32)
            grown[:work.shape[0]] = work
            work = grown
        w = seg0 + m
        for j in range(m):
            a = clo[j, axis]
            b = chi[j, axis]
            right = b > split or (a == b and a == split and not planar_left)
            if right:
                work[w] = work[seg0 + j]
                w += 1
        for j in range(m):
            a = clo[j, axis]
            b = chi[j, axis]
            left = a < split or (a == b and a == split and planar_left)
            if left:
                work[w] = work[seg0 + j]
                w += 1
        for j in range(nl + nr):
            work[seg0 + j] = work[seg0 + m + j]
        # push above (right) child, then below (left) child
        s_lo[sp, :] = lo
        s_hi[sp, :] = hi
        s_lo[sp, axis] = split
        s_depth[sp] = depth + 1
        s_parent[sp] = node
        s_seg0[sp] = seg0
        s_seg1[sp] = seg0 + nr
        sp += 1
        s_lo[sp, :] = lo
        s_hi[sp, :] = hi
        s_hi[sp, axis] = split
        s_depth[sp] = depth + 1
        s_parent[sp] = -1
        s_seg0[sp] = seg0 + nr
        s_seg1[sp] = seg0 + nr + nl
        sp += 1
    return nodes[:n_nodes].copy(), pidx[:n_pidx].copy(), leaves, empty_leaves, deepest, sah_cost


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
def _merge_events(ev_pos, ev_typ, ev_prim, q0, nq, side, keep, tpos, ttyp, tprim, order, k,
                  out_pos, out_typ, out_prim, w):
    # Writes, from out[w], the events ev[q0:q0+nq] of primitives with
    # side == keep merged with the k events t[order[:k]]; both inputs and the
    # output are in (position, type, primitive) order. Returns the new w.
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
            out_pos[w] = ev_pos[i]
            out_typ[w] = ev_typ[i]
            out_prim[w] = ev_prim[i]
            i += 1
        else:
            o = order[j]
            out_pos[w] = tpos[o]
            out_typ[w] = ttyp[o]
            out_prim[w] = tprim[o]
            j += 1
        w += 1
    return w


@njit(cache=True)
def _build_sah(prim_lo, prim_hi, clip_off, clip_v, spheres, root_lo, root_hi,
               max_depth, leaf_size, ct, ci, eb, clip, force):
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
    n = prim_lo.shape[0]
    nn = max(n, 1)
    nodes = np.zeros((max(16, 2 * n + 1), 2), np.uint32)
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
    tlo = np.empty(3)
    thi = np.empty(3)
    blo = np.empty(3)
    bhi = np.empty(3)
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
        if _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, root_lo, root_hi, clip, tlo, thi):
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

    S = max_depth + 4
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
    root_area = _area(root_hi[0] - root_lo[0], root_hi[1] - root_lo[1], root_hi[2] - root_lo[2])
    if root_area <= 0.0:
        root_area = 1.0
    leaves = 0
    empty_leaves = 0
    deepest = 0
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
            nodes[parent, 1] |= np.uint32(node << 2)
        area_frac = _area(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / root_area
        axis = -1
        pos = 0.0
        planar_left = True
        if m > leaf_size and depth < max_depth:
            cost, axis, pos, planar_left = _sah_sweep(ev_pos, ev_typ, e0, cnt, m, lo, hi, ct, ci, eb)
            axis, pos, planar_left = _settle_split(
                cost, axis, pos, planar_left, ids, i0, m, prim_lo, prim_hi, clip_off, clip_v,
                spheres, lo, hi, ct, ci, eb, clip, force, tlo, thi, blo, bhi)
        split = 0.0
        if axis >= 0:
            split32[0] = pos
            split = np.float64(split32[0])
            if not (split > lo[axis] and split < hi[axis]):
                axis = -1
        if axis < 0:
            nodes[node, 0] = np.uint32(n_pidx)
            nodes[node, 1] = np.uint32((m << 2) | 3)
            pidx = _grow_1d(pidx, n_pidx + m)
            for j in range(m):
                pidx[n_pidx + j] = ids[i0 + j]
            n_pidx += m
            leaves += 1
            if m == 0:
                empty_leaves += 1
            deepest = max(deepest, depth)
            sah_cost += ci * m * area_frac
            continue
        sah_cost += ct * area_frac
        nodes[node, 0] = split32.view(np.uint32)[0]
        nodes[node, 1] = np.uint32(axis)

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
                if _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, llo, lhi, clip, tlo, thi):
                    lbox_lo[p, :] = tlo
                    lbox_hi[p, :] = thi
                    new_l[k_l] = p
                    k_l += 1
                    s |= 1
                if _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, rlo, rhi, clip, tlo, thi):
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
                        kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, llo, lhi,
                                               True, tlo, thi)
                    else:
                        kept = _clipped_bounds(p, prim_lo, prim_hi, clip_off, clip_v, spheres, rlo, rhi,
                                               True, tlo, thi)
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
                w = _merge_events(ev_pos, ev_typ, ev_prim, q, cnt[a], side, keep, tpos, ttyp, tprim,
                                  order, k, ev_pos, ev_typ, ev_prim, w)
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
    return nodes[:n_nodes].copy(), pidx[:n_pidx].copy(), leaves, empty_leaves, deepest, sah_cost


def build_kdtree(scene: Scene, config: KdTreeConfig | None = None) -> KdTree:
    """Build a kd-tree over all elements of ``scene``.

    Parameters
    ----------
    scene : Scene
    config : KdTreeConfig, optional
        Defaults to ``KdTreeConfig()`` (SAH).

    Returns
    -------
    KdTree
    """
    return _build_kdtree(scene, config, per_node_sort=False)


def _build_kdtree(scene: Scene, config: KdTreeConfig | None, per_node_sort: bool) -> KdTree:
    """:func:`build_kdtree` with a choice of SAH builder.

    ``per_node_sort=True`` selects the earlier SAH builder, which re-clips
    every primitive to every node and sorts the node's events there
    (O(N log^2 N)); it builds the same trees and is kept as the peer of the
    presorted builder in the tests and ``benchmarks/bench_kdtree.py``. The
    median builder ignores it.
    """
    if config is None:
        config = KdTreeConfig()
    if not isinstance(config, KdTreeConfig):
        raise ValueError(f"config must be a KdTreeConfig, got {type(config).__name__}")
    n = scene.n_elements
    if n >= 2**30:
        raise ValueError(f"Scene.element_kind: too many elements for the kd-tree ({n})")
    max_depth = config.max_depth if config.max_depth is not None else default_max_depth(n)
    if config.max_depth is None:
        from dataclasses import replace
        config = replace(config, max_depth=max_depth)
    start = time.perf_counter()
    inputs = _builder_inputs(scene)
    nodes, pidx, leaves, empty, deepest, cost = _run_builder(inputs, config, per_node_sort)
    seconds = time.perf_counter() - start
    root_lo, root_hi = inputs[5], inputs[6]
    filled = leaves - empty
    stats = {
        "nodes": int(len(nodes)),
        "leaves": int(leaves),
        "empty_leaves": int(empty),
        "depth": int(deepest),
        "mean_primitives_per_leaf": float(len(pidx) / filled) if filled else 0.0,
        "references": int(len(pidx)),
        "sah_cost": float(cost),
        "build_seconds": float(seconds),
    }
    return KdTree(nodes=nodes, primitive_indices=pidx,
                  bounds=np.stack([root_lo, root_hi]).astype(np.float64),
                  config=config, stats=stats)


def _builder_inputs(scene: Scene) -> tuple:
    """The builder kernels' scene arrays.

    Returns
    -------
    tuple
        ``(lo, hi, clip_offsets, clip_vertices, spheres, root_lo, root_hi)``:
        element boxes (N, 3) float64, the clip shapes of
        :func:`tracer.geometry.element_clip_shapes`, and the root box (3,).
    """
    lo, hi = element_bounds(scene)
    if scene.n_elements:
        root_lo, root_hi = lo.min(axis=0), hi.max(axis=0)
    else:
        root_lo, root_hi = np.zeros(3), np.zeros(3)
    if not (np.all(np.isfinite(root_lo)) and np.all(np.isfinite(root_hi))):
        raise ValueError("Scene geometry has non-finite coordinates")
    clip_off, clip_v, spheres = element_clip_shapes(scene)
    return lo, hi, clip_off, clip_v, spheres, root_lo, root_hi


def _run_builder(inputs: tuple, config: KdTreeConfig, per_node_sort: bool = False) -> tuple:
    """Run the builder kernel of ``config`` (``max_depth`` resolved) on ``inputs``.

    Returns ``(nodes, primitive_indices, leaves, empty_leaves, deepest,
    sah_cost)``; see :func:`_build_kdtree` for ``per_node_sort``.
    """
    lo, hi, clip_off, clip_v, spheres, root_lo, root_hi = inputs
    if config.builder == "sah" and not per_node_sort:
        return _build_sah(lo, hi, clip_off, clip_v, spheres, root_lo.copy(), root_hi.copy(),
                          config.max_depth, config.leaf_size, config.traversal_cost,
                          config.intersection_cost, config.empty_bonus, config.clip,
                          config.force_split)
    return _build(lo, hi, clip_off, clip_v, spheres, root_lo.copy(), root_hi.copy(),
                  config.builder == "median", config.max_depth, config.leaf_size,
                  config.traversal_cost, config.intersection_cost, config.empty_bonus,
                  config.clip, config.force_split)
