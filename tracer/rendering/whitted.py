"""The renderer's compiled kernels: Whitted's rules for one sample, and the loops over samples.

:func:`render_kernel` traces work items (:class:`~tracer.rendering.types.WorkItems`
of :data:`CHUNK` samples) in parallel; each item's samples are traced one
after another by a loop compiled without reference counting
(:data:`rtcommon.jit.NO_REFCOUNTS`), into which the ray tree of a sample
and its traversals are inlined. :func:`tracer.rendering.render.render` is the public
entry point.

Rules (SPD test procedure, see ``reference/spd/README.md``):

* camera: ``angle`` spans the centres of the outermost pixel rows; square
  pixels; primary rays ignore hits closer than ``hither``;
* ambient ``a * Kd * colour`` plus, per light with ``N.L > 0`` (normals are
  one-sided, so no shadow ray where the surface faces away from the light),
  a shadow ray and, if unblocked, ``Kd * colour * N.L + Ks * (R.V)^shine``
  times the light colour; with ``n`` lights the ambient level and every
  light are scaled by ``sqrt(n) / (2 n)`` (SPD's suggestion);
* a reflection ray if ``Ks > 0`` (weight Ks), a refraction ray if ``T > 0``
  (weight T, Snell; none under total internal reflection), while the ray's
  depth (primary = 1) is below the scene's ``max_depth``;
* any hit blocks a shadow ray (transparent objects cast full shadows);
* reflection, refraction and shadow rays ignore hits closer than
  ``epsilon`` to their origin (default a self-intersection tolerance of
  1e-8 of the scene's diagonal; :data:`tracer.rendering.render.SPD_EPSILON`
  reproduces the published SPD counts).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from rtcommon.jit import NO_REFCOUNTS
from tracer.rendering.geometry import Ray, element_normal
from tracer.trace.records import Counter, RecordKind, make_record, make_write_record
from tracer.rendering.types import (N_RAY_COLUMNS, LightColumn, MaterialColumn, RayColumn, RayType, SampleRange,
                                 SampleScratch)
from tracer.scenes.model import ElementKind
from tracer.rendering.shading import texture_colour
from tracer.kd.traverse import RecordLog, new_stack, traverse

CHUNK = 64  # samples per parallel work item


@njit(cache=True, inline="always")
def _ray_counters(typ):
    # the (rays, hits) counters of a stacked ray's type
    if typ == RayType.PRIMARY:
        return Counter.PRIMARY_RAYS, Counter.PRIMARY_HITS
    if typ == RayType.REFLECTION:
        return Counter.REFLECTION_RAYS, Counter.REFLECTION_HITS
    return Counter.REFRACTION_RAYS, Counter.REFRACTION_HITS


@njit(cache=True, inline="always")
def _normalized(ray):
    # the ray with its direction scaled to unit length
    ox, oy, oz, dx, dy, dz = ray
    ln = math.sqrt(dx * dx + dy * dy + dz * dz)
    return Ray(ox, oy, oz, dx / ln, dy / ln, dz / ln)


@njit(cache=True, inline="always")
def _log_access(rec, limit, pos, cnt, counter, record):
    # one record of the tracer's own data at pos (stored while below limit),
    # counted in cnt[counter]; returns the next position
    if pos < limit:
        rec[pos] = record
    cnt[counter] += 1
    return pos + 1


@njit(cache=True, error_model="numpy")
def _push_ray(rays, n, ray, weight, depth, typ, cone):
    # put a ray of colour weight (r, g, b) and ray cone (width, spread) on
    # the ray stack; returns the new stack size
    ox, oy, oz, dx, dy, dz = ray
    rays[n, RayColumn.ORIGIN] = ox
    rays[n, RayColumn.ORIGIN + 1] = oy
    rays[n, RayColumn.ORIGIN + 2] = oz
    rays[n, RayColumn.DIRECTION] = dx
    rays[n, RayColumn.DIRECTION + 1] = dy
    rays[n, RayColumn.DIRECTION + 2] = dz
    rays[n, RayColumn.WEIGHT] = weight[0]
    rays[n, RayColumn.WEIGHT + 1] = weight[1]
    rays[n, RayColumn.WEIGHT + 2] = weight[2]
    rays[n, RayColumn.DEPTH] = depth
    rays[n, RayColumn.TYPE] = np.int64(typ)
    rays[n, RayColumn.CONE_WIDTH] = cone[0]
    rays[n, RayColumn.CONE_SPREAD] = cone[1]
    return n + 1


@njit(cache=True, error_model="numpy", inline="always")
def _trace_sample(primary, params, tree, geo, shading, log, pos, scratch):
    # Whitted ray tree of one primary ray, depth first with an explicit
    # stack (scratch.rays, columns RayColumn); pushing refraction before
    # reflection reproduces the recursive order (reflection subtree first).
    # Returns the colour and the position after the sample's last record.
    # With params.log_ray_data the tracer's own data is logged too: a push
    # writes a ray-stack entry and a pop reads it; tracing a stacked ray
    # writes the hit record of its depth, shading reads it, writes the
    # level's shading temporaries, reads them for every shadow ray and once
    # more to add the colour up.
    rec, limit = log
    cnt = scratch.counters
    rays = scratch.rays
    eps = params.epsilon
    own = params.log_ray_data
    shadow_anyhit = params.shadow_anyhit
    mats = shading.materials
    lights = shading.lights
    ambient = shading.ambient
    background = shading.background
    material_texture = shading.material_texture
    cr = 0.0
    cg = 0.0
    cb = 0.0
    n = _push_ray(rays, 0, primary, (1.0, 1.0, 1.0), 1.0, RayType.PRIMARY, (0.0, params.pixel_spread))
    if own:
        pos = _log_access(rec, limit, pos, cnt, Counter.RAY_STACK_ACCESSES,
                          make_write_record(RecordKind.RAY_STACK, 0))
    n_lights = lights.shape[0]
    while n > 0:
        n -= 1
        if own:
            pos = _log_access(rec, limit, pos, cnt, Counter.RAY_STACK_ACCESSES, make_record(RecordKind.RAY_STACK, n))
        rox, roy, roz = rays[n, RayColumn.ORIGIN], rays[n, RayColumn.ORIGIN + 1], rays[n, RayColumn.ORIGIN + 2]
        rdx = rays[n, RayColumn.DIRECTION]
        rdy = rays[n, RayColumn.DIRECTION + 1]
        rdz = rays[n, RayColumn.DIRECTION + 2]
        wr, wg, wb = rays[n, RayColumn.WEIGHT], rays[n, RayColumn.WEIGHT + 1], rays[n, RayColumn.WEIGHT + 2]
        depth = np.int64(rays[n, RayColumn.DEPTH])
        typ = np.int64(rays[n, RayColumn.TYPE])
        spread = rays[n, RayColumn.CONE_SPREAD]
        tmin = params.hither if typ == RayType.PRIMARY else eps
        rays_counter, hits_counter = _ray_counters(typ)
        cnt[rays_counter] += 1
        t, e, pos = traverse(tree, geo, Ray(rox, roy, roz, rdx, rdy, rdz), tmin, np.inf, False,
                             log, pos, cnt, scratch.stack)
        level = depth - 1
        if own:
            pos = _log_access(rec, limit, pos, cnt, Counter.HIT_RECORD_ACCESSES,
                              make_write_record(RecordKind.HIT_RECORD, level))
        if e < 0:
            cr += wr * background[0]
            cg += wg * background[1]
            cb += wb * background[2]
            continue
        cnt[hits_counter] += 1
        if own:
            pos = _log_access(rec, limit, pos, cnt, Counter.HIT_RECORD_ACCESSES, make_record(RecordKind.HIT_RECORD, level))
            pos = _log_access(rec, limit, pos, cnt, Counter.SHADING_TEMP_ACCESSES,
                              make_write_record(RecordKind.SHADING_TEMP, level))
        hx, hy, hz = rox + t * rdx, roy + t * rdy, roz + t * rdz
        cone_width = rays[n, RayColumn.CONE_WIDTH] + spread * t
        k = np.int64(geo.element_kind[e])
        nx, ny, nz = element_normal(k, geo.element_index[e], geo, hx, hy, hz)
        m = shading.element_material[e]
        if pos < limit:
            rec[pos] = make_record(RecordKind.MATERIAL, m)
        pos += 1
        cnt[Counter.SHADING] += 1
        mr, mg, mb = mats[m, MaterialColumn.COLOR], mats[m, MaterialColumn.COLOR + 1], mats[m, MaterialColumn.COLOR + 2]
        kd, ks = mats[m, MaterialColumn.KD], mats[m, MaterialColumn.KS]
        shine, tr, ior = mats[m, MaterialColumn.SHINE], mats[m, MaterialColumn.TRANSMIT], mats[m, MaterialColumn.IOR]
        if material_texture[m] >= 0:
            tex_r, tex_g, tex_b, pos = texture_colour(shading, m, k, e, geo, (hx, hy, hz),
                                                       (cone_width, rdx * nx + rdy * ny + rdz * nz), log, pos, cnt)
            mr *= tex_r
            mg *= tex_g
            mb *= tex_b
        lr = ambient * kd * mr
        lg = ambient * kd * mg
        lb = ambient * kd * mb
        for li in range(n_lights):
            if pos < limit:
                rec[pos] = make_record(RecordKind.LIGHT, li)
            pos += 1
            cnt[Counter.LIGHT_READS] += 1
            lx = lights[li, LightColumn.POSITION] - hx
            ly = lights[li, LightColumn.POSITION + 1] - hy
            lz = lights[li, LightColumn.POSITION + 2] - hz
            dist = math.sqrt(lx * lx + ly * ly + lz * lz)
            if dist == 0.0:
                continue
            lx, ly, lz = lx / dist, ly / dist, lz / dist
            ndl = nx * lx + ny * ly + nz * lz
            if ndl <= 0.0:
                continue
            cnt[Counter.SHADOW_RAYS] += 1
            if own:
                pos = _log_access(rec, limit, pos, cnt, Counter.SHADING_TEMP_ACCESSES,
                                  make_record(RecordKind.SHADING_TEMP, level))
            ts, es, pos = traverse(tree, geo, Ray(hx, hy, hz, lx, ly, lz), eps, dist, shadow_anyhit,
                                   log, pos, cnt, scratch.stack)
            if es >= 0:
                cnt[Counter.SHADOW_BLOCKED] += 1
                continue
            diff = kd * ndl
            spec = 0.0
            if ks > 0.0:
                # Phong: R = 2 (N.L) N - L against V = -d
                rv = -((2.0 * ndl * nx - lx) * rdx + (2.0 * ndl * ny - ly) * rdy + (2.0 * ndl * nz - lz) * rdz)
                if rv > 0.0:
                    spec = ks * rv ** shine
            lr += lights[li, LightColumn.COLOR] * (diff * mr + spec)
            lg += lights[li, LightColumn.COLOR + 1] * (diff * mg + spec)
            lb += lights[li, LightColumn.COLOR + 2] * (diff * mb + spec)
        if own:
            pos = _log_access(rec, limit, pos, cnt, Counter.SHADING_TEMP_ACCESSES,
                              make_record(RecordKind.SHADING_TEMP, level))
        cr += wr * lr
        cg += wg * lg
        cb += wb * lb
        if depth >= params.max_depth:
            continue
        ddn = rdx * nx + rdy * ny + rdz * nz
        # the secondary rays' cone: a sphere's curvature spreads it (ray cones,
        # Akenine-Moller et al. 2019), a plane keeps its spread
        if k == ElementKind.SPHERE:
            spread += 2.0 * cone_width / geo.sphere_radius[geo.element_index[e]]
        cone = (cone_width, spread)
        if tr > 0.0:
            # Snell; entering when the ray meets the front of the normal
            if ddn < 0.0:
                eta = 1.0 / ior
                cosi = -ddn
                fx, fy, fz = nx, ny, nz
            else:
                eta = ior
                cosi = ddn
                fx, fy, fz = -nx, -ny, -nz
            k2 = 1.0 - eta * eta * (1.0 - cosi * cosi)
            if k2 >= 0.0:
                c2 = eta * cosi - math.sqrt(k2)
                refracted = Ray(hx, hy, hz, eta * rdx + c2 * fx, eta * rdy + c2 * fy, eta * rdz + c2 * fz)
                if own:
                    pos = _log_access(rec, limit, pos, cnt, Counter.RAY_STACK_ACCESSES,
                                      make_write_record(RecordKind.RAY_STACK, n))
                n = _push_ray(rays, n, _normalized(refracted),
                              (wr * tr, wg * tr, wb * tr), depth + 1, RayType.REFRACTION, cone)
        if ks > 0.0:
            reflected = Ray(hx, hy, hz, rdx - 2.0 * ddn * nx, rdy - 2.0 * ddn * ny, rdz - 2.0 * ddn * nz)
            if own:
                pos = _log_access(rec, limit, pos, cnt, Counter.RAY_STACK_ACCESSES,
                                  make_write_record(RecordKind.RAY_STACK, n))
            n = _push_ray(rays, n, _normalized(reflected),
                          (wr * ks, wg * ks, wb * ks), depth + 1, RayType.REFLECTION, cone)
    return cr, cg, cb, pos


@njit(cache=True, error_model="numpy")
def _trace_chunk(p0, p1, log, pos, cam, params, tree, geo, shading, out):
    # samples p0..p1 one after another, records from log.records[pos] on
    # (stored while below log.limit); returns the position after the last
    # record. (A separate function: inside a prange body numba's copy
    # propagation merged ``first = pos`` with the updated ``pos``.)
    scratch = SampleScratch(np.zeros(out.counters.shape[1], np.int64), new_stack(),
                            np.empty((2 * params.max_depth + 2, N_RAY_COLUMNS)))
    return _trace_samples(SampleRange(p0, p1), log, pos, cam, params, tree, geo, shading, out, scratch)


@njit(cache=True, error_model="numpy", **NO_REFCOUNTS)
def _trace_samples(samples, log, pos, cam, params, tree, geo, shading, out, scratch):
    # the loop over the samples of _trace_chunk, with _trace_sample and its traversals inlined and
    # without reference counting: a call per sample or per ray that passed the bundles of arrays cost
    # more than most rays' traversal (rtcommon.jit.NO_REFCOUNTS)
    cnt = scratch.counters
    sx = np.int64(cam.samples_x)
    for p in range(samples.first, samples.stop):
        i = p % sx
        j = p // sx
        u = (i - cam.cx) * cam.pitch
        v = (cam.cy - j) * cam.pitch
        dx = cam.forward[0] + u * cam.right[0] + v * cam.up[0]
        dy = cam.forward[1] + u * cam.right[1] + v * cam.up[1]
        dz = cam.forward[2] + u * cam.right[2] + v * cam.up[2]
        ln = math.sqrt(dx * dx + dy * dy + dz * dz)
        cnt[:] = 0
        first = pos
        r, g, b, pos = _trace_sample(Ray(cam.eye[0], cam.eye[1], cam.eye[2], dx / ln, dy / ln, dz / ln), params, tree, geo, shading, log, pos, scratch)
        if params.log_ray_data:
            pos = _log_access(log.records, log.limit, pos, cnt, Counter.PIXEL_WRITES,
                              make_write_record(RecordKind.FRAME_BUFFER, p))
        out.image[p, 0] = r
        out.image[p, 1] = g
        out.image[p, 2] = b
        for column in range(cnt.shape[0]):  # a slice assignment would allocate (it checks for overlap)
            out.counters[p, column] = cnt[column]
        out.counts[p] = pos - first
    return pos


@njit(parallel=True, cache=True, error_model="numpy")
def render_kernel(work, records, cam, params, tree, geo, shading, out):
    # every work item (see WorkItems) traced into its slot of records.
    # Writes go to arrays taken out of their bundle first, by attribute:
    # numba drops a prange body's stores into ``bundle.array[i]``, and into
    # arrays unpacked from the bundle.
    used = work.used
    for k in prange(work.start.shape[0]):
        p0 = work.start[k]
        log = RecordLog(records, work.base[k] + work.capacity[k])
        end = _trace_chunk(p0, min(params.n_samples, p0 + CHUNK), log, work.base[k], cam, params, tree, geo,
                           shading, out)
        used[k] = end - work.base[k]
