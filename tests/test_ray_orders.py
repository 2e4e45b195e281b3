"""Ray orders (coherence.ray_orders): permutations of a path-traced trace's segments and their own records."""
import numpy as np
import pytest

from cachesim import CacheLevel, Hierarchy
from coherence.cost import ray_sort_cycles
from coherence.layout import get_layout, record_counts_of
from coherence.mappings import Strip
from coherence.cost import CostModel
from coherence.ray_order_base import QUEUE_OFFSET, OrderBuffers, path_structure
from coherence.ray_orders import RAY_ORDERS, get_ray_order, order_pieces, order_stream, replay_order, scene_bounds_of
from coherence.sorted_ray_orders import morton_keys
from coherence.simulation import Machine, simulate_run
from reference_ray_orders import events_of, morton_key, order_keys, random_segments, wavefront_events
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.model import Camera, Material, SceneBuilder
from tracer.trace.records import AuxKind, pack_aux
from tracer.trace.segments import RaySegments, SegmentColumn

SMALL = Hierarchy((CacheLevel("L1", 256, 32, 1, latency=2), CacheLevel("L2", 1024, 64, 2, latency=9)),
                  memory_latency=50)


@pytest.fixture(scope="module")
def traced():
    """A 5 x 4 path-traced trace of three spheres and two lights, 2 samples, up to 4 rays a path."""
    b = SceneBuilder("orders")
    b.camera = Camera(eye=(0.0, 1.0, 7.0), look_at=(0.0, 0.0, 0.0), up=(0, 1, 0), angle=45.0, hither=1e-3,
                      resolution=(5, 4))
    b.max_depth = 4
    b.material(Material((0.8, 0.7, 0.6), 0.9, 0.0, 1.0, 0.0, 1.0))
    b.sphere((0.0, -101.0, 0.0), 100.0)
    b.material(Material((0.2, 0.9, 0.3), 0.7, 0.2, 10.0, 0.0, 1.0))
    b.sphere((-1.2, 0.0, 0.0), 1.0)
    b.sphere((1.2, 0.0, 0.5), 0.9)
    b.light((4.0, 6.0, 5.0), (1.0, 1.0, 1.0))
    b.light((-5.0, 3.0, 4.0), (0.6, 0.5, 0.4))
    trace = path_trace(b.build(), options=RenderOptions(workload="pathtrace", spp=2, seed=5, log=True)).trace
    return trace, get_layout("compact").place(record_counts_of(trace))


def test_depth_first_replay_equals_simulate_in_pixel_order(traced):
    """Replaying every segment depth-first through empty caches gives the hits and misses per level of
    simulate_run with one process rendering the pixels in order (Strip, 1 process). Fails if
    depth_first_pieces reverses the rows (``rows[::-1]``) (checked)."""
    trace, placed = traced
    pieces = order_pieces(trace.segments, np.arange(trace.segments.n_segments), "depth-first")
    assert pieces.aux_records.size == 0 and pieces.sort_cycles == 0.0
    replayed = replay_order(trace.records, pieces, placed, SMALL)
    run = simulate_run(trace, Strip().build(trace.width, trace.height, 1), SMALL, placed, CostModel(),
                       Machine(n_cpus=1, quantum_cycles=0))
    for index, level in enumerate(SMALL.levels):
        assert replayed.counts[index, 1] == run.processes[f"{level.name}_hits"][0]
        assert replayed.counts[index, 2] == run.processes[f"{level.name}_misses"][0]
    assert replayed.counts[0, 0] > 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_wavefront_equals_reference_walk(seed):
    """The wavefront's pieces and buffer and queue records, in order, equal a ray-by-ray walk with explicit
    queues (tests/reference_ray_orders.py) on seeded random segments, a subset of rows in depth-first order.
    Fails if the suspended ray's state write is tied after its children's queue writes (``np.zeros(n,
    np.int64)`` -> ``np.full(n, n)`` in _wavefront_records) (checked)."""
    segments, _ = random_segments(n_pixels=7, spp=3, seed=seed)
    pixels = segments.ints[:, SegmentColumn.PIXEL]
    rows = np.flatnonzero(pixels % 2 == seed % 2)  # one process's pixels
    pieces = order_pieces(segments, rows, "wavefront")
    assert events_of(pieces) == wavefront_events(segments.ints[rows])


def test_wavefront_hand_checked():
    """Two paths: A = camera, shadow, bounce; B = camera. By hand: both camera rays queued and created, then
    A's camera ray (queues its shadow ray and bounce), B's camera ray, A's shadow ray (phase 1), A's bounce
    (phase 2, queue slots from 2 * capacity 2 = 4). Fails if children are queued before their parent
    suspends (``rank[parent[children]] + 1`` -> ``rank[parent[children]]``) (checked)."""
    ints = np.array([[0, 0, 0, 0, 0, 3], [0, 0, 0, 2, 3, 4], [0, 0, 1, 1, 4, 6], [1, 0, 0, 0, 6, 8]], dtype=np.int64)
    segments = RaySegments(ints, np.zeros((4, 9)))
    pieces = order_pieces(segments, np.arange(4), "wavefront")
    q, s = "queue", "state"
    assert events_of(pieces) == [
        (q, 0, True), (s, 0, True), (q, 1, True), (s, 1, True),
        (q, 0, False), (s, 0, False), ("piece", 0, 3), (s, 0, True), (q, 2, True), (q, 4, True),
        (q, 1, False), (s, 1, False), ("piece", 6, 8), (s, 1, True),
        (q, 2, False), (s, 0, False), ("piece", 3, 4), (s, 0, True),
        (q, 4, False), (s, 0, False), ("piece", 4, 6), (s, 0, True)]


def test_wavefront_respects_dependences_and_keeps_every_record():
    """Every ray runs after the ray that spawned it, phases never go back, and the pieces are a
    permutation of the segments' ranges. Fails if path_structure's phase of a shadow ray is ``2 * bounce``
    (``+ (~extension)`` dropped) (checked)."""
    segments, n_records = random_segments(n_pixels=9, spp=2, seed=4)
    rows = np.arange(segments.n_segments)
    pieces = order_pieces(segments, rows, "wavefront")
    _, phase, parent, _ = path_structure(segments.ints)
    ran_at = np.empty(rows.size, dtype=np.int64)
    ran_at[pieces.piece_segment] = np.arange(rows.size)
    spawned = parent >= 0
    assert (ran_at[spawned] > ran_at[parent[spawned]]).all()
    assert (np.diff(phase[pieces.piece_segment]) >= 0).all()
    assert np.array_equal(np.sort(pieces.piece_segment), rows)
    assert (pieces.piece_stop - pieces.piece_first).sum() == n_records


def test_rows_out_of_depth_first_order_are_refused():
    """A path whose bounce comes before its camera ray, a path split in two and a repeated row are each a
    one-line ValueError. Fails if path_structure's check is dropped (``if bad.any():`` -> ``if False:``)
    (checked)."""
    segments, _ = random_segments(n_pixels=3, spp=1, seed=1, max_depth=3)
    rows = np.arange(segments.n_segments)
    with pytest.raises(ValueError, match="depth-first order"):
        order_pieces(segments, rows[::-1], "wavefront")
    split = segments.ints[:, SegmentColumn.PIXEL] == 0
    with pytest.raises(ValueError, match="depth-first order"):
        order_pieces(segments, np.concatenate((rows[split][1:], rows[split][:1], rows[~split])), "wavefront")
    with pytest.raises(ValueError, match="must not repeat"):
        order_pieces(segments, np.concatenate((rows, rows[:1])), "depth-first")
    with pytest.raises(ValueError, match="unknown ray order"):
        order_pieces(segments, rows, "sideways")


def test_order_stream_places_buffers_per_process():
    """A ray state of process p lies at base + p * spacing + slot * state bytes, a queue entry
    QUEUE_OFFSET further at slot * entry bytes; writes keep their flag. Fails if extents forgets the
    process's spacing (checked)."""
    buffers = OrderBuffers(ray_state_bytes=64, queue_entry_bytes=4)
    records = np.concatenate((pack_aux(AuxKind.RAY_STATE, [3], True), pack_aux(AuxKind.QUEUE_ENTRY, [5], False)))
    start, size = buffers.extents(records, 2)
    base = buffers.base + 2 * buffers.spacing
    assert start.tolist() == [base + 3 * 64, base + QUEUE_OFFSET + 5 * 4] and size.tolist() == [64, 4]
    segments = RaySegments(np.array([[0, 0, 0, 0, 0, 0]], dtype=np.int64), np.zeros((1, 9)))
    pieces = order_pieces(segments, [0], "wavefront")
    placed = get_layout("compact").place({})
    addresses, writes = order_stream(np.zeros(0, np.uint32), pieces, placed, 32, buffers=buffers, process=1)
    state = buffers.base + buffers.spacing
    assert addresses.tolist() == [state + QUEUE_OFFSET, state, state + 32, state + QUEUE_OFFSET, state, state + 32,
                                  state, state + 32]
    assert writes.tolist() == [True, True, True, False, False, False, True, True]


def test_wavefront_replay_counts_its_buffer_accesses(traced):
    """Replaying the wavefront reads and writes every scene record the depth-first order does, plus one
    access per line of each of its own records (64-byte states span two 32-byte lines). Fails if
    _wavefront_records reads the suspended ray's state instead of writing it (``pack_aux(state, path, True)``
    -> ``False``) (checked)."""
    trace, placed = traced
    rows = np.arange(trace.segments.n_segments)
    pieces = order_pieces(trace.segments, rows, "wavefront")
    depth_first = order_pieces(trace.segments, rows, "depth-first")
    wave = replay_order(trace.records, pieces, placed, SMALL)
    plain = replay_order(trace.records, depth_first, placed, SMALL)
    counts = pieces.aux_counts()
    n_states = counts["ray_state_reads"] + counts["ray_state_writes"]
    assert counts["queue_reads"] == rows.size and counts["ray_state_reads"] == rows.size
    assert wave.counts[0, 0] == plain.counts[0, 0] + 2 * n_states + counts["queue_reads"] + counts["queue_writes"]


def test_ray_sort_cycles_counts_radix_passes():
    """A 17-bit key takes three 8-bit passes of 6 cycles per ray; one ray or no key costs nothing. Fails
    if the passes round down (``-(-key_bits // 8)`` -> ``key_bits // 8``) (checked)."""
    assert ray_sort_cycles(10, 17) == 10 * 3 * 6.0
    assert ray_sort_cycles(1, 64) == 0.0 and ray_sort_cycles(10, 0) == 0.0


def test_registry_names():
    """Every registered order is found by its name, case ignored. Fails if get_ray_order stops folding case."""
    for name, order in RAY_ORDERS.items():
        assert get_ray_order(name.upper()) is order


def test_morton_keys_equal_bitwise_reference():
    """Morton keys equal a bit-by-bit interleaving on seeded random points (some outside the box) and by hand:
    the low corner is 0, the high corner 2**63 - 1, the middle of x (cell 2**20) alone is bit 62. Fails if
    _spread's last mask is 0x1249249249249249 >> 1 (checked)."""
    rng = np.random.default_rng(7)
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([3.0, 5.0, 2.5])
    points = rng.uniform(-2.0, 6.0, (200, 3))
    keys = morton_keys(points, np.stack((lo, hi)))
    assert keys.tolist() == [morton_key(p, lo, hi, 21) for p in points]
    corners = morton_keys(np.array([lo, hi, [1.0, 0.0, 2.0]]), np.stack((lo, hi)))
    assert corners.tolist() == [0, 2**63 - 1, 1 << 62]


@pytest.mark.parametrize("name", ["morton-origin", "octant-origin", "hit-point"])
def test_sorted_wavefronts_equal_reference_walk(name):
    """Each sorted wavefront equals the reference walk with its phases stable-sorted by keys computed ray by
    ray (tests/reference_ray_orders.py: Morton bit by bit, octant signs, proxy hits), and pays one radix
    sort per phase. Fails if HitPoint sorts by the raw logged hit without the proxy for missed rays
    (``_proxy_hits`` keeping NaN) (checked), or if wavefront_pieces stops sorting (checked)."""
    segments, _ = random_segments(n_pixels=8, spp=2, seed=3)
    rows = np.arange(segments.n_segments)
    bounds = scene_bounds_of(segments)
    pieces = order_pieces(segments, rows, name)
    keys = order_keys(name, segments.rays, bounds[0], bounds[1])
    assert events_of(pieces) == wavefront_events(segments.ints, keys)
    _, phase, _, _ = path_structure(segments.ints)
    assert pieces.sort_cycles == sum(ray_sort_cycles(int(n), 63) for n in np.bincount(phase))


def test_a_process_without_rays_replays_nothing():
    """Every order, the treelet queues included, gives no piece and no record for a process that owns no
    segment (a strip of a mapping with more processes than rows). Fails if wavefront_pieces drops its
    ``if n else 0`` guard on the phase count (``phase.max()`` of nothing raises) (checked)."""
    from coherence.treelet_orders import TreeletQueues
    from reference_treelets import random_records, random_tree

    segments, _ = random_segments(n_pixels=3, spp=1, seed=0)
    nodes = random_tree(0)
    records = random_records(segments, len(nodes), 0)
    for order in [*RAY_ORDERS.values(), TreeletQueues(treelet_bytes=24, node_bytes=8)]:
        pieces = order_pieces(segments, np.zeros(0, np.int64), order, tree=nodes, records=records)
        assert pieces.n_pieces == 0 and pieces.aux_records.size == 0 and pieces.sort_cycles == 0.0
