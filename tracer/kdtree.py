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

* ``"sah"``: surface area heuristic with a sorted event sweep per node
  (Wald & Havran 2006; events are sorted per node, which costs
  O(N log^2 N) overall instead of the paper's merge-based O(N log N)).
  With ``clip`` on, each primitive's box is clipped to the node: polygons are
  clipped exactly (Sutherland-Hodgman), and a sphere is dropped from a node
  whose box lies entirely inside it (its surface cannot be hit there) or
  outside it. That keeps heavily overlapping spheres (SPD shells) from
  filling every leaf.
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
def _grow_i32(a, need):
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0]), np.int32)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_nodes(a, need):
    if need <= a.shape[0]:
        return a
    b = np.zeros((max(need, 2 * a.shape[0]), 2), np.uint32)
    b[:a.shape[0]] = a
    return b


@njit(cache=True)
def _sah_split(clo, chi, m, lo, hi, ct, ci, eb):
    # Returns (cost, axis, position, planar_left) of the best split, cost inf
    # when no valid plane exists. Events are ordered end < planar < start at
    # equal positions (stable sort over an array laid out in that order).
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
    pos = np.empty(2 * m)
    typ = np.empty(2 * m, np.int8)
    for axis in range(3):
        if hi[axis] <= lo[axis]:
            continue
        ne = 0
        for t in range(3):
            for j in range(m):
                a = clo[j, axis]
                b = chi[j, axis]
                if t == 0 and a != b:
                    pos[ne] = b
                    typ[ne] = 0
                    ne += 1
                elif t == 1 and a == b:
                    pos[ne] = a
                    typ[ne] = 1
                    ne += 1
                elif t == 2 and a != b:
                    pos[ne] = a
                    typ[ne] = 2
                    ne += 1
        order = np.argsort(pos[:ne], kind="mergesort")
        # dimensions of the node orthogonal to the axis
        if axis == 0:
            u, v = d1, d2
        elif axis == 1:
            u, v = d0, d2
        else:
            u, v = d0, d1
        nl = 0
        nr = m
        i = 0
        while i < ne:
            p = pos[order[i]]
            pe = 0
            pp = 0
            ps = 0
            while i < ne and pos[order[i]] == p and typ[order[i]] == 0:
                pe += 1
                i += 1
            while i < ne and pos[order[i]] == p and typ[order[i]] == 1:
                pp += 1
                i += 1
            while i < ne and pos[order[i]] == p and typ[order[i]] == 2:
                ps += 1
                i += 1
            nr -= pp + pe
            # the tree stores float32 planes: judge the plane that will be used
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
                cost, axis, pos, planar_left = _sah_split(clo, chi, m, lo, hi, ct, ci, eb)
                if clip and m >= 8 and not cost < ci * m:
                    # the sweep sees node-clipped boxes only; where it gives
                    # up on many primitives, judge the midplanes (and its own
                    # best plane) with primitives clipped to the children
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
            pidx = _grow_i32(pidx, n_pidx + m)
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
    lo, hi = element_bounds(scene)
    if n:
        root_lo, root_hi = lo.min(axis=0), hi.max(axis=0)
    else:
        root_lo, root_hi = np.zeros(3), np.zeros(3)
    if not (np.all(np.isfinite(root_lo)) and np.all(np.isfinite(root_hi))):
        raise ValueError("Scene geometry has non-finite coordinates")
    clip_off, clip_v, spheres = element_clip_shapes(scene)
    nodes, pidx, leaves, empty, deepest, cost = _build(
        lo, hi, clip_off, clip_v, spheres, root_lo.copy(), root_hi.copy(),
        config.builder == "median", max_depth, config.leaf_size,
        config.traversal_cost, config.intersection_cost, config.empty_bonus, config.clip,
        config.force_split)
    seconds = time.perf_counter() - start
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
