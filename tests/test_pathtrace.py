"""The path tracer: radiance against a plain-Python reference, a furnace, Whitted's first hits, segments and
reproducible traces."""
import json
import math

import numpy as np
import pytest

import tracer.rendering.pathtrace as pathtrace_module
import tracer.rendering.render as render_module
from reference_pathtrace import SphereScene, key_of, rand, radiance, JITTER_X, JITTER_Y
from tracer.kd.tree import build_kdtree
from tracer.rendering.camera import camera_frame
from tracer.rendering.pathtrace import path_trace
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import load
from tracer.scenes.model import Camera, Material, SceneBuilder
from tracer.trace.access import AccessTrace, RecordKind, TraceIntegrityError
from tracer.trace.segments import SegmentColumn, SegmentRayColumn, SegmentRayType

# (centre, radius, material): a diffuse floor, a diffuse ball, a mirror and a glass ball
_SPHERES = [((0.0, -101.0, 0.0), 100.0, Material((0.8, 0.7, 0.6), 0.9, 0.0, 1.0, 0.0, 1.0)),
            ((-1.2, 0.0, 0.0), 1.0, Material((0.2, 0.9, 0.3), 0.7, 0.2, 10.0, 0.0, 1.0)),
            ((1.2, 0.0, 0.5), 0.9, Material((1.0, 1.0, 1.0), 0.0, 0.9, 10.0, 0.0, 1.0)),
            ((0.0, 0.3, 2.0), 0.6, Material((1.0, 1.0, 1.0), 0.1, 0.1, 10.0, 0.8, 1.5))]
_LIGHTS = [((4.0, 6.0, 5.0), (1.0, 1.0, 1.0)), ((-5.0, 3.0, 4.0), (0.6, 0.5, 0.4))]
_BACKGROUND = (0.2, 0.3, 0.5)


def _tiny_scene():
    b = SceneBuilder("pt-tiny")
    b.camera = Camera(eye=(0.0, 1.0, 7.0), look_at=(0.0, 0.0, 0.0), up=(0, 1, 0), angle=45.0, hither=1e-3,
                      resolution=(6, 6))
    b.background = _BACKGROUND
    b.max_depth = 6
    for centre, radius, material in _SPHERES:
        b.material(material)
        b.sphere(centre, radius)
    for position, colour in _LIGHTS:
        b.light(position, colour)
    return b.build()


def test_radiance_per_sample_equals_plain_python_reference():
    """Every sample's radiance equals the plain-Python path tracer's with the same counter-based numbers
    (diffuse, mirror and glass spheres, two lights, a background; up to 6 rays a path, so roulette cuts).
    Fails if ``ROULETTE_BOUNCE`` in tracer.rendering.pathtrace_kernels becomes 4 (checked)."""
    scene = _tiny_scene()
    spp, seed = 3, 11
    result = path_trace(scene, options=RenderOptions(workload="pathtrace", spp=spp, seed=seed, log=False))
    eps = result.epsilon
    materials = [(m.color, m.kd, m.ks, m.t, m.ior) for _, _, m in _SPHERES]
    reference = SphereScene([(c, r, i) for i, (c, r, _) in enumerate(_SPHERES)], materials, _LIGHTS, _BACKGROUND)
    cam = camera_frame(scene, 6, 6)
    expected = []
    for p in range(36):
        i, j = p % 6, p // 6
        for s in range(spp):
            key = key_of(seed, p, s)
            u = (i + rand(key, 0, JITTER_X) - 0.5 - cam.cx) * cam.pitch
            v = (cam.cy - j - (rand(key, 0, JITTER_Y) - 0.5)) * cam.pitch
            d = [cam.forward[c] + u * cam.right[c] + v * cam.up[c] for c in range(3)]
            length = math.sqrt(sum(x * x for x in d))
            expected.append(radiance(reference, tuple(cam.eye), tuple(x / length for x in d), key,
                                     scene.camera.hither, eps, 6))
    expected = np.array(expected)
    assert (expected > 0).all()
    np.testing.assert_allclose(result.sample_radiance, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.image.reshape(-1, 3), expected.reshape(36, spp, 3).mean(axis=1), rtol=1e-12)


def test_furnace_converges_to_emission_over_one_minus_albedo():
    """Inside a closed, emissive, diffuse sphere of albedo a (no lights), every path's expected radiance is
    Le / (1 - a). The mean over 8 x 8 pixels x 32 samples lies within 5 standard errors (estimated from the
    samples) of it, plus the bias of stopping at 64 rays (a**64 Le / (1 - a)). Fails if Russian roulette
    forgets to divide the throughput by its probability (``tr_ /= q`` and the two like it dropped) (checked)."""
    albedo, le = 0.6, 0.25
    b = SceneBuilder("furnace")
    b.camera = Camera(eye=(0.1, 0.2, 0.0), look_at=(1.0, 0.3, 0.2), up=(0, 0, 1), angle=60.0, hither=1e-4,
                      resolution=(8, 8))
    b.max_depth = 64
    b.material(Material((1.0, 1.0, 1.0), albedo, 0.0, 1.0, 0.0, 1.0))
    b.sphere((0.0, 0.0, 0.0), 3.0)
    scene = b.build()
    result = path_trace(scene, options=RenderOptions(workload="pathtrace", spp=32, seed=5, log=False),
                        emission=[[le, le, le]])
    samples = result.sample_radiance[:, 0]
    expected = le / (1.0 - albedo)
    bound = 5.0 * samples.std() / math.sqrt(samples.size) + albedo ** 64 * expected
    assert abs(samples.mean() - expected) < bound
    assert samples.std() > 0  # the estimate is random: roulette and bounce counts differ
    assert np.array_equal(result.sample_radiance[:, 0], result.sample_radiance[:, 2])


def test_first_hits_equal_whitted_tracer():
    """With one ray a path (0 bounces), pixel-centre camera rays and one sample, each camera ray reads the same
    records as today's Whitted tracer's primary ray up to and including its material, and hits exactly
    where Whitted's primary rays hit. Fails if the path tracer's camera rows run upward
    (``v = (cam.cy - j - jv)`` made ``(j - cam.cy - jv)``) (checked)."""
    scene = load("tetra")
    options = dict(size=12, max_depth=1)
    whitted = render(scene, options=RenderOptions(**options)).trace
    traced = render(scene, options=RenderOptions(**options, workload="pathtrace", jitter=False)).trace
    ints, rays = traced.segments
    camera = np.flatnonzero(ints[:, SegmentColumn.RAY_TYPE] == SegmentRayType.CAMERA)
    assert len(camera) == 144
    n_lights = scene.n_lights
    hit = ~np.isnan(rays[camera, SegmentRayColumn.HIT])
    np.testing.assert_array_equal(hit, whitted.counter("primary_hits").reshape(-1) == 1)
    for p, s in enumerate(camera):
        first, stop = ints[s, SegmentColumn.FIRST], ints[s, SegmentColumn.STOP]
        mine = traced.records[first:stop - n_lights * hit[p]]
        theirs = whitted.pixel(p)[:len(mine)]
        np.testing.assert_array_equal(mine, theirs)
        assert (mine[-1] >> 28 == RecordKind.MATERIAL) == hit[p]


def test_segments_describe_their_rays():
    """Segments tile each pixel's records in trace order: a camera ray first per sample, shadow rays start at
    the hit point of the ray before them with a unit direction, bounces start where the previous hit,
    and each sample's bounces count up from 0. Fails if a shadow ray's segment closes before its traversal
    (``first = pos`` moved below the traverse call) (checked)."""
    scene = _tiny_scene()
    trace = path_trace(scene, options=RenderOptions(workload="pathtrace", spp=2, seed=3)).trace
    ints, rays = trace.segments
    kinds = trace.records >> 28
    last_hit = None
    for s in range(len(ints)):
        pixel, sample, bounce, typ, first, stop = ints[s]
        assert trace.pixel_offsets[pixel] <= first <= stop <= trace.pixel_offsets[pixel + 1]
        assert abs(np.linalg.norm(rays[s, 3:6]) - 1.0) < 1e-12
        if typ == SegmentRayType.SHADOW:
            np.testing.assert_array_equal(rays[s, :3], last_hit)
            assert stop > first and kinds[first] == RecordKind.KD_NODE
            assert not np.isin(kinds[first:stop], [RecordKind.MATERIAL, RecordKind.LIGHT]).any()
        else:
            if typ == SegmentRayType.CAMERA:
                assert bounce == 0
            else:
                assert bounce >= 1
                np.testing.assert_array_equal(rays[s, :3], last_hit)
            last_hit = rays[s, 6:9]
    assert set(ints[:, SegmentColumn.RAY_TYPE]) == {0, 1, 2}


def test_same_seed_gives_byte_identical_traces(tmp_path, monkeypatch):
    """Two renders with one seed write identical files, also when every work item overflows its slots and
    is traced again; another seed gives other records. The saved trace is format version 4 and loads with
    its segments. Fails if an overflowing item's records are not replaced by its second trace
    (``pieces[j] = exact_records[...]`` dropped) (checked)."""
    scene = load("balls")
    tree = build_kdtree(scene)  # one tree: its build time is in the metadata
    options = RenderOptions(size=8, workload="pathtrace", spp=2, seed=7)
    path_trace(scene, tree, options=options, trace_path=tmp_path / "a")
    monkeypatch.setattr(pathtrace_module, "SLOT_BUFFER_BYTES", 1024)
    path_trace(scene, tree, options=options, trace_path=tmp_path / "b")
    other = path_trace(scene, options=RenderOptions(size=8, workload="pathtrace", spp=2, seed=8)).trace
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert "segment_ints.npy" in names and "segment_rays.npy" in names
    for name in names:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    back = AccessTrace.load(tmp_path / "a")
    assert json.loads((tmp_path / "a" / "meta.json").read_text())["format_version"] == 4
    assert back.segments.n_segments > 64 and np.isnan(back.segments.rays).any()
    assert not np.array_equal(other.records, back.records)
    # a damaged segment file is refused by its checksum
    raw = bytearray((tmp_path / "a" / "segment_rays.npy").read_bytes())
    raw[-3] ^= 1
    (tmp_path / "a" / "segment_rays.npy").write_bytes(bytes(raw))
    with pytest.raises(TraceIntegrityError, match="segment_rays.npy does not match"):
        AccessTrace.load(tmp_path / "a")


def test_trace_is_the_same_however_its_buffers_grow(monkeypatch):
    """Slots that start at one record and one segment per sample (every item of the first batch overflows,
    later slots grow), batches of two items, and record and segment arrays grown to just what each batch
    needs give the same records and segments as the defaults. Fails if a grown segment array drops the
    rows already stored (``self.ints[:row] = ints[:row]`` removed) (checked)."""
    scene = load("balls")
    tree = build_kdtree(scene)
    options = RenderOptions(size=12, workload="pathtrace", spp=2)
    expected = path_trace(scene, tree, options=options).trace
    monkeypatch.setattr(pathtrace_module, "FIRST_SLOT_RECORDS", 1)
    monkeypatch.setattr(pathtrace_module, "FIRST_SLOT_SEGMENTS", 1)
    monkeypatch.setattr(pathtrace_module, "BATCH_ITEMS", 2)
    monkeypatch.setattr(render_module._GrowingRecords, "initial_capacity", 5)
    monkeypatch.setattr(pathtrace_module._Collected, "_expected", lambda self, need, capacity, pixels_done: need)
    grown = path_trace(scene, tree, options=options).trace
    np.testing.assert_array_equal(grown.pixel_offsets, expected.pixel_offsets)
    np.testing.assert_array_equal(grown.records, expected.records)
    np.testing.assert_array_equal(grown.segments.ints, expected.segments.ints)
    np.testing.assert_array_equal(grown.segments.rays, expected.segments.rays)


def test_bad_options_are_refused():
    """Clear errors for the path tracer's options. Fails if RenderOptions stops checking ``spp``."""
    with pytest.raises(ValueError, match="RenderOptions.spp"):
        RenderOptions(workload="pathtrace", spp=0)
    with pytest.raises(ValueError, match="RenderOptions.spp must be 1 for the 'modern'"):
        RenderOptions(spp=4)
    with pytest.raises(ValueError, match="RenderOptions.seed"):
        RenderOptions(workload="pathtrace", seed=-1)
    with pytest.raises(ValueError, match="emission must be a"):
        path_trace(_tiny_scene(), options=RenderOptions(workload="pathtrace", log=False), emission=[[1, 1, 1]])
    with pytest.raises(ValueError, match="corner_rays"):
        path_trace(_tiny_scene(), options=RenderOptions(workload="pathtrace", corner_rays=True))
