"""Ray orders composed with mappings (coherence.ordered_runs): pseudo-pixels of record pieces replayed by the
schedule simulation."""
import numpy as np
import pytest

from analyses.experiment import Experiment
from coherence.mappings import DynamicBlock, get_mapping
from coherence.ordered_runs import OrderedUnit, depth_first, ordered_work, pieces_unit, simulate_ordered, unit_pixels
from coherence.simulation import simulate_run
from coherence.studies import place_layout
from tracer.kd.tree import build_kdtree
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.catalog import load
from tracer.trace.access import COUNTER_NAMES
from tracer.trace.records import AUXILIARY_KIND, AuxKind, pack_aux
from tracer.trace.segments import SegmentColumn


@pytest.fixture(scope="module")
def setup():
    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=8, workload="pathtrace", spp=2)).trace
    experiment = Experiment(scene="balls", size=8)
    return (trace, experiment.hierarchy_object(), place_layout(experiment.layout_object(), trace, scene),
            experiment.cost_model(), experiment.machine())


@pytest.mark.parametrize("mapping", ["S", "P", "B", "DB"])
def test_depth_first_replays_the_mapping_itself(setup, mapping):
    """The depth-first order (each unit's segments as traced) gives the same processes, cycle for cycle, as
    simulating the mapping on the trace: pieces of one pixel merge back into the pixel. Fails if consecutive
    pieces are no longer merged (``joins[1:] = False``) or a dynamic mapping's units become processes
    (checked)."""
    trace, hierarchy, placed, cost, machine = setup
    chosen = DynamicBlock(block=2, dispatch_cycles=300.0) if mapping == "DB" else get_mapping(mapping)
    distribution = chosen.build(trace.width, trace.height, 3)
    expected = simulate_run(trace, distribution, hierarchy, placed, cost, machine)
    run, work = simulate_ordered(trace, distribution, depth_first, hierarchy, placed, cost, machine,
                                 name="depth-first")
    assert work.trace.width == trace.width * trace.height and work.n_aux == 0
    assert run.processes.equals(expected.processes)
    assert run.real_cycles == expected.real_cycles


def _reversed(segments, rows, n_records):
    ints = segments.ints[rows[::-1]]
    return OrderedUnit(ints[:, SegmentColumn.FIRST], ints[:, SegmentColumn.STOP], np.zeros(0, np.uint32), 0.0)


def test_pieces_of_a_reordered_unit_by_hand():
    """On a hand-built 2x1 trace (pixel 0: segments [0, 3) [3, 5); pixel 1: [5, 6)), one process, an order that
    replays pixel 1, then segment [3, 5), an auxiliary record, then [0, 3), with 7 sorting cycles: the pieces
    are numbered by where their records lie ([0, 3) [3, 5) [5, 6) then the aux record at 6), the task replays
    them as 2, 1, 3, 0, compute is shared by record counts (pixel 0's 10 cycles as 6 and 4) plus the sorting
    cycles on the first piece, as are the unit's counters (both pixels' summed). Fails if the
    auxiliary records are not placed after the trace's (``aux_base = n_records`` dropped) (checked)."""
    from types import SimpleNamespace

    ints = np.array([[0, 0, 0, 0, 0, 3], [0, 0, 1, 1, 3, 5], [1, 0, 0, 0, 5, 6]], np.int64)
    trace = SimpleNamespace(segments=SimpleNamespace(ints=ints), width=2, height=1, n_records=6,
                            pixel_offsets=np.array([0, 5, 6]), records=np.arange(6, dtype=np.uint32),
                            counters=np.array([[1, 2], [3, 4]], np.int64))
    aux = pack_aux(AuxKind.RAY_STATE, 0)

    def order(segments, rows, n_records):
        assert rows.tolist() == [0, 1, 2]
        return OrderedUnit(np.array([5, 3, 6, 0]), np.array([6, 5, 7, 3]), np.array([aux], np.uint32), 7.0)

    distribution = get_mapping("S").build(2, 1, 1)
    work = ordered_work(trace, distribution, order, np.array([10.0, 2.0]))
    assert work.trace.pixel_offsets.tolist() == [0, 3, 5, 6, 7]
    assert work.trace.records.tolist() == [0, 1, 2, 3, 4, 5, int(aux)]
    assert work.distribution.task_pixels.tolist() == [2, 1, 3, 0]
    assert work.distribution.task_process.tolist() == [0]
    assert work.compute.tolist() == [6.0, 4.0, 2.0 + 7.0, 0.0]
    assert work.trace.counters.tolist() == [[0, 0], [0, 0], [1 + 3, 2 + 4], [0, 0]]  # the unit's, on its first piece
    assert (work.n_aux, work.sort_cycles) == (1, 7.0)


def test_reordering_keeps_the_work_and_moves_the_misses(setup):
    """Reversing each process's rays keeps every process's counters, compute cycles and first-level accesses
    (each record is read once either way) and changes the misses. Fails if a unit's reversed pieces were
    replayed in record order (``task_pixels`` given ``np.sort(piece_id)``) (checked)."""
    trace, hierarchy, placed, cost, machine = setup
    distribution = get_mapping("P").build(trace.width, trace.height, 2)
    forward, _ = simulate_ordered(trace, distribution, depth_first, hierarchy, placed, cost, machine)
    backward, work = simulate_ordered(trace, distribution, _reversed, hierarchy, placed, cost, machine,
                                      name="reversed")
    assert work.trace.width == trace.segments.n_segments
    first = hierarchy.levels[0].name
    for column in [*COUNTER_NAMES, f"{first}_accesses"]:
        assert backward.processes[column].tolist() == forward.processes[column].tolist(), column
    np.testing.assert_allclose(backward.processes["compute_cycles"], forward.processes["compute_cycles"], rtol=1e-12)
    assert backward.processes[f"{first}_misses"].tolist() != forward.processes[f"{first}_misses"].tolist()


def test_units_are_processes_or_handed_out_tasks():
    """Static mappings order each process's pixels together, dynamic ones each task. Fails if static units were
    tasks (P at 2 processes has 64 one-pixel tasks, not 2 units) (checked)."""
    static = get_mapping("P").build(8, 8, 2)
    assert [len(u) for u in unit_pixels(static)] == [32, 32]
    dynamic = DynamicBlock(block=2).build(8, 8, 2)
    assert len(unit_pixels(dynamic)) == dynamic.n_tasks > 2


def test_an_order_that_drops_a_ray_is_refused(setup):
    """An order whose pieces miss a record is refused naming the order. Fails if both the count check of
    ``_checked_unit`` and the tiling check of ``ordered_work`` go (``if False:``; checked)."""
    trace, *_ = setup
    distribution = get_mapping("S").build(trace.width, trace.height, 2)

    def dropping(segments, rows, n_records):
        unit = depth_first(segments, rows, n_records)
        return unit._replace(starts=unit.starts[1:], stops=unit.stops[1:])

    with pytest.raises(ValueError, match="ray order 'dropping'"):
        ordered_work(trace, distribution, dropping, np.zeros(trace.width * trace.height), "dropping")


def test_pieces_unit_puts_each_aux_record_before_its_piece():
    """An OrderedPieces with pieces [0, 3) [5, 9) and aux records a, b, c after 0, 1 and 2 pieces replays
    a, [0, 3), b, [5, 9), c (aux positions from n_records = 10). Fails if aux records went after their piece
    (``2 * aux_after + 2``) (checked)."""
    from types import SimpleNamespace

    aux = pack_aux(AuxKind.QUEUE_ENTRY, np.array([0, 1, 2]))
    pieces = SimpleNamespace(piece_first=np.array([0, 5]), piece_stop=np.array([3, 9]), aux_records=aux,
                             aux_after=np.array([0, 1, 2]), sort_cycles=4.0)
    unit = pieces_unit(pieces, 10)
    assert unit.starts.tolist() == [10, 0, 11, 5, 12]
    assert unit.stops.tolist() == [11, 3, 12, 9, 13]
    assert unit.aux.tolist() == aux.tolist() and unit.sort_cycles == 4.0


def _with_state_reads(segments, rows, n_records):
    """Depth-first, each ray preceded by a read of its process's ray-state slot 0."""
    ints = segments.ints[rows]
    n = len(rows)
    starts = np.empty(2 * n, np.int64)
    stops = np.empty(2 * n, np.int64)
    starts[0::2], stops[0::2] = n_records + np.arange(n), n_records + np.arange(n) + 1
    starts[1::2], stops[1::2] = ints[:, SegmentColumn.FIRST], ints[:, SegmentColumn.STOP]
    return OrderedUnit(starts, stops, pack_aux(AuxKind.RAY_STATE, np.zeros(n, np.int64)), 0.0)


def test_buffer_records_are_placed_and_read(setup):
    """An order that reads one ray-state line (8 bytes) before every ray: its records become auxiliary-kind rows at the
    extents' addresses, one per process (static P at 2: two rows, at 2**50 and 2**50 + 2**40), and each
    process's first-level accesses grow by exactly its rays. Fails if every process's aux records took
    process 0's extents (``0 if distribution.dynamic else unit`` made 0: one row) (checked)."""
    from coherence.ordered_runs import with_order_buffers

    trace, hierarchy, placed, cost, machine = setup

    def extents(records, process):
        return np.full(len(records), (1 << 50) + process * (1 << 40), np.int64), np.full(len(records), 8, np.int64)

    distribution = get_mapping("P").build(trace.width, trace.height, 2)
    plain, _ = simulate_ordered(trace, distribution, depth_first, hierarchy, placed, cost, machine)
    run, work = simulate_ordered(trace, distribution, _with_state_reads, hierarchy, placed, cost, machine,
                                 name="state reads", extents=extents)
    buffered, pieces = with_order_buffers(placed, work, trace.n_records, extents)
    rows = slice(buffered.kind_first[AUXILIARY_KIND], buffered.kind_first[AUXILIARY_KIND + 1])
    assert buffered.record_start[rows].tolist() == [1 << 50, (1 << 50) + (1 << 40)]
    assert np.all(pieces.records[trace.n_records:] >> 28 == AUXILIARY_KIND)
    first = hierarchy.levels[0].name
    per_process_rays = [int(np.isin(trace.segments.ints[:, SegmentColumn.PIXEL], pixels).sum())
                        for pixels in unit_pixels(distribution)]
    assert (run.processes[f"{first}_accesses"] - plain.processes[f"{first}_accesses"]).tolist() == per_process_rays


@pytest.fixture(scope="module")
def platform_setup(setup):
    """The 8x8 trace on apple-m1's shared levels (4 cores, a shared L2), no background load."""

    trace, _, placed, _, _ = setup
    experiment = Experiment(scene="balls", size=8, workload="pathtrace", platform="apple-m1", background=0)
    return trace, experiment.study_hierarchy(), placed, experiment.cost_model(), experiment.machine()


@pytest.mark.parametrize("mapping", ["S", "P", "DB"])
def test_depth_first_on_shared_levels_is_the_platform_run(platform_setup, mapping):
    """On a platform's shared levels, the depth-first order gives the processes and real time of
    ``simulate_shared_run`` of the mapping itself, cycle for cycle, as a platform report's runs are made. Fails
    if the pieces' compute cycles were not given to the run (``compute=work.compute`` dropped: the run then
    costs each piece from its counters, which sit on a unit's first piece) (checked)."""
    from coherence.ordered_runs import simulate_ordered_shared
    from coherence.shared_run import simulate_shared_run

    trace, shared, placed, cost, machine = platform_setup
    chosen = DynamicBlock(block=2, dispatch_cycles=300.0) if mapping == "DB" else get_mapping(mapping)
    distribution = chosen.build(trace.width, trace.height, 3)
    expected = simulate_shared_run(trace, distribution, shared.machine, placed, cost, machine,
                                   interleave_cycles=shared.interleave_cycles)
    run, work = simulate_ordered_shared(trace, distribution, depth_first, shared, placed, cost, machine,
                                        name="depth-first")
    assert work.n_aux == 0
    assert run.run.processes.equals(expected.run.processes)
    assert run.run.real_cycles == expected.run.real_cycles
    np.testing.assert_array_equal(run.shared.counts, expected.shared.counts)


def _with_state_writes(segments, rows, n_records):
    """Depth-first, each ray preceded by a write of its process's ray-state slot 0."""
    unit = _with_state_reads(segments, rows, n_records)
    return unit._replace(aux=pack_aux(AuxKind.RAY_STATE, np.zeros(len(rows), np.int64), True))


def test_buffers_on_shared_levels_are_each_process_own(platform_setup):
    """Under DB on shared levels, every handed-out block's rays write the ray-state slots of the process that
    took it: the slot rows lie one spacing below process 0's buffers, marked private with the spacing between
    copies, and no buffer line moves between cores (no coherence invalidation or miss of the auxiliary kind
    beyond the task counter's, at most one per hand-out) while each process writes its rays' states. Fails if the buffer accesses were not private (``private =
    pieces.private``: every process then shares one buffer) (checked, also with the flag assertion left out:
    the kind's coherence misses)."""
    from cachesim.multicore_state import ACCESSES, COHERENCE_INVALIDATIONS, COHERENCE_MISSES
    from coherence.ordered_runs import shared_order_pieces, simulate_ordered_shared
    from coherence.ray_order_base import OrderBuffers

    trace, shared, placed, cost, machine = platform_setup
    distribution = DynamicBlock(block=2, dispatch_cycles=300.0).build(trace.width, trace.height, 4)
    run, work = simulate_ordered_shared(trace, distribution, _with_state_writes, shared, placed, cost, machine,
                                        name="state writes")
    buffers = OrderBuffers()
    buffered, pieces = shared_order_pieces(work, placed, trace.n_records, shared.hierarchy.levels[0].line_size)
    rows = slice(buffered.kind_first[AUXILIARY_KIND], buffered.kind_first[AUXILIARY_KIND + 1])
    assert buffered.record_start[rows].tolist() == [buffers.base - buffers.spacing]  # slot 0, one row for all
    aux = pieces.pieces.kinds == AUXILIARY_KIND
    assert aux.sum() == trace.segments.n_segments and pieces.pieces.private[aux].all()
    assert pieces.pieces.private_span == buffers.spacing
    counts = run.shared.counts[:, :, AUXILIARY_KIND]
    # the auxiliary kind also holds the task counter's writes, one per hand-out (coherence.shared_schedule)
    assert counts[0, :, ACCESSES].sum() == trace.segments.n_segments + distribution.n_tasks
    # every counter access is a write, so one cache holds its line at a time: a hand-out invalidates one copy
    # at most; all else of the kind is the buffers', which must move no line between cores
    assert counts[..., COHERENCE_INVALIDATIONS].sum() <= distribution.n_tasks
    assert counts[..., COHERENCE_MISSES].sum() <= distribution.n_tasks
    assert (run.run.processes["tasks"] > 0).sum() > 1  # the blocks went to several processes


def test_shared_buffers_below_their_spacing_are_refused(platform_setup):
    """On shared levels process 0's buffer rows lie one spacing below its buffers, so buffers based below
    their spacing are refused by name, not wrapped round to a huge address. Fails without the check (checked:
    the run then goes through on wrapped addresses)."""
    from coherence.ordered_runs import simulate_ordered_shared
    from coherence.ray_order_base import OrderBuffers
    from rtcommon.validate import InputError

    trace, shared, placed, cost, machine = platform_setup
    distribution = get_mapping("P").build(trace.width, trace.height, 2)
    with pytest.raises(InputError, match="OrderBuffers.base .* at least its spacing"):
        simulate_ordered_shared(trace, distribution, _with_state_writes, shared, placed, cost, machine,
                                buffers=OrderBuffers(base=4096))
