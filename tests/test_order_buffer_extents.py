"""A ray order's buffer accesses stay in the buffers of the process that makes them.

Every process has its own ray buffer and queues (``OrderBuffers.extents(.., p)``);
the schedule simulation places the orders' auxiliary records there
(``coherence.ordered_runs.with_order_buffers`` on private caches,
``shared_order_pieces`` on a platform's shared levels, where the run moves a
private access by ``(p + 1)`` spacings). These tests follow each auxiliary
record a process replays to the lines the simulation reads for it, on the
registered orders that add records.
"""
from __future__ import annotations

import numpy as np
import pytest

from analyses.experiment import Experiment
from analyses.report_orders import registry_orders
from coherence.mappings import DynamicBlock, get_mapping
from coherence.ordered_runs import ordered_work, shared_order_pieces, with_order_buffers
from coherence.ray_order_base import OrderBuffers
from coherence.ray_orders import scene_bounds_of
from coherence.studies import place_layout
from tracer.kd.tree import build_kdtree
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions
from tracer.scenes.catalog import load
from tracer.trace.records import AUXILIARY_KIND, KIND_SHIFT

N_PROCESSES = 3


@pytest.fixture(scope="module")
def setup():
    """balls at 8x8, 2 samples a pixel, its kd-tree and the compact layout placed for it."""
    scene = load("balls")
    tree = build_kdtree(scene)
    trace = path_trace(scene, tree, RenderOptions(size=8, workload="pathtrace", spp=2)).trace
    experiment = Experiment(scene="balls", size=8)
    return trace, tree, place_layout(experiment.layout_object(), trace, scene)


def _order(setup, name):
    trace, tree, _ = setup
    return registry_orders(name, scene_bounds=scene_bounds_of(trace.segments), tree=tree, records=trace.records)[0]


def _lines(starts, sizes, line_size: int) -> set:
    """Every ``line_size`` line address that the byte ranges ``starts[i] .. starts[i] + sizes[i] - 1`` touch."""
    lines = set()
    for start, size in zip(np.asarray(starts).tolist(), np.asarray(sizes).tolist()):
        lines.update(range(start // line_size * line_size, start + size, line_size))
    return lines


@pytest.mark.parametrize("name", ["wavefront", "treelet"])
def test_each_process_buffer_lines_lie_in_its_own_extents(setup, name):
    """Private caches, P at 3 processes: the line addresses the simulation reads for every auxiliary record a
    process replays (the records of the pseudo-pixels the distribution gives it, placed by
    ``with_order_buffers`` with ``OrderBuffers().extents``) are exactly the lines of that record's
    ``extents(record, p)``, inside ``p``'s span of ``spacing`` bytes; and no line of one process's
    extents is another's.

    Mutations that fail it (checked): in ``coherence.ordered_runs.ordered_work``, give every static unit's
    records process 0's buffers (``aux_owner = np.zeros(n_units, np.int64)``); or drop ``process *
    self.spacing`` from ``OrderBuffers.extents`` (every process's extents then overlap process 0's).
    """
    trace, _, placed = setup
    n_records = int(trace.n_records)
    buffers = OrderBuffers()
    line_size = 32
    distribution = get_mapping("P").build(trace.width, trace.height, N_PROCESSES)
    work = ordered_work(trace, distribution, _order(setup, name), np.ones(trace.width * trace.height), name=name)
    assert work.n_aux > 0
    buffered, pieces = with_order_buffers(placed, work, n_records, buffers.extents)
    offsets = np.asarray(pieces.pixel_offsets)
    extent_lines = []
    for process in range(N_PROCESSES):
        replayed = np.concatenate([np.arange(offsets[pixel], offsets[pixel + 1])
                                   for pixel in work.distribution.process_pixels(process)])
        positions = replayed[replayed >= n_records]  # the aux records follow the trace's
        assert positions.size, f"process {process} replays no buffer record"
        original = np.asarray(work.trace.records)[positions]
        starts, sizes = buffers.extents(original, process)
        low = buffers.base + process * buffers.spacing
        assert starts.min() >= low and (starts + sizes).max() <= low + buffers.spacing
        for position, start, size in zip(positions.tolist(), starts.tolist(), sizes.tolist()):
            read = buffered.addresses(pieces.records[position:position + 1], line_size)
            assert set(read.tolist()) == _lines([start], [size], line_size), (process, position)
        extent_lines.append(_lines(starts, sizes, line_size))
    for process in range(N_PROCESSES):
        for other in range(process + 1, N_PROCESSES):
            assert not extent_lines[process] & extent_lines[other], (process, other)


def test_shared_levels_move_each_process_buffers_to_its_extents(setup):
    """A platform's shared levels, DB at 3 processes, the wavefront order: every buffer access is private, and
    moved as the run moves process ``p``'s private accesses (``+ (p + 1) * private_span``) its lines are
    exactly those of ``OrderBuffers().extents(aux records, p)``, whichever process takes the block; the
    processes' line sets do not overlap.

    Mutation that fails it (checked): in ``shared_order_pieces``, place the rows at process 0's extents
    (``return start, size`` instead of ``start - buffers.spacing``).
    """
    trace, _, placed = setup
    n_records = int(trace.n_records)
    buffers = OrderBuffers()
    line_size = Experiment(scene="balls", size=8, workload="pathtrace", platform="apple-m1",
                           background=0).study_hierarchy().hierarchy.levels[0].line_size
    distribution = DynamicBlock(block=2, dispatch_cycles=300.0).build(trace.width, trace.height, N_PROCESSES)
    work = ordered_work(trace, distribution, _order(setup, "wavefront"), np.ones(trace.width * trace.height),
                        name="wavefront")
    _, shared = shared_order_pieces(work, placed, n_records, line_size, buffers, name="wavefront")
    accesses = shared.pieces
    aux = accesses.kinds == AUXILIARY_KIND
    assert aux.any() and accesses.private[aux].all()
    assert not (np.asarray(work.trace.records[:n_records]) >> KIND_SHIFT == AUXILIARY_KIND).any()
    original = np.asarray(work.trace.records)[n_records:]
    lines_of = []
    for process in range(N_PROCESSES):
        moved = accesses.addresses[aux].astype(np.int64) + (process + 1) * accesses.private_span
        starts, sizes = buffers.extents(original, process)
        expected = _lines(starts, sizes, line_size)
        assert _lines(moved, accesses.sizes[aux], line_size) == expected, process
        lines_of.append(expected)
    for process in range(N_PROCESSES):
        for other in range(process + 1, N_PROCESSES):
            assert not lines_of[process] & lines_of[other], (process, other)
