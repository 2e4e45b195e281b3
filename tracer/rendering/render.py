"""Instrumented Whitted ray tracer (numba, parallel over pixels).

:func:`render` traces one ray through every pixel centre (or, with
``corner_rays``, a (W+1) x (H+1) grid through the pixel corners, as SPD's
published counts use), shades by Whitted's rules and, with ``log=True``,
returns an :class:`~tracer.trace.access.AccessTrace` of every scene record each
pixel read (see :mod:`tracer.trace.access` for the record order).

The shading rules are stated in :mod:`tracer.rendering.whitted`, whose kernels do the
tracing.

Logging takes one pass, parallel over work items of 64 samples handed out
dynamically: each item logs into a slot of a reused buffer, and an item that
outgrows its slot is traced again into a buffer of the size it reported.
Records come out in sample order whatever the schedule, and the image does
not depend on logging (same arithmetic, bit for bit).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from rtcommon.versions import package_versions
from rtcommon.validate import InputError, require_bool, require_int, require_number
from tracer.rendering.camera import camera_frame, checked_size
from tracer.rendering.geometry import prepare_geometry
from tracer.kd.tree import KdTree, KdTreeConfig
from tracer.trace.records import COUNTER_NAMES, N_COUNTERS
from tracer.rendering.types import RenderParams, SampleOutputs, WorkItems
from tracer.scenes.model import MAX_DEPTH, Scene
from tracer.rendering.shading import shading_of
from tracer.rendering.texture import MipChains, TextureFilter
from tracer.trace.access import AccessTrace, TraceWriter, column_sums
from tracer.kd.traverse import tree_arrays
from tracer.rendering.whitted import CHUNK, render_kernel
from tracer.rendering.workload import Workload, get_workload

DEFAULT_MEMORY_BUDGET = 1 << 30  # bytes of records held in RAM at once
#: ``epsilon`` with which :func:`render` reproduces the published SPD counts
#: (Havran 1999; ``reference/spd/README.md``): the reference tracer ignored
#: hits within 0.01 (scene units) of a secondary or shadow ray's origin. On
#: balls that lets reflection rays skip the near wall of the smallest spheres
#: (radius 0.0062) and bounce inside them, which is why its reflection rays
#: hit more often (0.747 of them) than with a tight tolerance (0.720).
SPD_EPSILON = 0.01
#: Most samples per pixel :class:`RenderOptions` accepts.
MAX_SPP = 4096
BATCH_CHUNKS = 128  # work items per kernel call when logging
SLOT_BUFFER_BYTES = 256 << 20  # most a logging batch's slots take


@dataclass(eq=False)
class RenderResult:
    """What :func:`render` returns.

    Attributes
    ----------
    image : ndarray, shape (H, W, 3) float64
        Linear RGB, not clipped.
    counters : ndarray, shape (H * W, K) int64
        Per-pixel counters, columns :data:`tracer.trace.access.COUNTER_NAMES`.
    trace : AccessTrace or None
        The access log (``log=True``), possibly memory-mapped from disk.
    tree : KdTree
    timings : dict
        Seconds: ``build``, ``trace`` (the logged pass) or ``render`` (the
        pass without logging), ``total``.
    width, height : int
        Samples per row and rows (W + 1, H + 1 with corner rays).
    epsilon : float
        The self-intersection tolerance used (scene units).
    workload : dict
        The :class:`~tracer.rendering.workload.Workload` imitated, as plain values.
    texture_filter : str
        How textured surfaces were filtered.
    n_records : int or None
        Records logged (kept or only counted); None without logging.
    sample_radiance : ndarray, shape (H * W * spp, 3) float64, or None
        The path tracer's radiance of each sample (pixel-major); None for
        Whitted renders.
    """

    image: np.ndarray
    counters: np.ndarray
    trace: AccessTrace | None
    tree: KdTree
    timings: dict = field(default_factory=dict)
    width: int = 0
    height: int = 0
    epsilon: float = 0.0
    workload: dict = field(default_factory=dict)
    texture_filter: str = "trilinear"
    n_records: int | None = None
    sample_radiance: np.ndarray | None = None

    def totals(self) -> dict:
        """Counter sums over all pixels (plus ``records`` when logged, ``rays``)."""
        sums = column_sums(self.counters)
        out = {name: int(v) for name, v in zip(COUNTER_NAMES, sums)}
        out["rays"] = (out["primary_rays"] + out["shadow_rays"]
                       + out["reflection_rays"] + out["refraction_rays"])
        out["intersection_tests"] = sum(out[n] for n in COUNTER_NAMES if n.startswith("tests_"))
        if self.n_records is not None:
            out["records"] = self.n_records
        elif self.trace is not None:
            out["records"] = self.trace.n_records
        return out


# --------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------


class _GrowingRecords:
    """A uint32 array that grows in place (``realloc``) as records arrive."""

    initial_capacity = 1 << 20

    def __init__(self, memory_budget: int):
        self.memory_budget = memory_budget
        self.data = np.empty(self.initial_capacity, np.uint32)
        self.n = 0

    def extend(self, pieces) -> None:
        need = self.n + sum(len(piece) for piece in pieces)
        if 4 * need > self.memory_budget:
            raise InputError(f"the trace needs more than memory_budget ({self.memory_budget / 2**20:.4g} MB of "
                             "records); pass trace_path to write it to disk in chunks, or keep_records=False "
                             "to count the records only")
        if need > len(self.data):
            self.data.resize(max(need, 2 * len(self.data)), refcheck=False)
        for piece in pieces:
            self.data[self.n:self.n + len(piece)] = piece
            self.n += len(piece)

    def reserve(self, capacity: int) -> None:
        """Make room for ``capacity`` records (at most the budget's) in one fresh array, when more than now."""
        capacity = min(capacity, self.memory_budget // 4)
        if capacity > len(self.data):
            data = np.empty(capacity, np.uint32)
            data[:self.n] = self.data[:self.n]
            self.data = data

    def finish(self) -> np.ndarray:
        self.data.resize(self.n, refcheck=False)
        return self.data


def _log_samples(kernel_inputs, out, memory_budget, sink):
    """Trace every sample once with logging, handing records to ``sink`` in sample order.

    ``sink`` receives each batch as a list of arrays (views of a reused
    buffer: copy them before the next batch).

    Samples run in batches of ``BATCH_CHUNKS`` work items; each item logs
    into its own slot of one reused buffer (memory is touched only where
    records land, so generous slots cost address space, not RAM). An item
    that overflows its slot is traced again into a buffer of the exact size
    it reported. Output depends on neither the slot size nor the schedule.
    """
    chunks = np.arange(0, len(out.counts), CHUNK, dtype=np.int64)
    # slots stay within the memory budget (and SLOT_BUFFER_BYTES) together
    slot = max(1, min(memory_budget, SLOT_BUFFER_BYTES) // (4 * BATCH_CHUNKS))
    buffer = np.empty(slot * min(BATCH_CHUNKS, len(chunks)), np.uint32)
    for b0 in range(0, len(chunks), BATCH_CHUNKS):
        start = chunks[b0:b0 + BATCH_CHUNKS]
        k = len(start)
        base = np.arange(k, dtype=np.int64) * slot
        used = np.empty(k, np.int64)
        with numba.parallel_chunksize(1):
            render_kernel(WorkItems(start, base, np.full(k, slot, np.int64), used), buffer, *kernel_inputs, out)
        pieces = [buffer[base[j]:base[j] + used[j]] for j in range(k)]
        over = np.flatnonzero(used > slot)
        if len(over):
            exact_base = np.concatenate([[0], np.cumsum(used[over])[:-1]]).astype(np.int64)
            exact = np.empty(int(used[over].sum()), np.uint32)
            with numba.parallel_chunksize(1):
                render_kernel(WorkItems(start[over], exact_base, used[over], np.empty(len(over), np.int64)),
                               exact, *kernel_inputs, out)
            for j, b in zip(over, exact_base):
                pieces[j] = exact[b:b + used[j]]
        sink(pieces)


#: the texture filters :class:`RenderOptions` accepts, by name
TEXTURE_FILTERS = {f.name.lower(): f for f in TextureFilter}


@dataclass(frozen=True)
class RenderOptions:
    """How :func:`render` renders and logs; every field is checked when the options are made.

    Parameters
    ----------
    size : int or (int, int), optional
        Image width and height; default the camera's resolution.
    corner_rays : bool
        Trace (W+1) x (H+1) rays through the pixel corners (SPD counting)
        instead of W x H through the centres.
    log : bool
        Trace with logging (one logged pass: the records every pixel reads)
        or only the image and counters (one pass without).
    keep_records : bool
        With ``log``: keep the records, in an :class:`AccessTrace` in memory
        or in ``trace_path`` (default); False counts them only
        (``RenderResult.n_records``), in the memory of one logging batch,
        so that a render for its image and figures needs no trace.
    kd_config : KdTreeConfig, optional
        The tree rule; default the workload's.
    max_depth : int, optional
        Ray-tree depth in 1..``MAX_DEPTH`` (64; primary = 1); default ``scene.max_depth``.
    memory_budget : int
        Bytes of records held in memory at once (>= 4): a trace kept in
        memory may not exceed it, and a logging batch's buffer stays
        within it.
    epsilon : float, optional
        Hits closer than this (scene units) to the origin of a reflection,
        refraction or shadow ray are ignored; default 1e-8 of the scene's
        bounding-box diagonal. :data:`SPD_EPSILON` reproduces the published
        SPD counts.
    workload : str or Workload, optional
        The tracer imitated, a :data:`tracer.rendering.workload.WORKLOADS`
        name or a :class:`~tracer.rendering.workload.Workload`; default
        ``"modern"`` (today's SAH tracer). Kept as the Workload; recorded in
        the trace's metadata.
    texture_filter : {"trilinear", "bilinear", "nearest"}
        How textured surfaces filter their texels
        (:mod:`tracer.rendering.texture`); the level of detail comes from
        ray cones. Recorded in the metadata.
    spp : int
        Samples per pixel of the path tracer (a workload whose renderer is
        ``"pathtrace"``), 1..4096; the Whitted renderer takes one.
    seed : int
        Key of the path tracer's counter-based random numbers, 0..2**63 - 1.
    jitter : bool
        The path tracer's camera rays pass through a random point of their
        pixel (else through its centre, as Whitted's do).

    Raises
    ------
    ValueError
        Naming the field and what it accepts.
    """

    size: int | tuple[int, int] | None = None
    corner_rays: bool = False
    log: bool = True
    keep_records: bool = True
    kd_config: KdTreeConfig | None = None
    max_depth: int | None = None
    memory_budget: int = DEFAULT_MEMORY_BUDGET
    epsilon: float | None = None
    workload: str | Workload | None = None
    texture_filter: str = "trilinear"
    spp: int = 1
    seed: int = 0
    jitter: bool = True

    def __post_init__(self):
        if self.size is not None:
            object.__setattr__(self, "size", checked_size(self.size, "RenderOptions.size"))
        object.__setattr__(self, "spp", require_int("RenderOptions.spp", self.spp, 1, MAX_SPP))
        object.__setattr__(self, "seed", require_int("RenderOptions.seed", self.seed, 0, 2**63 - 1))
        for name in ("corner_rays", "log", "keep_records", "jitter"):
            object.__setattr__(self, name, require_bool(f"RenderOptions.{name}", getattr(self, name)))
        if self.kd_config is not None and not isinstance(self.kd_config, KdTreeConfig):
            raise InputError(f"RenderOptions.kd_config must be a KdTreeConfig or None, got {self.kd_config!r}")
        if self.max_depth is not None:
            object.__setattr__(self, "max_depth", require_int("RenderOptions.max_depth", self.max_depth, 1, MAX_DEPTH))
        object.__setattr__(self, "memory_budget", require_int("RenderOptions.memory_budget", self.memory_budget, 4))
        if self.epsilon is not None:
            epsilon = require_number("RenderOptions.epsilon", self.epsilon, 0, "a distance")
            if epsilon == 0:
                raise InputError("RenderOptions.epsilon must be a finite number > 0 (a distance), got 0")
            object.__setattr__(self, "epsilon", epsilon)
        try:
            workload = get_workload("modern" if self.workload is None else self.workload)
        except ValueError as error:
            raise InputError(f"RenderOptions.workload: {error}") from None
        object.__setattr__(self, "workload", workload)
        if self.spp != 1 and self.workload.renderer != "pathtrace":
            raise InputError(f"RenderOptions.spp must be 1 for the {self.workload.name!r} workload (Whitted's "
                             f"rules trace one sample per pixel), got {self.spp}")
        if self.texture_filter not in TEXTURE_FILTERS:
            raise InputError(f"RenderOptions.texture_filter must be one of {', '.join(TEXTURE_FILTERS)}, "
                             f"got {self.texture_filter!r}")


def render(scene: Scene, tree: KdTree | None = None, options: RenderOptions | None = None, *,
           trace_path=None, metadata: dict | None = None) -> RenderResult:
    """Render ``scene`` and, with ``options.log``, record every scene access per pixel.

    Parameters
    ----------
    scene : Scene
    tree : KdTree, optional
        Built from ``options.kd_config`` when omitted.
    options : RenderOptions, optional
        Size, logging, tree rule, depth, tolerance, workload, texture
        filter; default ``RenderOptions()``.
    trace_path : path, optional
        Also save the trace there (atomically). A trace whose records exceed
        ``options.memory_budget`` bytes requires it (or ``keep_records``
        False): records are then written in chunks straight to disk and the
        returned trace is memory-mapped.
    metadata : dict, optional
        Extra JSON-serialisable entries for the trace's metadata.

    Returns
    -------
    RenderResult
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a Scene, got {type(scene).__name__}")
    options = RenderOptions() if options is None else options
    if not isinstance(options, RenderOptions):
        raise InputError(f"options must be RenderOptions, got {type(options).__name__}")
    if options.workload.renderer == "pathtrace":
        from tracer.rendering.pathtrace import path_trace

        return path_trace(scene, tree, options, trace_path=trace_path, metadata=metadata)
    width, height = scene.camera.resolution if options.size is None else options.size
    depth = scene.max_depth if options.max_depth is None else options.max_depth
    if isinstance(depth, (bool, np.bool_)) or int(depth) != depth or not 1 <= depth <= MAX_DEPTH:
        raise InputError(f"max_depth must be an int in 1..{MAX_DEPTH}, got {depth!r} (the scene's {scene.name!r})")
    depth = int(depth)
    corner_rays, log, memory_budget = options.corner_rays, options.log, options.memory_budget
    epsilon, texture_filter, workload = options.epsilon, options.texture_filter, options.workload
    filters = TEXTURE_FILTERS
    kd_config = options.kd_config
    if kd_config is None and tree is None:
        kd_config = workload.kd_config
    timings = {}
    t_start = time.perf_counter()
    tree, tree_arr = tree_arrays(scene, tree, kd_config)
    timings["build"] = time.perf_counter() - t_start
    shading = shading_of(scene, filters[texture_filter])
    geo = prepare_geometry(scene)
    eps = self_intersection_tolerance(tree, epsilon)
    hither = float(scene.camera.hither)
    cam = camera_frame(scene, width, height, corner_rays)
    sx = width + 1 if corner_rays else width
    sy = height + 1 if corner_rays else height
    n_pix = sx * sy
    image = np.zeros((n_pix, 3))
    counts = np.zeros(n_pix, np.int64)
    # a trace written to disk fills its counters in their file instead
    counters = None if log and trace_path is not None else np.zeros((n_pix, N_COUNTERS), np.int64)
    out = SampleOutputs(image, counters, counts)
    offsets = np.zeros(n_pix + 1, np.int64)
    # the render kernel's arguments between the work items and the outputs
    kernel_inputs = (cam, RenderParams(n_pix, hither, eps, depth, not workload.shadow_nearest,
                                       workload.log_ray_data, math.atan(cam.pitch)), tree_arr, geo, shading)
    trace = None
    t0 = time.perf_counter()
    if not log:
        chunks = np.arange(0, n_pix, CHUNK, dtype=np.int64)
        zeros = np.zeros(len(chunks), np.int64)
        with numba.parallel_chunksize(1):
            render_kernel(WorkItems(chunks, zeros, zeros, np.empty(len(chunks), np.int64)),
                           np.empty(0, np.uint32), *kernel_inputs, out)
        timings["render"] = time.perf_counter() - t0
    else:
        meta = trace_metadata(scene, tree, shading, {"width": sx, "height": sy, "image_size": [width, height],
                                                     "corner_rays": bool(corner_rays), "max_depth": depth,
                                                     "hither": hither, "epsilon": eps}, workload, texture_filter)
        meta.update(metadata or {})
        if trace_path is None and not options.keep_records:
            _log_samples(kernel_inputs, out, memory_budget, lambda pieces: None)  # counts are all that is kept
        elif trace_path is None:
            records = _GrowingRecords(memory_budget)
            _log_samples(kernel_inputs, out, memory_budget, records.extend)
            np.cumsum(counts, out=offsets[1:])
            trace = AccessTrace(offsets, records.finish(), counters, sx, sy, meta)
        else:
            with TraceWriter(trace_path) as writer:
                # the counters are part of the trace: filled in their file, batch by batch
                def sink(pieces):
                    for piece in pieces:
                        writer.append(piece)
                    writer.release_counter_pages()

                _log_samples(kernel_inputs, SampleOutputs(image, writer.counters_array(n_pix, N_COUNTERS), counts),
                             memory_budget, sink)
                np.cumsum(counts, out=offsets[1:])
                trace = writer.finish(offsets, None, sx, sy, meta, mmap=4 * int(offsets[-1]) > memory_budget)
            counters = trace.counters
        timings["trace"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_start
    return RenderResult(image=image.reshape(sy, sx, 3), counters=counters, trace=trace, tree=tree,
                        timings=timings, width=sx, height=sy, epsilon=eps, workload=workload.to_dict(),
                        texture_filter=texture_filter, n_records=int(counts.sum()) if log else None)


def self_intersection_tolerance(tree: KdTree, epsilon: float | None) -> float:
    """``epsilon`` as given, else 1e-8 of the diagonal of ``tree``'s box (1e-12 for an empty box)."""
    if epsilon is not None:
        return float(epsilon)
    diag = float(np.linalg.norm(tree.bounds[1] - tree.bounds[0]))
    return 1e-8 * max(diag, 1e-300) if diag > 0 else 1e-12


def trace_metadata(scene: Scene, tree: KdTree, shading, render_record: dict, workload: Workload,
                   texture_filter: str) -> dict:
    """The metadata a logged render stores with its trace.

    Parameters
    ----------
    scene : Scene
    tree : KdTree
    shading : tracer.rendering.types.Shading
        What the render's shading read (its textures' sizes are recorded).
    render_record : dict
        The render's own values, in the order stored: ``width`` and ``height``
        (samples per row and rows), ``image_size``, ``corner_rays``,
        ``max_depth``, ``hither``, ``epsilon``.
    workload : Workload
    texture_filter : str

    Returns
    -------
    dict
        JSON-serialisable; ``record_counts`` holds how many records of each
        kind exist, read or not, so that a memory layout can place them all
        (``coherence.layout``).
    """
    depth = render_record["max_depth"]
    n_pix = render_record["width"] * render_record["height"]
    meta = {
        "scene": scene.name, **render_record,
        "kd_config": tree.config.to_dict(), "kd_stats": tree.stats, "workload": workload.to_dict(),
        "scene_summary": scene.summary() if hasattr(scene, "summary") else {"name": scene.name},
        "versions": package_versions(),
        "record_index_note": "primitive records use the row in that kind's arrays (Scene.element_index)",
        "record_counts": {
            "kd_node": int(tree.nodes.shape[0]), "index_entry": int(tree.primitive_indices.size),
            "sphere": int(scene.sphere_radius.size), "triangle": int(scene.triangle_vertices.shape[0]),
            "polygon": int(scene.polygon_offsets.size - 1), "patch": int(scene.patch_offsets.size - 1),
            "cone": int(scene.cone_base_radius.size), "material": int(scene.material_kd.size),
            "light": int(scene.light_position.shape[0]),
        },
    }
    # the tracer's own data exists only where it is logged
    own = workload.log_ray_data
    meta["record_counts"].update({"ray_stack": (2 * depth + 2) * own, "hit_record": depth * own,
                                  "shading_temp": depth * own, "frame_buffer": n_pix * own})
    meta["record_counts"].update({"texel": int(shading.level_first[-1]), "texture": scene.n_textures})
    if scene.n_textures:
        # each texture's mip levels, (width, height) finest first: a
        # memory layout needs them to place the texels
        meta["textures"] = MipChains(shading.texels, shading.level_first, shading.level_width,
                                     shading.level_height, shading.texture_level).levels()
        meta["texture_filter"] = texture_filter
    return meta


def save_png(image, path) -> Path:
    """Save a linear RGB image (H, W, 3) as PNG, clipped to [0, 1]."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"image must have shape (H, W, 3), got {image.shape}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plt.imsave(path, np.clip(image, 0.0, 1.0))
    return path
