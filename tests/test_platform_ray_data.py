"""Runs under a platform: the trace logs per-ray data and frame-buffer writes, a layout takes a frame-buffer
pixel size, and a platform's machine shows P's false sharing on 3-byte pixels."""
from dataclasses import replace

import numpy as np
import pytest

from analyses.experiment import Experiment
from analyses.traces import cached_trace, trace_key, with_ray_data
from coherence.layout import FRAME_BUFFER_BYTES, get_layout
from coherence.platforms import get_platform
from coherence.studies import place_layout
from coherence.thread_streams import PRIVATE_KINDS
from tracer.rendering.workload import WORKLOADS
from tracer.trace.records import INDEX_MASK, KIND_SHIFT, RecordKind

from test_thread_streams import false_sharing_misses


def test_ray_data_changes_the_trace_key_only_where_it_adds_records():
    """``ray_data`` gives the modern workload another key labelled ``-raydata``; False, and the study1997
    workload (which logs it already), keep the key as it was.
    Mutation: hash ``preset.to_dict()`` instead of ``logged.to_dict()`` in trace_key (label only differs)."""
    plain = trace_key("tetra", 8, max_depth=3)
    assert trace_key("tetra", 8, max_depth=3, ray_data=False) == plain
    logged = trace_key("tetra", 8, max_depth=3, ray_data=True)
    assert logged != plain and logged.startswith("tetra-8-raydata-sah-d3-")
    assert logged.rsplit("-", 1)[1] != plain.rsplit("-", 1)[1]
    study = dict(max_depth=3, workload="study1997", kd="median")
    assert trace_key("tetra", 8, **study, ray_data=True) == trace_key("tetra", 8, **study)
    assert with_ray_data(WORKLOADS["pathtrace"], True) is WORKLOADS["pathtrace"]
    with pytest.raises(ValueError, match="ray_data must be True or False"):
        with_ray_data(WORKLOADS["modern"], 1)


def test_an_experiment_under_a_platform_logs_ray_data():
    """Mutation: ``return self.workload`` in Experiment.trace_workload."""
    assert not Experiment().logs_ray_data()
    assert Experiment(workload="study1997").logs_ray_data()
    assert Experiment(platform="apple-m1").logs_ray_data()
    assert not Experiment(platform="apple-m1", workload="pathtrace").logs_ray_data()
    assert Experiment(platform="apple-m1", workload="study1997").trace_workload() == "study1997"
    with pytest.raises(ValueError, match="or such a preset logging its ray data"):
        cached_trace("tetra", 8, workload=replace(WORKLOADS["modern"], shadow_nearest=True))


def test_frame_buffer_pixels_lie_packed_at_their_size():
    """Each size's pixels lie ``size`` bytes apart (3-byte pixels unaligned) and nothing else moves
    before the frame buffer's region. Mutation: ``RecordLayout(pixel_bytes, 4)`` in with_frame_buffer."""
    counts = {RecordKind.SPHERE: 5, RecordKind.FRAME_BUFFER: 10}
    base = get_layout("compact").place(counts)
    for size in FRAME_BUFFER_BYTES:
        placed = get_layout("compact").with_frame_buffer(size).place(counts)
        first = placed.kind_first[RecordKind.FRAME_BUFFER]
        starts = placed.record_start[first:first + 10]
        assert np.diff(starts).tolist() == [size] * 9
        assert placed.record_size[first:first + 10].tolist() == [size] * 10
        assert np.array_equal(placed.record_start[:first], base.record_start[:first])


@pytest.mark.parametrize("bad", [0, 5, 12, True, "3"])
def test_bad_frame_buffer_sizes_are_refused_by_name(bad):
    """Mutation: drop the FRAME_BUFFER_BYTES check in Experiment.__post_init__ (12 passes)."""
    with pytest.raises(ValueError, match="Experiment.frame_buffer_bytes must be None or one of 3, 4, 16"):
        Experiment(frame_buffer_bytes=bad)
    with pytest.raises(ValueError, match="frame-buffer pixel size must be one of 3, 4, 16"):
        get_layout("compact").with_frame_buffer(bad)


def test_frame_buffer_bytes_reach_the_layout_and_the_parameters():
    """Mutation: ``return _layout(self.layout)`` in Experiment.layout_object."""
    default = Experiment()
    assert "frame_buffer_bytes" not in default.as_parameters()
    assert default.layout_object().record("frame_buffer").size == 12
    three = replace(default, frame_buffer_bytes=3)
    assert three.layout_object().record("frame_buffer").size == 3
    assert three.as_parameters()["frame_buffer_bytes"] == 3


@pytest.fixture(scope="module")
def balls_with_ray_data(tmp_path_factory):
    """Balls at 16x16 by the modern workload, logging its ray data as a platform run does."""
    cache = tmp_path_factory.mktemp("cache")
    return cached_trace("balls", 16, cache_dir=cache, progress=False,
                        workload=Experiment(platform="zen4-7950x").trace_workload())


def test_a_platform_run_logs_every_pixel_s_frame_buffer_write(balls_with_ray_data):
    """Every pixel writes its own frame-buffer record once, and the per-ray kinds are logged.
    Mutation: ``return workload`` first in with_ray_data (no ray data)."""
    _, trace, info = balls_with_ray_data
    records = np.asarray(trace.records)
    kinds = records >> KIND_SHIFT
    frame = records[kinds == RecordKind.FRAME_BUFFER] & INDEX_MASK
    assert sorted(frame.tolist()) == list(range(16 * 16))
    assert all((kinds == kind).any() for kind in PRIVATE_KINDS)
    assert "-raydata-" in info["key"]


def test_p_shares_3_byte_pixels_falsely_more_than_s_on_a_platform(balls_with_ray_data):
    """8 threads of the zen4-7950x's machine (its L1 and L2 per core, L3 per complex), balls with ray data,
    3-byte pixels: P's false-sharing misses are > 0 and more than S's.
    Mutation: ``RecordLayout(pixel_bytes, 64)`` in with_frame_buffer (a line per pixel: no false sharing)."""
    scene, trace, _ = balls_with_ray_data
    placed = place_layout(get_layout("compact").with_frame_buffer(3), trace, scene)
    machine = get_platform("zen4-7950x").hierarchy
    false_sharing = {mapping: false_sharing_misses(trace, placed, machine, mapping, 8) for mapping in ("P", "S")}
    assert false_sharing["P"] > 0 and false_sharing["P"] > false_sharing["S"]
