"""The path tracer's compiled kernels: one path per sample, and the parallel loop over pixels.

:func:`tracer.rendering.pathtrace.path_trace` is the public entry point and
states the rules; this module holds their arithmetic. Records are logged as
the Whitted kernels log them (:func:`tracer.kd.traverse.traverse`), and every
ray's run of records is closed as a segment (:mod:`tracer.trace.segments`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from rtcommon.jit import NO_REFCOUNTS
from tracer.kd.traverse import RecordLog, new_stack, traverse
from tracer.rendering.geometry import Ray, element_normal
from tracer.rendering.sampling import Dimension, cosine_direction, sample_key, uniform
from tracer.rendering.types import LightColumn, MaterialColumn
from tracer.trace.records import Counter, RecordKind, make_record
from tracer.trace.segments import SegmentColumn, SegmentRayColumn, SegmentRayType

#: Pixels per parallel work item.
PIXEL_CHUNK = 16
#: Russian roulette starts at this bounce (0 = the camera ray's hit): paths
#: shorter than this are never cut.
ROULETTE_BOUNCE = 3
#: Russian roulette keeps a path with probability ``min(max(throughput), ROULETTE_CAP)``.
ROULETTE_CAP = 0.95


class PathParams(NamedTuple):
    """Per-render scalars of the path tracer's kernels."""

    n_pixels: int
    spp: int           #: samples per pixel
    seed: int          #: key of the counter-based generator (>= 0)
    hither: float      #: camera rays ignore hits closer than this
    epsilon: float     #: bounce and shadow rays ignore hits closer than this
    max_depth: int     #: rays per path at most (the camera ray is 1)
    jitter: bool       #: camera rays through a random point of the pixel (else its centre)
    shadow_anyhit: bool  #: shadow rays stop at the first hit found


class PathOutputs(NamedTuple):
    """Per-pixel and per-sample outputs of :func:`path_kernel`."""

    image: np.ndarray            #: (P, 3) float64 mean radiance of the pixel's samples
    sample_radiance: np.ndarray  #: (P * spp, 3) float64 radiance of each sample (pixel-major)
    counters: np.ndarray         #: (P, N_COUNTERS) int64
    counts: np.ndarray           #: (P,) int64 records of the pixel
    segment_counts: np.ndarray   #: (P,) int64 segments of the pixel


class PathWork(NamedTuple):
    """Parallel work items: :data:`PIXEL_CHUNK` pixels each, with a slot of records and one of segments.

    Item ``k`` logs into ``records[base[k]:base[k] + capacity[k]]`` and
    segment rows ``segment_base[k] ..`` (``segment_capacity[k]`` of them);
    ``used`` and ``segments_used`` report what it produced (more than the
    capacity: that slot overflowed and nothing past it was stored).
    Segment record ranges are relative to the item's first record.
    """

    start: np.ndarray             #: (K,) int64 first pixel
    base: np.ndarray              #: (K,) int64
    capacity: np.ndarray          #: (K,) int64
    used: np.ndarray              #: (K,) int64 output
    segment_base: np.ndarray      #: (K,) int64
    segment_capacity: np.ndarray  #: (K,) int64
    segments_used: np.ndarray     #: (K,) int64 output


@njit(cache=True, inline="always")
def _close_segment(seg, where, ray, what, hit):
    # row where[0] of the segment arrays (stored while below where[1]): ray
    # (origin, direction), what = (pixel, sample, bounce, type, first, stop), hit point
    ints, rays = seg
    row, limit = where
    if row < limit:
        ints[row, SegmentColumn.PIXEL] = what[0]
        ints[row, SegmentColumn.SAMPLE] = what[1]
        ints[row, SegmentColumn.BOUNCE] = what[2]
        ints[row, SegmentColumn.RAY_TYPE] = what[3]
        ints[row, SegmentColumn.FIRST] = what[4]
        ints[row, SegmentColumn.STOP] = what[5]
        for c in range(6):
            rays[row, SegmentRayColumn.ORIGIN + c] = ray[c]
        rays[row, SegmentRayColumn.HIT] = hit[0]
        rays[row, SegmentRayColumn.HIT + 1] = hit[1]
        rays[row, SegmentRayColumn.HIT + 2] = hit[2]
    return row + 1


@njit(cache=True, error_model="numpy", inline="always")
def _toward_light(lights, li, hx, hy, hz):
    # unit direction from the hit point to light li and its distance (0: the light is at the point)
    lx = lights[li, LightColumn.POSITION] - hx
    ly = lights[li, LightColumn.POSITION + 1] - hy
    lz = lights[li, LightColumn.POSITION + 2] - hz
    dist = math.sqrt(lx * lx + ly * ly + lz * lz)
    if dist == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return lx / dist, ly / dist, lz / dist, dist


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def _trace_path(first_ray, ids, params, scene, log, seg, cursor, scratch):
    # one path of ids = (pixel, sample, generator key), from first_ray, through scene = (tree, geo,
    # shading, emission); returns r, g, b, pos, seg_pos. cursor = (pos, seg_pos): the next record /
    # segment row, relative to the work item's slot; segment ranges are stored as they are.
    # scratch = (counters, traversal stack).
    pixel, sample, key = ids
    tree, geo, shading, emission = scene
    pos, seg_pos = cursor
    cnt, stack = scratch
    rec, limit = log
    seg_limit = seg[0].shape[0]
    mats = shading.materials
    lights = shading.lights
    n_lights = lights.shape[0]
    eps = params.epsilon
    nan = np.nan
    lr = 0.0
    lg = 0.0
    lb = 0.0
    tr_ = 1.0
    tg = 1.0
    tb = 1.0
    ox, oy, oz, dx, dy, dz = first_ray
    rays_counter = Counter.PRIMARY_RAYS
    for bounce in range(params.max_depth):
        typ = np.int64(SegmentRayType.CAMERA) if bounce == 0 else np.int64(SegmentRayType.BOUNCE)
        tmin = params.hither if bounce == 0 else eps
        first = pos
        cnt[rays_counter] += 1
        t, e, pos = traverse(tree, geo, Ray(ox, oy, oz, dx, dy, dz), tmin, np.inf, False,
                             RecordLog(rec, limit), pos, cnt, stack)
        ray6 = (ox, oy, oz, dx, dy, dz)
        if e < 0:
            bg = shading.background
            lr += tr_ * bg[0]
            lg += tg * bg[1]
            lb += tb * bg[2]
            seg_pos = _close_segment(seg, (seg_pos, seg_limit), ray6, (pixel, sample, bounce, typ, first, pos),
                                     (nan, nan, nan))
            break
        cnt[rays_counter + 1] += 1  # the hits counter follows its rays counter
        hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
        k = np.int64(geo.element_kind[e])
        nx, ny, nz = element_normal(k, geo.element_index[e], geo, hx, hy, hz)
        ddn = dx * nx + dy * ny + dz * nz
        # shading normal facing the incoming ray (diffuse and mirror lobes are two-sided)
        if ddn > 0.0:
            fx, fy, fz = -nx, -ny, -nz
        else:
            fx, fy, fz = nx, ny, nz
        m = shading.element_material[e]
        if pos < limit:
            rec[pos] = make_record(RecordKind.MATERIAL, m)
        pos += 1
        cnt[Counter.SHADING] += 1
        lr += tr_ * emission[m, 0]
        lg += tg * emission[m, 1]
        lb += tb * emission[m, 2]
        kd, ks, trans = mats[m, MaterialColumn.KD], mats[m, MaterialColumn.KS], mats[m, MaterialColumn.TRANSMIT]
        ar = kd * mats[m, MaterialColumn.COLOR]
        ag = kd * mats[m, MaterialColumn.COLOR + 1]
        ab = kd * mats[m, MaterialColumn.COLOR + 2]
        for li in range(n_lights):
            if pos < limit:
                rec[pos] = make_record(RecordKind.LIGHT, li)
            pos += 1
            cnt[Counter.LIGHT_READS] += 1
        seg_pos = _close_segment(seg, (seg_pos, seg_limit), ray6, (pixel, sample, bounce, typ, first, pos),
                                 (hx, hy, hz))
        # next-event estimation: a shadow ray to every point light the diffuse lobe faces
        if kd > 0.0:
            for li in range(n_lights):
                lx, ly, lz, dist = _toward_light(lights, li, hx, hy, hz)
                ndl = fx * lx + fy * ly + fz * lz
                if dist == 0.0 or ndl <= 0.0:
                    continue
                first = pos
                cnt[Counter.SHADOW_RAYS] += 1
                ts, es, pos = traverse(tree, geo, Ray(hx, hy, hz, lx, ly, lz), eps, dist, params.shadow_anyhit,
                                       RecordLog(rec, limit), pos, cnt, stack)
                if es >= 0:
                    cnt[Counter.SHADOW_BLOCKED] += 1
                    blocker = (hx + ts * lx, hy + ts * ly, hz + ts * lz)
                else:
                    blocker = (nan, nan, nan)
                    lr += tr_ * ar * ndl * lights[li, LightColumn.COLOR]
                    lg += tg * ag * ndl * lights[li, LightColumn.COLOR + 1]
                    lb += tb * ab * ndl * lights[li, LightColumn.COLOR + 2]
                seg_pos = _close_segment(seg, (seg_pos, seg_limit), (hx, hy, hz, lx, ly, lz),
                                         (pixel, sample, bounce, np.int64(SegmentRayType.SHADOW), first, pos), blocker)
        if bounce + 1 >= params.max_depth:
            break
        # choose a lobe in proportion to its weight; the throughput divides by that probability
        w_diffuse = kd * max(mats[m, MaterialColumn.COLOR], mats[m, MaterialColumn.COLOR + 1],
                             mats[m, MaterialColumn.COLOR + 2])
        total = w_diffuse + ks + trans
        if total <= 0.0:
            break
        u = uniform(key, bounce, Dimension.LOBE) * total
        if u < w_diffuse:
            dx, dy, dz = cosine_direction(fx, fy, fz, uniform(key, bounce, Dimension.DIRECTION_U),
                                          uniform(key, bounce, Dimension.DIRECTION_V))
            scale = total / w_diffuse
            tr_ *= ar * scale
            tg *= ag * scale
            tb *= ab * scale
            rays_counter = Counter.REFLECTION_RAYS
        else:
            refracted = False
            if u >= w_diffuse + ks:
                # Snell; entering where the ray meets the front of the geometric normal
                if ddn < 0.0:
                    eta = 1.0 / mats[m, MaterialColumn.IOR]
                    cosi = -ddn
                else:
                    eta = mats[m, MaterialColumn.IOR]
                    cosi = ddn
                k2 = 1.0 - eta * eta * (1.0 - cosi * cosi)
                if k2 >= 0.0:
                    c2 = eta * cosi - math.sqrt(k2)
                    # (fx, fy, fz) faces the incoming ray: the refracted ray leaves along -f
                    dx, dy, dz = eta * dx - c2 * fx, eta * dy - c2 * fy, eta * dz - c2 * fz
                    refracted = True
            if not refracted:  # a mirror, or total internal reflection
                dn = dx * fx + dy * fy + dz * fz
                dx, dy, dz = dx - 2.0 * dn * fx, dy - 2.0 * dn * fy, dz - 2.0 * dn * fz
            ln = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx, dy, dz = dx / ln, dy / ln, dz / ln
            scale = total  # weight / (weight / total)
            tr_ *= scale
            tg *= scale
            tb *= scale
            rays_counter = Counter.REFRACTION_RAYS if refracted else Counter.REFLECTION_RAYS
        if bounce + 1 >= ROULETTE_BOUNCE:
            q = min(max(tr_, tg, tb), ROULETTE_CAP)
            if q <= 0.0 or uniform(key, bounce, Dimension.ROULETTE) >= q:
                break
            tr_ /= q
            tg /= q
            tb /= q
        ox, oy, oz = hx, hy, hz
    return lr, lg, lb, pos, seg_pos


@njit(cache=True, error_model="numpy")
def _trace_pixels(p0, p1, slots, cam, params, tree, geo, shading, emission, out):
    # pixels p0..p1 one after another into the slots = (records, limit, base, segment ints,
    # segment rays, segment base, segment limit); returns (records used, segments used)
    records, limit, base, seg_ints, seg_rays, seg_base, seg_limit = slots
    cnt = np.zeros(out.counters.shape[1], np.int64)
    stack = new_stack()
    seg = (seg_ints[seg_base:seg_limit], seg_rays[seg_base:seg_limit])
    slot = records[base:limit]
    pos = 0
    seg_pos = 0
    sx = np.int64(cam.samples_x)
    spp = params.spp
    for p in range(p0, p1):
        i = p % sx
        j = p // sx
        cnt[:] = 0
        first = pos
        first_seg = seg_pos
        sr = 0.0
        sg = 0.0
        sb = 0.0
        for s in range(spp):
            key = sample_key(params.seed, p, s)
            ju = uniform(key, 0, Dimension.JITTER_X) - 0.5 if params.jitter else 0.0
            jv = uniform(key, 0, Dimension.JITTER_Y) - 0.5 if params.jitter else 0.0
            u = (i + ju - cam.cx) * cam.pitch
            v = (cam.cy - j - jv) * cam.pitch
            dx = cam.forward[0] + u * cam.right[0] + v * cam.up[0]
            dy = cam.forward[1] + u * cam.right[1] + v * cam.up[1]
            dz = cam.forward[2] + u * cam.right[2] + v * cam.up[2]
            ln = math.sqrt(dx * dx + dy * dy + dz * dz)
            r, g, b, pos, seg_pos = _trace_path((cam.eye[0], cam.eye[1], cam.eye[2], dx / ln, dy / ln, dz / ln),
                                                (p, s, key), params, (tree, geo, shading, emission),
                                                (slot, limit - base), seg, (pos, seg_pos), (cnt, stack))
            out.sample_radiance[p * spp + s, 0] = r
            out.sample_radiance[p * spp + s, 1] = g
            out.sample_radiance[p * spp + s, 2] = b
            sr += r
            sg += g
            sb += b
        out.image[p, 0] = sr / spp
        out.image[p, 1] = sg / spp
        out.image[p, 2] = sb / spp
        for column in range(cnt.shape[0]):
            out.counters[p, column] = cnt[column]
        out.counts[p] = pos - first
        out.segment_counts[p] = seg_pos - first_seg
    return pos, seg_pos


@njit(parallel=True, cache=True, error_model="numpy")
def path_kernel(work, buffers, cam, params, tree, geo, shading, emission, out):
    # every work item (PathWork) traced into its slots of buffers = (records, segment ints, segment
    # rays), in parallel
    records, seg_ints, seg_rays = buffers
    used = work.used
    segments_used = work.segments_used
    for k in prange(work.start.shape[0]):
        p0 = work.start[k]
        base = work.base[k]
        seg_base = work.segment_base[k]
        slots = (records, base + work.capacity[k], base, seg_ints, seg_rays, seg_base,
                 seg_base + work.segment_capacity[k])
        n_rec, n_seg = _trace_pixels(p0, min(params.n_pixels, p0 + PIXEL_CHUNK), slots, cam, params, tree, geo,
                                     shading, emission, out)
        used[k] = n_rec
        segments_used[k] = n_seg
