"""Instrumented unidirectional path tracer: the second renderer, beside Whitted's.

:func:`path_trace` (or :func:`tracer.rendering.render.render` with the
``"pathtrace"`` workload) traces ``spp`` paths through every pixel and, with
logging, returns an :class:`~tracer.trace.access.AccessTrace` whose records
are read exactly as the Whitted renderer reads them (kd nodes, index
entries, primitives, materials, lights), with every ray's records closed as
one segment (:mod:`tracer.trace.segments`, format version 4).

Rules
-----
* Camera: the Whitted camera (:mod:`tracer.rendering.camera`); with
  ``jitter`` each sample's ray passes through a uniformly random point of its
  pixel, else through the centre. Camera rays ignore hits closer than
  ``hither``, every other ray hits closer than ``epsilon``.
* Materials: an NFF material is a diffuse lobe of albedo ``Kd * colour``
  (Lambertian), a perfect mirror of weight ``Ks`` and, where ``T > 0``, a
  perfect refraction of weight ``T`` (Snell with the material's index; total
  internal reflection reflects). ``shine`` and the ambient term are not
  used. Surfaces are two-sided: the normal is turned to face the incoming
  ray. NFF weights need not sum to one; nothing renormalises them.
* Next-event estimation: at every hit of a material with ``Kd > 0``, one
  shadow ray to each point light the facing normal sees (``N.L > 0``); an
  unblocked light adds ``throughput * Kd * colour * N.L * light colour``,
  without distance falloff, as Whitted's diffuse term (light colours scaled
  by SPD's ``sqrt(L) / (2 L)``). Point lights cannot be hit by bounces, so
  nothing is counted twice.
* Scattering: a lobe is chosen with probability proportional to its weight
  (``Kd * max(colour)``, ``Ks``, ``T``) and the throughput is multiplied by the
  lobe's weight over that probability; the diffuse lobe's direction is
  cosine-weighted (:func:`tracer.rendering.sampling.cosine_direction`), so
  its throughput factor is the albedo over the probability.
* A ray that hits nothing adds ``throughput * background``. A material may
  emit (``emission``, zero for NFF scenes; a test's furnace uses it): a hit
  adds ``throughput * emission``.
* A path has at most ``max_depth`` rays besides its shadow rays (the camera
  ray is 1, so ``max_depth`` 1 is direct lighting of first hits only). From
  bounce :data:`~tracer.rendering.pathtrace_kernels.ROULETTE_BOUNCE` on,
  Russian roulette keeps a path with probability ``min(max(throughput),
  0.95)`` and divides the throughput by it.
* Random numbers: :mod:`tracer.rendering.sampling`'s counter-based
  generator keyed by (seed, pixel, sample, bounce, dimension), so a path's
  radiance and records do not depend on the order rays are traced in.

Counters: camera rays count as primary rays; diffuse and mirror bounces as
reflection rays; refractions as refraction rays; shadow rays as shadow rays.
Scenes with textures are refused (the path tracer has no ray cones).
"""
from __future__ import annotations

import time

import numba
import numpy as np

from rtcommon.validate import InputError
from tracer.kd.traverse import tree_arrays
from tracer.rendering.camera import camera_frame
from tracer.rendering.geometry import prepare_geometry
from tracer.rendering.pathtrace_kernels import (PIXEL_CHUNK, ROULETTE_BOUNCE, ROULETTE_CAP, PathOutputs, PathParams,
                                                PathWork, path_kernel)
from tracer.rendering.render import (SLOT_BUFFER_BYTES, RenderOptions, RenderResult, _GrowingRecords,
                                     self_intersection_tolerance, trace_metadata)
from tracer.rendering.shading import shading_of
from tracer.scenes.model import Scene
from tracer.trace.access import AccessTrace
from tracer.trace.records import N_COUNTERS
from tracer.trace.segments import N_SEGMENT_COLUMNS, N_SEGMENT_RAY_COLUMNS, RaySegments, SegmentColumn

#: Work items per kernel call when logging.
BATCH_ITEMS = 64
#: Records per segment the segment slots are sized for (an overflowing item is traced again).
RECORDS_PER_SEGMENT = 8


def path_trace(scene: Scene, tree=None, options: RenderOptions | None = None, *, trace_path=None,
               metadata: dict | None = None, emission=None) -> RenderResult:
    """Path-trace ``scene`` (module docstring) and, with ``options.log``, record every access per ray.

    Parameters
    ----------
    scene : Scene
        Without textures.
    tree : KdTree, optional
        Built from ``options.kd_config`` (else the workload's rule) when omitted.
    options : RenderOptions, optional
        Size, logging, tree rule, ``max_depth`` (rays per path), tolerance,
        workload (its tree rule and shadow-ray rule), ``spp``, ``seed``,
        ``jitter``. ``corner_rays`` is refused.
    trace_path : path, optional
        Also save the trace there (atomically; format version 4).
    metadata : dict, optional
        Extra JSON-serialisable entries for the trace's metadata.
    emission : array_like, shape (M, 3), optional
        Radiance emitted by each material (finite, >= 0); default none.

    Returns
    -------
    RenderResult
        With ``sample_radiance``; the trace carries ``segments``.
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a Scene, got {type(scene).__name__}")
    options = RenderOptions() if options is None else options
    if not isinstance(options, RenderOptions):
        raise InputError(f"options must be RenderOptions, got {type(options).__name__}")
    if options.corner_rays:
        raise InputError("RenderOptions.corner_rays: the path tracer samples pixels, not their corners")
    if scene.n_textures:
        raise InputError(f"scene {scene.name!r} has textures; the path tracer renders untextured scenes only")
    width, height = scene.camera.resolution if options.size is None else options.size
    depth = scene.max_depth if options.max_depth is None else options.max_depth
    if isinstance(depth, (bool, np.bool_)) or int(depth) != depth or not 1 <= depth <= 64:
        raise InputError(f"max_depth must be an int in 1..64, got {depth!r} (the scene's {scene.name!r})")
    depth = int(depth)
    workload = options.workload
    n_materials = int(scene.material_kd.size)
    emission = _checked_emission(emission, n_materials)
    timings = {}
    t_start = time.perf_counter()
    tree, tree_arr = tree_arrays(scene, tree, options.kd_config or (workload.kd_config if tree is None else None))
    timings["build"] = time.perf_counter() - t_start
    shading = shading_of(scene)
    geo = prepare_geometry(scene)
    eps = self_intersection_tolerance(tree, options.epsilon)
    hither = float(scene.camera.hither)
    cam = camera_frame(scene, width, height)
    n_pix = width * height
    spp = options.spp
    params = PathParams(n_pix, spp, options.seed, hither, eps, depth, options.jitter, not workload.shadow_nearest)
    out = PathOutputs(np.zeros((n_pix, 3)), np.zeros((n_pix * spp, 3)), np.zeros((n_pix, N_COUNTERS), np.int64),
                      np.zeros(n_pix, np.int64), np.zeros(n_pix, np.int64))
    inputs = (cam, params, tree_arr, geo, shading, emission)
    t0 = time.perf_counter()
    trace = None
    if not options.log:
        _trace_batches(inputs, out, 0, lambda records, segments: None)
        timings["render"] = time.perf_counter() - t0
    else:
        record = {"width": width, "height": height, "image_size": [width, height], "corner_rays": False,
                  "max_depth": depth, "hither": hither, "epsilon": eps}
        meta = trace_metadata(scene, tree, shading, record, workload, "trilinear")
        meta["path_tracing"] = {"spp": spp, "seed": options.seed, "jitter": options.jitter,
                                "roulette_bounce": ROULETTE_BOUNCE, "roulette_cap": ROULETTE_CAP,
                                "generator": "SplitMix64 chain (tracer.rendering.sampling)"}
        meta.update(metadata or {})
        if not options.keep_records:
            _trace_batches(inputs, out, options.memory_budget, lambda records, segments: None)
        else:
            records = _GrowingRecords(options.memory_budget)
            segments = []

            def sink(pieces, segment_pieces):
                for (ints, rays), piece_start in zip(segment_pieces, _starts(records.n, pieces)):
                    ints = ints.copy()
                    ints[:, SegmentColumn.FIRST] += piece_start
                    ints[:, SegmentColumn.STOP] += piece_start
                    segments.append((ints, rays.copy()))
                records.extend(pieces)

            _trace_batches(inputs, out, options.memory_budget, sink)
            offsets = np.zeros(n_pix + 1, np.int64)
            np.cumsum(out.counts, out=offsets[1:])
            ray_segments = RaySegments(
                np.concatenate([s[0] for s in segments]) if segments else np.zeros((0, N_SEGMENT_COLUMNS), np.int64),
                np.concatenate([s[1] for s in segments]) if segments else np.zeros((0, N_SEGMENT_RAY_COLUMNS)))
            trace = AccessTrace(offsets, records.finish(), out.counters, width, height, meta, ray_segments)
            if trace_path is not None:
                trace.save(trace_path)
        timings["trace"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return RenderResult(image=out.image.reshape(height, width, 3), counters=out.counters, trace=trace, tree=tree,
                        timings=timings, width=width, height=height, epsilon=eps, workload=workload.to_dict(),
                        texture_filter="trilinear", n_records=int(out.counts.sum()) if options.log else None,
                        sample_radiance=out.sample_radiance)


def _checked_emission(emission, n_materials: int) -> np.ndarray:
    if emission is None:
        return np.zeros((n_materials, 3))
    emission = np.asarray(emission, dtype=np.float64)
    if emission.shape != (n_materials, 3) or not np.isfinite(emission).all() or (emission < 0).any():
        raise InputError(f"emission must be a ({n_materials}, 3) array of finite radiances >= 0 (one row per "
                         f"material), got shape {emission.shape}")
    return np.ascontiguousarray(emission)


def _starts(first: int, pieces) -> list:
    """Where each of ``pieces`` starts when appended after ``first`` records."""
    starts = []
    for piece in pieces:
        starts.append(first)
        first += len(piece)
    return starts


def _trace_batches(inputs, out, memory_budget: int, sink) -> None:
    """Trace every pixel once, handing ``sink(record pieces, segment pieces)`` each batch in pixel order.

    With ``memory_budget`` 0 nothing is logged (slots of size 0). Each work
    item logs into its own slot of one reused buffer (records and segment
    rows); an item that overflows either slot is traced again into buffers
    of the sizes it reported, so the output depends on neither the slot
    sizes nor the schedule. The pieces are views of reused buffers: copy
    them before the next batch.
    """
    n_pix = out.counts.shape[0]
    items = np.arange(0, n_pix, PIXEL_CHUNK, dtype=np.int64)
    slot = max(1, min(memory_budget, SLOT_BUFFER_BYTES) // (4 * BATCH_ITEMS)) if memory_budget else 0
    seg_slot = max(1, slot // RECORDS_PER_SEGMENT) if memory_budget else 0
    n_batch = min(BATCH_ITEMS, len(items))
    records = np.empty(slot * n_batch, np.uint32)
    seg_ints = np.empty((seg_slot * n_batch, N_SEGMENT_COLUMNS), np.int64)
    seg_rays = np.empty((seg_slot * n_batch, N_SEGMENT_RAY_COLUMNS))
    for b0 in range(0, len(items), BATCH_ITEMS):
        start = items[b0:b0 + BATCH_ITEMS]
        k = len(start)
        work = PathWork(start, np.arange(k, dtype=np.int64) * slot, np.full(k, slot, np.int64), np.empty(k, np.int64),
                        np.arange(k, dtype=np.int64) * seg_slot, np.full(k, seg_slot, np.int64),
                        np.empty(k, np.int64))
        with numba.parallel_chunksize(1):
            path_kernel(work, (records, seg_ints, seg_rays), *inputs, out)
        if not memory_budget:
            continue
        pieces = [records[work.base[j]:work.base[j] + work.used[j]] for j in range(k)]
        segment_pieces = [(seg_ints[work.segment_base[j]:work.segment_base[j] + work.segments_used[j]],
                           seg_rays[work.segment_base[j]:work.segment_base[j] + work.segments_used[j]])
                          for j in range(k)]
        over = np.flatnonzero((work.used > slot) | (work.segments_used > seg_slot))
        if len(over):
            used, seg_used = work.used[over], work.segments_used[over]
            base = np.concatenate([[0], np.cumsum(used)[:-1]]).astype(np.int64)
            seg_base = np.concatenate([[0], np.cumsum(seg_used)[:-1]]).astype(np.int64)
            exact = PathWork(start[over], base, used.copy(), np.empty(len(over), np.int64), seg_base, seg_used.copy(),
                             np.empty(len(over), np.int64))
            exact_records = np.empty(int(used.sum()), np.uint32)
            exact_ints = np.empty((int(seg_used.sum()), N_SEGMENT_COLUMNS), np.int64)
            exact_rays = np.empty((int(seg_used.sum()), N_SEGMENT_RAY_COLUMNS))
            with numba.parallel_chunksize(1):
                path_kernel(exact, (exact_records, exact_ints, exact_rays), *inputs, out)
            for n, j in enumerate(over):
                pieces[j] = exact_records[base[n]:base[n] + used[n]]
                rows = slice(seg_base[n], seg_base[n] + seg_used[n])
                segment_pieces[j] = (exact_ints[rows], exact_rays[rows])
        sink(pieces, segment_pieces)
