"""The ``malloc1997`` image (coherence.malloc_image): a heap walked by hand.

The references here are plain Python written from the allocator's and the
tracer's description in docs/memory_image.md, not from the kernels.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from coherence.layout import PRESET_RECORDS, get_layout
from coherence.malloc_image import HEAP_KINDS, CreationOrder, HeapModel, creation_order, heap_blocks
from coherence.studies import place_layout
from scene_factory import random_scene
from tracer.scenes.model import Material, SceneBuilder
from tracer.trace.records import RecordKind

ROOT = Path(__file__).resolve().parents[1]
HEADER, SMALLEST, PAGE = 16, 32, 8192


def _block_size(request):
    size = SMALLEST
    while size < request + HEADER:
        size *= 2
    return size


def _walk_allocator(requests, start):
    """Block addresses of a power-of-two bucket allocator, one request at a time."""
    top = (start + PAGE - 1) // PAGE * PAGE
    runs = {}  # block size -> [next free block, end of its run]
    blocks = []
    for request in requests:
        size = _block_size(int(request))
        run = runs.get(size)
        if run is None or run[0] + size > run[1]:
            length = max(size, PAGE)
            run = runs[size] = [top, top + length]
            top += length
        blocks.append(run[0])
        run[0] += size
    return blocks


def _walk_creation(scene, nodes):
    """(kind, index) in the order a recursive C tracer mallocs them."""
    order = [(RecordKind.LIGHT, i) for i in range(scene.light_position.shape[0])]
    made = set()
    for e in range(scene.element_kind.shape[0]):
        material = int(scene.element_material[e])
        if material not in made:
            made.add(material)
            order.append((RecordKind.MATERIAL, material))
        order.append((RecordKind.SPHERE + int(scene.element_kind[e]), int(scene.element_index[e])))
    order += [(RecordKind.MATERIAL, m) for m in range(scene.material_kd.shape[0]) if m not in made]

    def build(node):
        order.append((RecordKind.KD_NODE, node))
        link = int(nodes[node][1])
        if link & 3 == 3:  # a leaf: its list entries follow it
            order.extend((RecordKind.INDEX_ENTRY, int(nodes[node][0]) + j) for j in range(link >> 2))
        else:
            build(node + 1)
            build(link >> 2)

    if len(nodes):
        build(0)
    return order


def _record_size(kind, n_vertices=4):
    record = PRESET_RECORDS[RecordKind(kind).name.lower()][1]
    return record.size + record.per_vertex * n_vertices


def _scene_and_trace(seed):
    from tracer.rendering.render import RenderOptions, render

    scene = random_scene(n=40, seed=seed)
    return scene, render(scene, options=RenderOptions(size=8)).trace


@pytest.mark.parametrize("seed", [0, 3])
def test_scene_records_sit_where_a_walk_of_the_allocator_puts_them(seed):
    """Every heap record of a small scene's ``malloc1997`` image is where a by-hand
    recursive build and bucket walk puts it; every other record keeps its
    ``alpha1997`` address. Fails if ``_tree_order`` pushes the below child
    before the above one (``stack[sp] = node + 1`` first), building the above
    subtree first."""
    from tracer.kd.tree import KdTreeConfig, build_kdtree

    scene, trace = _scene_and_trace(seed)
    placed = place_layout(get_layout("malloc1997"), trace, scene)
    alpha = place_layout(get_layout("alpha1997"), trace, scene)
    tree = build_kdtree(scene, KdTreeConfig(**trace.metadata["kd_config"]))
    assert (tree.nodes[:, 1] & 3 != 3).sum() > 10  # a tree with interior nodes to order
    order = _walk_creation(scene, tree.nodes.tolist())
    n_vertices = {RecordKind.POLYGON: np.diff(scene.polygon_offsets), RecordKind.PATCH: np.diff(scene.patch_offsets)}
    sizes = [_record_size(kind, n_vertices[kind][i] if kind in n_vertices else 4) for kind, i in order]
    blocks = _walk_allocator(sizes, alpha.end)
    expected = alpha.record_start.copy()
    for (kind, index), block in zip(order, blocks):
        expected[alpha.kind_first[kind] + index] = block + HEADER
    assert len(order) == sum(int(np.diff(alpha.kind_first)[k]) for k in HEAP_KINDS)
    np.testing.assert_array_equal(placed.record_start, expected)
    np.testing.assert_array_equal(placed.record_size, alpha.record_size)


def _random_counts(rng):
    counts = {kind: int(rng.integers(0, 60)) for kind in HEAP_KINDS}
    counts.update({"ray_stack": 10, "hit_record": 4, "shading_temp": 4, "frame_buffer": 64})
    vertices = {kind: rng.integers(3, 400, counts[kind]) for kind in (RecordKind.POLYGON, RecordKind.PATCH)}
    return counts, vertices


@pytest.mark.parametrize("seed", range(4))
def test_random_record_counts_against_the_allocator_walk(seed):
    """Seeded random counts of every heap kind (polygons up to 400 vertices, so
    some blocks exceed a page), allocated in a random order: the layout's
    addresses are the by-hand walk's. Fails if ``_carve`` gives a block larger
    than a page a run of one page (``run = page_size``)."""
    rng = np.random.default_rng(seed)
    counts, vertices = _random_counts(rng)
    pairs = [(kind, i) for kind in HEAP_KINDS for i in range(counts[kind])]
    pairs = [pairs[k] for k in rng.permutation(len(pairs))]
    creation = CreationOrder(np.array([k for k, _ in pairs], dtype=np.int64),
                             np.array([i for _, i in pairs], dtype=np.int64))
    placed = get_layout("malloc1997").place(counts, vertices, None, creation)
    alpha = get_layout("alpha1997").place(counts, vertices)
    sizes = [_record_size(kind, vertices[kind][i] if kind in vertices else 4) for kind, i in pairs]
    assert max(sizes) + HEADER > PAGE
    blocks = _walk_allocator(sizes, alpha.end)
    for (kind, index), block in zip(pairs, blocks):
        assert placed.record_start[alpha.kind_first[kind] + index] == block + HEADER
    _check_blocks(placed, alpha)


def _check_blocks(placed, alpha):
    """Every heap record inside its block after a header; blocks disjoint, above the regions."""
    rows = np.concatenate([np.arange(placed.kind_first[k], placed.kind_first[k + 1]) for k in HEAP_KINDS])
    other = np.setdiff1d(np.arange(placed.record_start.size), rows)
    np.testing.assert_array_equal(placed.record_start[other], alpha.record_start[other])
    block = placed.record_start[rows] - HEADER
    size = np.array([_block_size(int(n)) for n in placed.record_size[rows]], dtype=np.int64)
    assert (block % np.minimum(size, PAGE) == 0).all()  # a block starts on its size within a page run
    assert (placed.record_start[rows] + placed.record_size[rows] <= block + size).all()
    order = np.argsort(block)
    assert (block[order][1:] >= (block + size)[order][:-1]).all()  # headers and records never overlap
    if rows.size:
        assert block.min() >= alpha.end and (block + size).max() <= placed.end


@pytest.mark.parametrize("seed", [0, 3])
def test_blocks_hold_their_records_and_never_overlap(seed):
    """The small scene's heap: each record lies in its own block after its
    16-byte header, blocks do not overlap and lie above the regions. Fails if
    ``MemoryLayout._place_heap`` places records at their blocks' starts
    (``record_start[rows] = blocks``, no header)."""
    scene, trace = _scene_and_trace(seed)
    _check_blocks(place_layout(get_layout("malloc1997"), trace, scene),
                  place_layout(get_layout("alpha1997"), trace, scene))


def test_hand_checked_allocator():
    """A light (48 bytes), a material (88), a sphere (104), a node (40), a
    polygon of 200 vertices (4,912) twice and a 9,000-byte request, from a
    heap at 0x1000 (rounded to 0x2000): worked out by hand. Fails if
    ``heap_blocks`` does not round the heap's start up to a page."""
    blocks = heap_blocks(HeapModel(), [48, 88, 104, 40, 4912, 4912, 9000], 0x1000)
    b = 0x2000
    # 64-byte class: page b; 128: page b+8K (material, then sphere); node next to the light;
    # 4,928 bytes -> 8K blocks, a run each; 9,016 -> a 16K run
    assert blocks.tolist() == [b, b + 8192, b + 8192 + 128, b + 64, b + 16384, b + 24576, b + 32768]


def test_hand_checked_creation_order():
    """Two lights; a sphere and a triangle of material A, a sphere of B, a
    polygon of A; a tree of a root, an interior node and three leaves
    (entries 0-1, 2, none). Fails if ``_scene_order`` allocates each
    element's material every time (without ``made``)."""
    b = SceneBuilder("hand")
    b.light((0, 0, 5))
    b.light((1, 0, 5))
    red, blue = Material((1, 0, 0)), Material((0, 0, 1))
    b.material(red)
    b.sphere((0, 0, 0), 1.0)
    b.triangle([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    b.material(blue)
    b.sphere((3, 0, 0), 1.0)
    b.material(red)
    b.polygon([(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)])
    scene = b.build()
    split = struct.unpack("<I", struct.pack("<f", 0.5))[0]
    # root: above child 4, axis 0; node 1: above child 3, axis 1; leaves 2 (entries 0, 1), 3 (2), 4 (none)
    nodes = np.array([[split, 4 << 2 | 0], [split, 3 << 2 | 1], [0, 2 << 2 | 3], [2, 1 << 2 | 3], [3, 0 << 2 | 3]],
                     dtype=np.uint32)
    order = creation_order(scene, nodes, np.array([0, 1, 2], dtype=np.int32))
    K = RecordKind
    assert list(zip(order.kind.tolist(), order.index.tolist())) == [
        (K.LIGHT, 0), (K.LIGHT, 1), (K.MATERIAL, 0), (K.SPHERE, 0), (K.TRIANGLE, 0), (K.MATERIAL, 1),
        (K.SPHERE, 1), (K.POLYGON, 0), (K.KD_NODE, 0), (K.KD_NODE, 1), (K.KD_NODE, 2), (K.INDEX_ENTRY, 0),
        (K.INDEX_ENTRY, 1), (K.KD_NODE, 3), (K.INDEX_ENTRY, 2), (K.KD_NODE, 4)]


def _table(heading: str) -> dict:
    """The rows of the first table after ``heading`` in docs/memory_image.md, first cell -> other cells."""
    text = (ROOT / "docs" / "memory_image.md").read_text(encoding="utf-8")
    rows = {}
    for line in text.split(heading, 1)[1].split("\n\n|", 1)[1].split("\n\n", 1)[0].splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if not set(cells[1]) <= set("-"):
            rows[cells[0]] = cells[1:]
    return rows


def test_memory_image_page_shows_the_allocator():
    """docs/memory_image.md's allocator tables are the code's: the parameters
    and every heap kind's block. Fails if ``HeapModel.header`` defaults to 8."""
    model = get_layout("malloc1997").heap
    parameters = _table("## The allocator")
    assert parameters == {"allocator parameter": ["bytes"], "header": [str(model.header)],
                          "smallest block": [str(model.smallest_block)], "run (the Alpha's page)": [str(model.page_size)]}
    blocks = _table("Blocks of the records")
    del blocks["record"]
    assert sorted(name.split(" ")[0] for name in blocks) == sorted(k.name.lower() for k in HEAP_KINDS)
    layout = get_layout("malloc1997")
    for name, (record_bytes, block_bytes) in blocks.items():
        kind = name.split(" ")[0]
        n = int(name.split("n = ")[1].rstrip(")")) if "n = " in name else 0
        request = layout.record(kind).size + layout.record(kind).per_vertex * n
        assert (record_bytes, block_bytes) == (str(request), str(int(model.block_sizes([request])[0]))), name


def test_malloc1997_is_alpha1997_sizes_with_a_heap_and_says_so():
    """The preset has the alpha1997 records and the documented allocator, and a
    study records its name. Fails if ``LAYOUTS`` loses ``malloc1997``."""
    from coherence.studies import study

    layout = get_layout("malloc1997")
    assert layout.records == get_layout("alpha1997").records and layout.heap == HeapModel()
    assert layout.scaled(2).heap == layout.heap
    scene, trace = _scene_and_trace(0)
    result = study(trace, ["S"], [1], layout="malloc1997", scene=scene, progress=False)
    assert result.parameters["layout"] == "malloc1997"


def test_bad_input_is_named():
    """A heap layout without a creation order, an order that leaves a record out,
    a trace of an unnamed scene without its scene, and a bad allocator field
    each raise one ValueError saying what is wrong. Fails if
    ``MemoryLayout.place`` stops checking that ``creation`` names every record
    (the left-out node then keeps its unused region address), or stops checking
    that no record is named twice."""
    layout = get_layout("malloc1997")
    counts = {"kd_node": 2, "sphere": 1}
    with pytest.raises(ValueError, match="creation order"):
        layout.place(counts)
    short = CreationOrder(np.array([RecordKind.SPHERE, RecordKind.KD_NODE]), np.array([0, 0]))
    with pytest.raises(ValueError, match="every record of the heap's kinds once"):
        layout.place(counts, None, None, short)
    # as many allocations as records, but node 0 twice and node 1 never: "2 distinct"
    twice = CreationOrder(np.array([RecordKind.SPHERE, RecordKind.KD_NODE, RecordKind.KD_NODE]), np.array([0, 0, 0]))
    with pytest.raises(ValueError, match="3 allocations, 3 of them records of those kinds, 2 distinct"):
        layout.place(counts, None, None, twice)
    with pytest.raises(ValueError, match="creation= is only for a layout with a heap"):
        get_layout("alpha1997").place(counts, None, None, short)
    scene, trace = _scene_and_trace(0)
    with pytest.raises(ValueError, match="not a scene of the catalogue"):
        place_layout(layout, trace)
    with pytest.raises(ValueError, match="HeapModel.header"):
        HeapModel(header=12)
    with pytest.raises(ValueError, match="HeapModel.smallest_block"):
        HeapModel(smallest_block=16)


def test_the_report_warm_up_compiles_for_malloc1997():
    """The report's warm-up compiles the simulation on a synthetic trace, which
    has no scene to allocate a heap from; with ``malloc1997`` it compiles the
    same kernels without the heap instead of failing. Fails if
    ``analyses.warmup._compile`` keeps the layout's heap (no ``replace``)."""
    from analyses.warmup import _compile
    from cachesim import get_hierarchy
    from coherence.cost import get_cost_model
    from coherence.mappings import get_mapping
    from coherence.simulation import Machine

    _compile(get_hierarchy("alpha21164"), get_layout("malloc1997"), get_cost_model("alpha8400"), Machine(),
             [get_mapping("S")])
