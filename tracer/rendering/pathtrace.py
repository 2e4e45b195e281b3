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
#: Records per sample a work item's slot holds in the first logging batch (later batches learn from it).
FIRST_SLOT_RECORDS = 1024
#: Segments (rays) per sample a work item's segment slot holds in the first logging batch.
FIRST_SLOT_SEGMENTS = 16


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
        _trace_batches(inputs, out, 0, lambda records, segments, done: None)
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
            _trace_batches(inputs, out, options.memory_budget, lambda records, segments, done: None)
        else:
            collected = _Collected(n_pix, options.memory_budget)
            _trace_batches(inputs, out, options.memory_budget, collected.extend)
            offsets = np.zeros(n_pix + 1, np.int64)
            np.cumsum(out.counts, out=offsets[1:])
            records, ray_segments = collected.finish()
            trace = AccessTrace(offsets, records, out.counters, width, height, meta, ray_segments)
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


class _Collected:
    """Every batch's records and segments, copied into arrays sized ahead.

    After each batch the arrays are sized for the whole image from the
    records (and segments) per pixel so far, so that most renders copy each
    record once; the segments' record ranges become positions in the whole
    trace.
    """

    def __init__(self, n_pixels: int, memory_budget: int):
        self.n_pixels = n_pixels
        self.records = _GrowingRecords(memory_budget)
        self.n_segments = 0
        self.ints = np.empty((0, N_SEGMENT_COLUMNS), np.int64)
        self.rays = np.empty((0, N_SEGMENT_RAY_COLUMNS))

    def _expected(self, need: int, capacity: int, pixels_done: int) -> int:
        # room for the image at the rate so far (with 10% to spare), and never less than 1.5 times the last room
        return max(need, -(-need * self.n_pixels * 11 // (10 * pixels_done)), capacity + capacity // 2)

    def extend(self, pieces, segment_pieces, pixels_done: int) -> None:
        """Append one batch: its record ``pieces`` and ``segment_pieces`` (segment ranges relative to each piece)."""
        records = self.records
        need = records.n + sum(len(piece) for piece in pieces)
        if need > len(records.data):
            records.reserve(self._expected(need, len(records.data), pixels_done))
        row = self.n_segments
        need = row + sum(len(ints) for ints, _ in segment_pieces)
        if need > len(self.ints):
            ints, rays = self.ints, self.rays
            rows = self._expected(need, len(ints), pixels_done)
            self.ints = np.empty((rows, N_SEGMENT_COLUMNS), np.int64)
            self.rays = np.empty((rows, N_SEGMENT_RAY_COLUMNS))
            self.ints[:row] = ints[:row]
            self.rays[:row] = rays[:row]
        rows = slice(row, need)
        np.concatenate([ints for ints, _ in segment_pieces], out=self.ints[rows])
        np.concatenate([rays for _, rays in segment_pieces], out=self.rays[rows])
        piece_starts = records.n + np.cumsum([0] + [len(piece) for piece in pieces[:-1]])
        self.ints[rows, SegmentColumn.FIRST:SegmentColumn.STOP + 1] += np.repeat(
            piece_starts, [len(ints) for ints, _ in segment_pieces])[:, None]
        records.extend(pieces)
        self.n_segments = need

    def finish(self) -> tuple:
        """The records, shape (R,) uint32, and the :class:`RaySegments`, each trimmed to what was appended."""
        self.ints.resize((self.n_segments, N_SEGMENT_COLUMNS), refcheck=False)
        self.rays.resize((self.n_segments, N_SEGMENT_RAY_COLUMNS), refcheck=False)
        return self.records.finish(), RaySegments(self.ints, self.rays)


def _slot_buffers(n_items: int, slot: int, segment_slot: int) -> tuple:
    """Records, segment ints and segment rays for ``n_items`` work items of these slot sizes."""
    return (np.empty(slot * n_items, np.uint32), np.empty((segment_slot * n_items, N_SEGMENT_COLUMNS), np.int64),
            np.empty((segment_slot * n_items, N_SEGMENT_RAY_COLUMNS)))


def _trace_batches(inputs, out, memory_budget: int, sink) -> None:
    """Trace every pixel once, handing ``sink(record pieces, segment pieces, pixels done)`` each batch in
    pixel order.

    With ``memory_budget`` 0 nothing is logged (slots of size 0). Each work
    item logs into its own slot of one reused buffer (records and segment
    rows); an item that overflows either slot is traced again into buffers
    of the sizes it reported, so the output depends on neither the slot
    sizes nor the schedule. The first batch's slots hold
    :data:`FIRST_SLOT_RECORDS` records and :data:`FIRST_SLOT_SEGMENTS`
    segments per sample; after a batch that overflowed, slots grow to twice
    the most any item used, within the memory budget (segments: one per
    :data:`RECORDS_PER_SEGMENT` records of it). Slots are kept small
    because a buffer's pages are zeroed where first written, a whole huge
    page at a time. The pieces are views of reused buffers: copy them
    before the next batch.
    """
    n_pix = out.counts.shape[0]
    items = np.arange(0, n_pix, PIXEL_CHUNK, dtype=np.int64)
    most = max(1, min(memory_budget, SLOT_BUFFER_BYTES) // (4 * BATCH_ITEMS)) if memory_budget else 0
    most_segments = max(1, most // RECORDS_PER_SEGMENT) if memory_budget else 0
    spp = inputs[1].spp
    slot = min(most, FIRST_SLOT_RECORDS * PIXEL_CHUNK * spp)
    seg_slot = min(most_segments, FIRST_SLOT_SEGMENTS * PIXEL_CHUNK * spp)
    n_batch = min(BATCH_ITEMS, len(items))
    records, seg_ints, seg_rays = _slot_buffers(n_batch, slot, seg_slot)
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
            exact_records, exact_ints, exact_rays = _slot_buffers(1, int(used.sum()), int(seg_used.sum()))
            with numba.parallel_chunksize(1):
                path_kernel(exact, (exact_records, exact_ints, exact_rays), *inputs, out)
            for n, j in enumerate(over):
                pieces[j] = exact_records[base[n]:base[n] + used[n]]
                rows = slice(seg_base[n], seg_base[n] + seg_used[n])
                segment_pieces[j] = (exact_ints[rows], exact_rays[rows])
        sink(pieces, segment_pieces, min(n_pix, int(start[-1]) + PIXEL_CHUNK))
        if len(over):
            slot = min(most, max(slot, 2 * int(work.used.max())))
            seg_slot = min(most_segments, max(seg_slot, 2 * int(work.segments_used.max())))
            records, seg_ints, seg_rays = _slot_buffers(n_batch, slot, seg_slot)
