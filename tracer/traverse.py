"""kd-tree traversal shared by the renderer and the closest-hit API.

:func:`traverse` walks the flat tree of :mod:`tracer.kdtree` front to back
and appends every record it reads to the access log; :func:`brute_force` is
the slow reference that tests every element. ``_scene_arrays`` and
``_tree_arrays`` check and prepare the arrays the kernels read.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from tracer.geometry import hit_element
from tracer.kdtree import KdTree, KdTreeConfig, build_kdtree
from tracer.records import Counter, RecordKind, make_record
from tracer.scene import Scene


@njit(cache=True, error_model="numpy")
def traverse(nodes, fnodes, pidx, ekind, eidx, geo, blo, bhi,
             ox, oy, oz, dx, dy, dz, tmin, tmax, anyhit,
             rec, pos, limit, cnt, st_node, st_t0, st_t1):
    """Closest (or any, with ``anyhit``) hit of a ray in ``(tmin, tmax)``.

    Every node visit, leaf index-entry read and primitive test is counted in
    ``cnt`` and advances ``pos``; its packed record (:mod:`tracer.records`)
    is stored at ``rec[pos]`` while ``pos < limit`` (``limit = 0`` logs
    nothing, and a caller whose slot overflows learns the size it needs).

    Returns
    -------
    t : float
        Hit distance or ``inf``.
    element : int
        Element id or -1.
    pos : int
        Next free record position.
    """
    best_t = tmax
    best_e = -1
    # root box: the root record is read (it holds the bounds) even when the
    # ray misses the box
    t0 = tmin
    t1 = tmax
    o3 = (ox, oy, oz)
    d3 = (dx, dy, dz)
    inv = (1.0 / dx if dx != 0.0 else np.inf,
           1.0 / dy if dy != 0.0 else np.inf,
           1.0 / dz if dz != 0.0 else np.inf)
    miss = False
    for a in range(3):
        if d3[a] == 0.0:
            if o3[a] < blo[a] or o3[a] > bhi[a]:
                miss = True
        else:
            ta = (blo[a] - o3[a]) * inv[a]
            tb = (bhi[a] - o3[a]) * inv[a]
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
    if miss or t0 > t1:
        if pos < limit:
            rec[pos] = make_record(RecordKind.KD_NODE, 0)
        pos += 1
        cnt[Counter.NODE_VISITS] += 1
        return np.inf, -1, pos
    sp = 0
    node = 0
    while True:
        if best_t < t0:
            break  # stacked nodes lie even farther along the ray
        if pos < limit:
            rec[pos] = make_record(RecordKind.KD_NODE, node)
        pos += 1
        cnt[Counter.NODE_VISITS] += 1
        w1 = nodes[node, 1]
        flag = w1 & 3
        if flag != 3:
            axis = flag
            split = np.float64(fnodes[node, 0])
            oa = o3[axis]
            da = d3[axis]
            below_first = oa < split or (oa == split and da <= 0.0)
            if below_first:
                first = node + 1
                second = np.int64(w1 >> 2)
            else:
                first = np.int64(w1 >> 2)
                second = node + 1
            if da != 0.0:
                tp = (split - oa) * inv[axis]
            else:
                tp = np.inf
            if tp > t1 or tp <= 0.0:
                node = first
            elif tp < t0:
                node = second
            else:
                st_node[sp] = second
                st_t0[sp] = tp
                st_t1[sp] = t1
                sp += 1
                node = first
                t1 = tp
            continue
        # leaf
        cnt[Counter.LEAF_VISITS] += 1
        count = np.int64(w1 >> 2)
        off = np.int64(nodes[node, 0])
        for j in range(off, off + count):
            e = pidx[j]
            k = np.int64(ekind[e])
            i = eidx[e]
            if pos + 1 < limit:
                rec[pos] = make_record(RecordKind.INDEX_ENTRY, j)
                rec[pos + 1] = make_record(RecordKind.SPHERE + k, i)
            elif pos < limit:
                rec[pos] = make_record(RecordKind.INDEX_ENTRY, j)
            pos += 2
            cnt[Counter.INDEX_READS] += 1
            cnt[Counter.TESTS_SPHERE + k] += 1
            t = hit_element(k, i, geo, ox, oy, oz, dx, dy, dz, tmin, best_t)
            if t < best_t:
                best_t = t
                best_e = e
                if anyhit:
                    return best_t, best_e, pos
        if best_e >= 0 and best_t <= t1:
            break
        if sp == 0:
            break
        sp -= 1
        node = st_node[sp]
        t0 = st_t0[sp]
        t1 = st_t1[sp]
    if best_e < 0:
        return np.inf, -1, pos
    return best_t, best_e, pos


@njit(cache=True, error_model="numpy")
def brute_force(ekind, eidx, geo, ox, oy, oz, dx, dy, dz, tmin, tmax):
    """Closest hit over all elements in id order (reference for tests)."""
    best_t = tmax
    best_e = -1
    for e in range(ekind.shape[0]):
        t = hit_element(np.int64(ekind[e]), eidx[e], geo, ox, oy, oz, dx, dy, dz, tmin, best_t)
        if t < best_t:
            best_t = t
            best_e = e
    if best_e < 0:
        return np.inf, -1
    return best_t, best_e


def _scene_arrays(scene: Scene):
    n = scene.n_elements
    for name in ("element_index", "element_material"):
        if getattr(scene, name).shape != (n,):
            raise ValueError(f"Scene.{name} must have shape ({n},)")
    ekind = np.ascontiguousarray(scene.element_kind, dtype=np.uint8)
    eidx = np.ascontiguousarray(scene.element_index, dtype=np.int64)
    emat = np.ascontiguousarray(scene.element_material, dtype=np.int64)
    if n and ekind.max() > 4:
        raise ValueError("Scene.element_kind holds a value outside ElementKind (0..4)")
    mats = np.column_stack([scene.material_color.reshape(-1, 3), scene.material_kd, scene.material_ks,
                            scene.material_shine, scene.material_t, scene.material_ior]).astype(np.float64)
    mats = np.ascontiguousarray(mats.reshape(-1, 8))
    if n and (emat.min() < 0 or emat.max() >= len(mats)):
        raise ValueError("Scene.element_material refers to a material row that does not exist")
    return ekind, eidx, emat, mats


def _tree_arrays(scene: Scene, tree: KdTree | None, kd_config: KdTreeConfig | None):
    if tree is None:
        tree = build_kdtree(scene, kd_config)
    elif not isinstance(tree, KdTree):
        raise ValueError(f"tree must be a KdTree, got {type(tree).__name__}")
    nodes = np.ascontiguousarray(tree.nodes, dtype=np.uint32)
    return tree, nodes, nodes.view(np.float32), np.ascontiguousarray(tree.primitive_indices, dtype=np.int32), \
        np.ascontiguousarray(tree.bounds[0]), np.ascontiguousarray(tree.bounds[1])
