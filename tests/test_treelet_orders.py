"""Treelet queues (coherence.treelet_orders) against plain-Python references (tests/reference_treelets.py)."""
import numpy as np
import pytest

from coherence.ray_orders import order_pieces
from coherence.treelet_orders import TreeletQueues, cut_segments, treelets
from reference_ray_orders import events_of, random_segments
from reference_treelets import cut, random_records, random_tree, treelet_events
from reference_treelets import treelets as reference_treelets
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.model import Camera, Material, SceneBuilder
from tracer.trace.records import AuxKind, unpack_aux

# a hand-drawn tree: 0 splits into 1 and 4; 1 into leaves 2, 3; 4 into leaf 5 and 6; 6 into leaves 7, 8
_HAND = np.array([[0, 4 << 2], [0, 3 << 2 | 1], [0, 3], [0, 3], [0, 6 << 2 | 2], [0, 3], [0, 8 << 2], [0, 3],
                  [0, 3]], dtype=np.uint32)


def test_treelets_of_a_hand_checked_tree():
    """Three nodes per treelet (24 bytes of 8-byte nodes): the root's treelet takes 0, 1, 4 (breadth first);
    2, 3, 5 and 6 start treelets 1-4 in the order the walk reached them; 6's treelet takes 7 and 8. Fails
    if _treelets walks depth first (the next node taken from the walk's tail, not its head) (checked)."""
    treelet, n = treelets(_HAND, 24, 8)
    assert treelet.tolist() == [0, 0, 1, 2, 0, 3, 4, 4, 4] and n == 5
    treelet, n = treelets(_HAND, 16, 8)  # 31 bytes would hold 3 nodes; 16 holds 2
    assert treelet.tolist() == reference_treelets(_HAND, 2)[0] and n == reference_treelets(_HAND, 2)[1]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("max_nodes", [1, 3, 7])
def test_treelets_equal_reference_on_random_trees(seed, max_nodes):
    """Treelets equal the plain-Python breadth-first partition on seeded random trees, every treelet is
    connected (a node's parent is in its treelet unless it is the treelet's root) and holds at most
    max_nodes nodes. Fails if the treelet is full at ``max_nodes + 1`` (checked)."""
    nodes = random_tree(seed)
    treelet, n = treelets(nodes, 8 * max_nodes + 7, 8)
    expected, expected_n = reference_treelets(nodes, max_nodes)
    assert treelet.tolist() == expected and n == expected_n
    assert np.bincount(treelet).max() <= max_nodes
    roots = 0
    for node in range(len(nodes)):
        link = int(nodes[node][1])
        if link & 3 != 3:
            for child in (node + 1, link >> 2):
                roots += treelet[child] != treelet[node]
    assert roots == n - 1  # every treelet but the root's is entered through exactly one edge


@pytest.mark.parametrize("seed", range(3))
def test_cuts_equal_reference_walk(seed):
    """Cutting every segment equals a record-by-record walk, and the pieces tile the records. Fails if _cut
    cuts at every node record (``current >= 0 and t != current`` -> ``current >= 0``) (checked)."""
    nodes = random_tree(seed + 10)
    node_treelet, _ = treelets(nodes, 24, 8)
    segments, n_records = random_segments(n_pixels=5, spp=2, seed=seed)
    records = random_records(segments, len(nodes), seed)
    rows = np.arange(segments.n_segments)
    offsets, first, stop, piece_treelet = cut_segments(records, segments, rows, node_treelet)
    got = [list(zip(first[offsets[s]:offsets[s + 1]].tolist(), stop[offsets[s]:offsets[s + 1]].tolist(),
                    piece_treelet[offsets[s]:offsets[s + 1]].tolist())) for s in rows]
    expected = [cut(records, int(row[4]), int(row[5]), node_treelet.tolist()) for row in segments.ints]
    assert got == [[tuple(p) for p in e] for e in expected]
    assert (stop - first).sum() == n_records


@pytest.mark.parametrize("seed", range(3))
def test_treelet_order_equals_reference_queues(seed):
    """The treelet order's pieces, ray states and queue entries, in order, equal the reference walk with
    explicit phase and treelet queues, on seeded random trees, records and segments (one process's pixels).
    Fails if the sweeps visit the treelets bottom-up (``range(n_treelets)`` -> ``range(n_treelets - 1, -1,
    -1)`` in _walk) (checked)."""
    nodes = random_tree(seed + 20)
    segments, _ = random_segments(n_pixels=6, spp=2, seed=seed + 5)
    records = random_records(segments, len(nodes), seed)
    rows = np.flatnonzero(segments.ints[:, 0] % 2 == 0)
    pieces = order_pieces(segments, rows, TreeletQueues(treelet_bytes=24, node_bytes=8), tree=nodes,
                          records=records)
    node_treelet, n_treelets = treelets(nodes, 24, 8)
    assert events_of(pieces) == treelet_events(segments.ints[rows], records, node_treelet.tolist(), n_treelets)


def test_treelet_order_needs_tree_and_records():
    """Without the tree or the records the order is a one-line ValueError; a treelet smaller than a node is
    refused by field. Fails if order_pieces stops checking ``needs_records`` (checked)."""
    segments, _ = random_segments(n_pixels=2, spp=1, seed=0)
    with pytest.raises(ValueError, match="kd-tree"):
        order_pieces(segments, np.arange(segments.n_segments), TreeletQueues())
    with pytest.raises(ValueError, match="records"):
        order_pieces(segments, np.arange(segments.n_segments), TreeletQueues(), tree=_HAND)
    with pytest.raises(ValueError, match="TreeletQueues.treelet_bytes must be >= node_bytes"):
        TreeletQueues(treelet_bytes=4, node_bytes=8)


def test_a_tree_smaller_than_the_records_visit_is_refused():
    """Records that visit kd nodes the given tree does not have are a one-line error naming the tree, not
    an out-of-bounds read in the cutting kernel. Fails if cut_segments drops its node-count check (checked:
    the kernel then reads past node_treelet)."""
    segments, _ = random_segments(n_pixels=2, spp=1, seed=0)
    records = random_records(segments, 100_000, 1)
    with pytest.raises(ValueError, match="tree: the records visit kd node"):
        order_pieces(segments, np.arange(segments.n_segments), TreeletQueues(),
                     tree=np.array([[0, 3]], dtype=np.uint32), records=records)


def test_treelet_order_on_a_path_trace():
    """On a real path trace with an L1-sized treelet budget of 64 bytes, rays are cut (more pieces than
    segments), queue entries are written and read in equal numbers, and the pieces replay every record
    once. Fails if cut_segments never cuts (``node_treelet`` all zero) (checked)."""
    b = SceneBuilder("treelets")
    b.camera = Camera(eye=(0.0, 1.0, 7.0), look_at=(0.0, 0.0, 0.0), up=(0, 1, 0), angle=45.0, hither=1e-3,
                      resolution=(4, 4))
    b.max_depth = 3
    b.material(Material((0.8, 0.7, 0.6), 0.9, 0.0, 1.0, 0.0, 1.0))
    for k in range(12):
        b.sphere((k % 4 - 1.5, k // 4 - 1.0, 0.3 * k), 0.4)
    b.light((4.0, 6.0, 5.0), (1.0, 1.0, 1.0))
    result = path_trace(b.build(), options=RenderOptions(workload="pathtrace", spp=1, seed=2, log=True))
    trace = result.trace
    rows = np.arange(trace.segments.n_segments)
    pieces = order_pieces(trace.segments, rows, TreeletQueues(treelet_bytes=64), tree=result.tree,
                          records=np.asarray(trace.records))
    assert pieces.n_pieces > rows.size
    counts = pieces.aux_counts()
    assert counts["queue_writes"] == counts["queue_reads"] > 0
    covered = np.zeros(trace.n_records, dtype=np.int64)
    for first, stop in zip(pieces.piece_first, pieces.piece_stop):
        covered[first:stop] += 1
    assert (covered == 1).all()
    assert set(unpack_aux(pieces.aux_records)[0].tolist()) == {AuxKind.RAY_STATE, AuxKind.QUEUE_ENTRY}


def test_cut_of_a_hand_checked_ray():
    """On the hand-drawn tree (treelets of 3 nodes: 0 1 4 | 2 | 3 | 5 | 6 7 8) a ray reading nodes 0, 1, 2,
    a sphere, then 4, 6, 7 and its material is cut into (0, 1) in treelet 0, (2, sphere) in 1, (4) back in
    0 and (6, 7, material) in 4. Fails if a piece takes the treelet of its last node record instead of its
    first (``current`` -> ``t`` when a piece is closed in _cut) (checked)."""
    from tracer.trace.records import RecordKind, pack
    from tracer.trace.segments import RaySegments

    kinds = [RecordKind.KD_NODE] * 3 + [RecordKind.SPHERE] + [RecordKind.KD_NODE] * 3 + [RecordKind.MATERIAL]
    records = pack(kinds, [0, 1, 2, 5, 4, 6, 7, 0])
    segments = RaySegments(np.array([[0, 0, 0, 0, 0, 8]], dtype=np.int64), np.zeros((1, 9)))
    node_treelet, _ = treelets(_HAND, 24, 8)
    offsets, first, stop, piece_treelet = cut_segments(records, segments, np.array([0]), node_treelet)
    assert list(zip(first.tolist(), stop.tolist(), piece_treelet.tolist())) == [(0, 2, 0), (2, 4, 1), (4, 5, 0),
                                                                               (5, 8, 4)]
    assert offsets.tolist() == [0, 4]


def test_sized_treelets_follow_the_cache_and_the_layout():
    """sized(cache, node) gives treelets of the cache's bytes of the layout's nodes, never less than one
    node. Fails if sized keeps the registered node size (``node_bytes=node_bytes`` dropped) (checked)."""
    from coherence.ray_orders import RAY_ORDERS

    order = RAY_ORDERS["treelet"].sized(32768, 40)
    assert (order.treelet_bytes, order.node_bytes, order.name) == (32768, 40, "treelet")
    assert RAY_ORDERS["treelet"].sized(16, 40).treelet_bytes == 40
