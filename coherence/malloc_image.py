"""The ``malloc1997`` memory image: scene records in a 1990s C heap.

A C ray tracer of the mid-1990s called ``malloc`` once per object, per
material, per light, per BSP node and per leaf-list entry, in the order it
created them. Where a record lands then depends on that order and on the
allocator, not on its kind. This module gives

* :class:`HeapModel`, the allocator: power-of-two size classes as in the
  4.2BSD ``malloc`` (a header before every block; each class carves its
  blocks from runs of one page taken from the heap's top; a request of a
  page or more gets a run of its own);
* :func:`creation_order`, the order the tracer made the records in:
  lights, then the scene's elements in file order each preceded by its
  material when that is first used, then the BSP tree built recursively,
  each leaf followed by its list entries;
* :func:`heap_blocks`, where the allocator puts each block, in that order.

:meth:`coherence.layout.MemoryLayout.place` uses them for a layout with a
``heap`` (the ``malloc1997`` preset), and :func:`trace_creation_order`
rebuilds the order of a trace's scene and tree.
``docs/memory_image.md`` gives the model, its reasons and its sizes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.validate import InputError, require_int, require_power_of_two
from tracer.kd.nodes import LINK_WORD, FLAG_BITS, FLAG_MASK, LEAF_FLAG, OFFSET_WORD
from tracer.trace.records import RecordKind

#: The record kinds the tracer allocates one at a time; the others (the
#: per-ray data, the frame buffer and textures) keep their regions.
HEAP_KINDS = (RecordKind.KD_NODE, RecordKind.INDEX_ENTRY, RecordKind.SPHERE, RecordKind.TRIANGLE,
              RecordKind.POLYGON, RecordKind.PATCH, RecordKind.CONE, RecordKind.MATERIAL, RecordKind.LIGHT)


@dataclass(frozen=True)
class HeapModel:
    """A power-of-two size-class allocator (4.2BSD ``malloc``).

    A request of ``n`` bytes gets a block of the smallest power of two that
    holds ``n + header`` bytes (at least ``smallest_block``); the record
    starts ``header`` bytes into it. Blocks of one size come from runs of
    ``page_size`` bytes (one block per run for blocks of a page or more)
    taken from the heap's top when the class's run is used up, so
    consecutive allocations of one class are adjacent and the classes
    interleave page by page in allocation order. Nothing is freed.

    Parameters
    ----------
    header : int
        Bytes before every record (the allocator's bookkeeping); a multiple
        of 8, so that records keep their 8-byte alignment.
    smallest_block : int
        The smallest block (a power of two larger than ``header``).
    page_size : int
        Bytes of a run (a power of two, at least ``smallest_block``); the
        heap starts on a multiple of it.
    """

    header: int = 16
    smallest_block: int = 32
    page_size: int = 8192

    def __post_init__(self):
        require_int("HeapModel.header", self.header, 0, 4096)
        if self.header % 8:
            raise InputError(f"HeapModel.header must be a multiple of 8 bytes, got {self.header}")
        require_power_of_two("HeapModel.smallest_block", self.smallest_block)
        if self.smallest_block <= self.header:
            raise InputError(f"HeapModel.smallest_block must be larger than the header ({self.header}), "
                             f"got {self.smallest_block}")
        require_power_of_two("HeapModel.page_size", self.page_size)
        if self.page_size < self.smallest_block:
            raise InputError(f"HeapModel.page_size must be >= smallest_block ({self.smallest_block}), "
                             f"got {self.page_size}")

    def block_sizes(self, request) -> np.ndarray:
        """Block bytes (int64, shape (B,)) for requests of ``request`` bytes (shape (B,))."""
        request = np.asarray(request, dtype=np.int64)
        if request.size and request.min() < 1:
            raise InputError("HeapModel.block_sizes: every request must be >= 1 byte")
        return _block_sizes(request, self.header, self.smallest_block)


class CreationOrder(NamedTuple):
    """The records a tracer allocates, in the order it allocates them.

    Attributes
    ----------
    kind : ndarray of int64, shape (B,)
        :class:`~tracer.trace.records.RecordKind` of each allocation.
    index : ndarray of int64, shape (B,)
        The record's index within its kind (as the trace numbers it).
    """

    kind: np.ndarray
    index: np.ndarray


def creation_order(scene, nodes, primitive_indices) -> CreationOrder:
    """The order a 1990s C tracer allocates a scene's and its tree's records.

    Lights first (an SPD file lists them before the objects; the scene keeps
    them apart from the elements), then the elements in file order, each
    preceded by its material where the element is the material's first
    user (the reader allocates a material as it reads it), then materials
    no element uses, then the tree: a recursive build allocates a node, and
    a leaf's list entries right after the leaf, the child below the plane
    before the child above.

    Parameters
    ----------
    scene : tracer.scenes.model.Scene
    nodes : ndarray of uint32, shape (N, 2)
        The tree's nodes (:mod:`tracer.kd.nodes`), root first.
    primitive_indices : ndarray, shape (E,)
        The leaves' entries; a record's index is its position here.

    Returns
    -------
    CreationOrder
    """
    nodes = np.ascontiguousarray(nodes, dtype=np.uint32)
    if nodes.ndim != 2 or nodes.shape[1] != 2:
        raise InputError(f"creation_order: nodes must have shape (N, 2), got {nodes.shape}")
    n_entries = int(np.asarray(primitive_indices).shape[0])
    n_lights = int(scene.light_position.shape[0])
    n_materials = int(scene.material_kd.shape[0])
    element_material = np.ascontiguousarray(scene.element_material, dtype=np.int64)
    if element_material.size and (element_material.min() < 0 or element_material.max() >= n_materials):
        raise InputError(f"creation_order: Scene.element_material must name materials 0..{n_materials - 1}")
    scene_kind, scene_index = _scene_order(n_lights, np.ascontiguousarray(scene.element_kind, dtype=np.int64),
                                           np.ascontiguousarray(scene.element_index, dtype=np.int64),
                                           element_material, n_materials)
    tree_kind, tree_index, n_walked = _tree_order(nodes, n_entries)
    if n_walked != nodes.shape[0] or tree_kind.shape[0] != nodes.shape[0] + n_entries:
        raise InputError(f"creation_order: the tree's {nodes.shape[0]} nodes and {n_entries} entries do not form "
                         f"one tree from node 0 (a walk reaches {n_walked} nodes)")
    return CreationOrder(np.concatenate([scene_kind, tree_kind]), np.concatenate([scene_index, tree_index]))


def heap_blocks(model: HeapModel, request, heap_start: int) -> np.ndarray:
    """Where ``model`` puts blocks for ``request`` (bytes, shape (B,)), in that order.

    Parameters
    ----------
    model : HeapModel
    request : ndarray of int, shape (B,)
        Bytes each allocation asks for (the record's size).
    heap_start : int
        The heap's first address; rounded up to a multiple of
        ``model.page_size``.

    Returns
    -------
    ndarray of int64, shape (B,)
        Each block's first address; its record starts ``model.header``
        bytes later.
    """
    if not isinstance(model, HeapModel):
        raise InputError(f"heap_blocks: model must be a HeapModel, got {type(model).__name__}")
    sizes = model.block_sizes(request)
    start = require_int("heap_blocks: heap_start", heap_start, 0, 2**48 - 1)
    start = -(-start // model.page_size) * model.page_size
    return _carve(sizes, start, model.page_size)


def trace_creation_order(trace, scene=None) -> CreationOrder:
    """:func:`creation_order` of a trace's scene and of the tree its render built.

    The tree is built again from the scene with the trace's recorded
    ``kd_config`` (the build is deterministic). Without ``scene``, the
    scene the trace's metadata names is loaded when it is one of the
    catalogue's (:data:`tracer.scenes.catalog.NAMED_SCENES`). The scene's
    and the tree's record counts must be the trace's ``record_counts``.
    """
    from tracer.kd.tree import KdTreeConfig, build_kdtree
    from tracer.scenes.catalog import NAMED_SCENES, load

    metadata = getattr(trace, "metadata", None) or {}
    counts, config = metadata.get("record_counts"), metadata.get("kd_config")
    if not counts or not config:
        raise InputError("the malloc1997 image places records in the order the tracer created them, which needs "
                         "a trace whose metadata holds record_counts and kd_config (one written by "
                         "tracer.rendering.render)")
    if scene is None:
        if metadata.get("scene") not in NAMED_SCENES:
            raise InputError(f"the malloc1997 image places records in the order the tracer created them, which "
                             f"needs the trace's scene: {metadata.get('scene')!r} is not a scene of the catalogue "
                             f"({', '.join(NAMED_SCENES)}); pass the scene (scene=...)")
        scene = load(metadata["scene"])
    tree = build_kdtree(scene, KdTreeConfig(**config))
    have = {"kd_node": tree.nodes.shape[0], "index_entry": tree.primitive_indices.size,
            "sphere": scene.sphere_radius.size, "triangle": scene.triangle_vertices.shape[0],
            "polygon": scene.polygon_offsets.size - 1, "patch": scene.patch_offsets.size - 1,
            "cone": scene.cone_base_radius.size, "material": scene.material_kd.size,
            "light": scene.light_position.shape[0]}
    for name, count in have.items():
        if int(counts.get(name, 0)) != int(count):
            raise InputError(f"the scene {scene.name!r} and the tree rebuilt from the trace's kd_config have "
                             f"{count} {name} records but the trace's record_counts say {counts.get(name, 0)}: "
                             "is it the trace of this scene?")
    return creation_order(scene, tree.nodes, tree.primitive_indices)


@njit(cache=True)
def _block_sizes(request, header, smallest):
    out = np.empty(request.shape[0], dtype=np.int64)
    for i in range(request.shape[0]):
        size = smallest
        while size < request[i] + header:
            size *= 2
        out[i] = size
    return out


@njit(cache=True)
def _carve(sizes, start, page_size):
    # run_next[c], run_end[c]: the next free block and the end of size class c's current run
    run_next = np.zeros(64, dtype=np.int64)
    run_end = np.zeros(64, dtype=np.int64)
    top = start
    out = np.empty(sizes.shape[0], dtype=np.int64)
    for i in range(sizes.shape[0]):
        size = sizes[i]
        c = 0
        while (np.int64(1) << c) < size:
            c += 1
        if run_next[c] + size > run_end[c] or run_end[c] == 0:
            run = max(size, page_size)
            run_next[c] = top
            run_end[c] = top + run
            top += run
        out[i] = run_next[c]
        run_next[c] += size
    return out


@njit(cache=True)
def _scene_order(n_lights, element_kind, element_index, element_material, n_materials):
    n_elements = element_kind.shape[0]
    kind = np.empty(n_lights + n_elements + n_materials, dtype=np.int64)
    index = np.empty_like(kind)
    made = np.zeros(n_materials, dtype=np.bool_)
    k = 0
    for light in range(n_lights):
        kind[k] = RecordKind.LIGHT
        index[k] = light
        k += 1
    for e in range(n_elements):
        m = element_material[e]
        if not made[m]:
            made[m] = True
            kind[k] = RecordKind.MATERIAL
            index[k] = m
            k += 1
        kind[k] = RecordKind.SPHERE + element_kind[e]
        index[k] = element_index[e]
        k += 1
    for m in range(n_materials):
        if not made[m]:
            kind[k] = RecordKind.MATERIAL
            index[k] = m
            k += 1
    return kind[:k], index[:k]


@njit(cache=True)
def _tree_order(nodes, n_entries):
    # preorder walk from node 0 with an explicit stack: a node, then its entries (a leaf) or its below
    # subtree before its above subtree; stops early (short count) on a malformed tree
    n_nodes = nodes.shape[0]
    kind = np.empty(n_nodes + n_entries, dtype=np.int64)
    index = np.empty_like(kind)
    seen = np.zeros(n_nodes, dtype=np.bool_)
    stack = np.empty(2 * n_nodes + 2, dtype=np.int64)  # a pop pushes at most two
    sp = 0
    if n_nodes > 0:
        stack[0] = 0
        sp = 1
    k = 0
    walked = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if node < 0 or node >= n_nodes or seen[node] or k >= kind.shape[0]:
            return kind[:k], index[:k], -1
        seen[node] = True
        walked += 1
        kind[k] = RecordKind.KD_NODE
        index[k] = node
        k += 1
        link = np.int64(nodes[node, LINK_WORD])
        if (link & FLAG_MASK) == LEAF_FLAG:
            offset = np.int64(nodes[node, OFFSET_WORD])
            count = link >> FLAG_BITS
            if offset + count > n_entries or k + count > kind.shape[0]:
                return kind[:k], index[:k], -1
            for j in range(count):
                kind[k] = RecordKind.INDEX_ENTRY
                index[k] = offset + j
                k += 1
        else:
            stack[sp] = link >> FLAG_BITS  # above: built after the whole below subtree
            stack[sp + 1] = node + 1       # below
            sp += 2
    return kind[:k], index[:k], walked
