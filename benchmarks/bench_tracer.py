"""Tracer speed: rays/s with and without access logging, Embree as the anchor,
and per paper scene trace time, records and bytes per record.

Run:  python3 benchmarks/bench_tracer.py [--size 512] [--scenes balls,tetra,...]

Embree (embreex) is optional: install it into its own folder with
``pip install --target /tmp/embree embreex`` (or set EMBREEX_PATH); without it
the anchor is skipped with a message. The last line printed is one JSON
object with every figure.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time

import numba
import numpy as np

from tracer.kd.tree import build_kdtree
from tracer.rendering.camera import camera_rays
from tracer.kd.closest import closest_hit
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import PAPER_SCENES, load
from tracer.scenes.study import STUDY_SCENES
from tracer.trace.check import ARRAY_FILES


def _study_tests_1e6(name: str) -> float:
    """The study's intersection tests of scene ``name``, in millions (NaN for a scene it did not run)."""
    return STUDY_SCENES[name].tests_1e6 if name in STUDY_SCENES else float("nan")


def _one_core():
    numba.set_num_threads(1)
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpus[0]})
        return cpus
    return None


def _restore(cpus):
    if cpus is not None:
        os.sched_setaffinity(0, set(cpus))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def _tessellate_spheres(centres, radii, rings=6, segments=12):
    # UV spheres: rings x segments quads, two triangles each (poles degenerate
    # into single triangles but keep the count simple)
    th = np.linspace(0, np.pi, rings + 1)
    ph = np.linspace(0, 2 * np.pi, segments + 1)
    unit = np.stack(np.meshgrid(th, ph, indexing="ij"), -1)
    pts = np.stack([np.sin(unit[..., 0]) * np.cos(unit[..., 1]),
                    np.sin(unit[..., 0]) * np.sin(unit[..., 1]),
                    np.cos(unit[..., 0])], -1)
    a, b = pts[:-1, :-1], pts[1:, :-1]
    c, d = pts[1:, 1:], pts[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                           np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    out = centres[:, None, None, :] + radii[:, None, None, None] * tris[None]
    return out.reshape(-1, 3, 3)


def embree_rate(scene, size):
    path = os.environ.get("EMBREEX_PATH", "/tmp/embree")
    if os.path.isdir(path) and path not in sys.path:
        sys.path.append(path)  # appended: our own numpy stays first
    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh
    except ImportError as error:
        print(f"embree anchor skipped: embreex not importable ({error}); "
              f"pip install --target /tmp/embree embreex", file=sys.stderr)
        return None
    tris = [_tessellate_spheres(scene.sphere_center, np.abs(scene.sphere_radius))]
    if len(scene.triangle_vertices):
        tris.append(scene.triangle_vertices)
    for k in range(len(scene.polygon_offsets) - 1):  # fan-triangulate polygons
        v = scene.polygon_vertices[scene.polygon_offsets[k]:scene.polygon_offsets[k + 1]]
        tris.append(np.stack([np.repeat(v[:1], len(v) - 2, 0), v[1:-1], v[2:]], 1))
    tris = np.concatenate(tris).astype(np.float32)
    origin, dirs = camera_rays(scene, size=size)
    d = dirs.reshape(-1, 3).astype(np.float32)
    o = np.broadcast_to(origin.astype(np.float32), d.shape).copy()
    t0 = time.perf_counter()
    es = rtcs.EmbreeScene()
    TriangleMesh(es, tris)
    es.run(o[:1], d[:1])  # commit/build
    build = time.perf_counter() - t0
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        prim = es.run(o, d)
        best = min(best, time.perf_counter() - t0)
    return {"triangles": int(len(tris)), "build_seconds": build, "primary_rays_per_second": len(d) / best,
            "primary_hit_fraction": float(np.mean(np.asarray(prim) >= 0))}


def _primary_seconds(scene, tree, size):
    """Seconds of closest_hit for the primary rays alone, as Embree traces them (compiled first; best of 3,
    as Embree's own figure is)."""
    origin, dirs = camera_rays(scene, size=size)
    d = dirs.reshape(-1, 3)
    o = np.broadcast_to(origin, d.shape)
    closest_hit(scene, tree, o[:8], d[:8])
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        closest_hit(scene, tree, o, d)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--scenes", default=",".join(PAPER_SCENES))
    args = parser.parse_args(argv)
    size = args.size
    figures = {"size": size, "numba_threads_default": numba.config.NUMBA_NUM_THREADS}

    # --- one core: balls with and without logging, and Embree
    balls = load("balls")
    tree = build_kdtree(balls)
    render(balls, tree, RenderOptions(size=8, log=True))  # compile (or load from cache)
    cpus = _one_core()
    try:
        t0 = time.perf_counter()
        plain = render(balls, tree, RenderOptions(size=size, log=False))
        t_plain = time.perf_counter() - t0
        rays = plain.totals()["rays"]
        t0 = time.perf_counter()
        logged = render(balls, tree, RenderOptions(size=size, log=True))
        t_log_first = time.perf_counter() - t0  # the first logged pass also faults in its buffers
        del logged
        t0 = time.perf_counter()
        logged = render(balls, tree, RenderOptions(size=size, log=True))
        t_log = min(t_log_first, time.perf_counter() - t0)
        t_prim = _primary_seconds(balls, tree, size)
        emb = embree_rate(balls, size)
        tetra = load("tetra")
        tetra_prim = size * size / _primary_seconds(tetra, build_kdtree(tetra), size)
        tetra_emb = embree_rate(tetra, size)
    finally:
        _restore(cpus)
    one = {"rays": rays, "seconds_no_log": t_plain, "rays_per_second_no_log": rays / t_plain,
           "seconds_log": t_log, "rays_per_second_log": rays / t_log,
           "rays_per_second_log_first_pass": rays / t_log_first,
           "records": logged.trace.n_records,
           "primary_only_rays_per_second": size * size / t_prim,
           "embree": emb}
    if emb:
        one["embree_over_ours_primary"] = emb["primary_rays_per_second"] / (size * size / t_prim)
    figures["balls_one_core"] = one
    print(f"balls {size}^2 on one core: {rays / t_plain / 1e6:.2f} M rays/s without logging, "
          f"{rays / t_log / 1e6:.2f} M with (best of 2; the first pass {rays / t_log_first / 1e6:.2f} M; "
          f"target >= 1 M); primary-only {size * size / t_prim / 1e6:.2f} M rays/s"
          + (f"; Embree primary {emb['primary_rays_per_second'] / 1e6:.2f} M rays/s "
             f"({emb['triangles']} triangles)" if emb else "; Embree skipped"))
    del logged, plain
    figures["tetra_one_core"] = {"primary_only_rays_per_second": tetra_prim, "embree": tetra_emb}
    if tetra_emb:
        figures["tetra_one_core"]["embree_over_ours_primary"] = tetra_emb["primary_rays_per_second"] / tetra_prim
    for name, ours, peer in (("balls", size * size / t_prim, emb), ("tetra", tetra_prim, tetra_emb)):
        if peer:
            print(f"{name} primary rays, one core: ours {ours / 1e6:.2f} M/s, Embree {peer['primary_rays_per_second'] / 1e6:.2f}"
                  f" M/s: {peer['primary_rays_per_second'] / ours:.2f}x (target <= 4x)")

    # --- every paper scene, all cores, with logging, trace written to disk
    figures["scenes"] = {}
    tmp = tempfile.mkdtemp(prefix="bench-tracer-")
    try:
        print(f"{'scene':<7}{'elements':>9}{'rays':>11}{'trace s':>9}{'records':>14}{'B/rec':>7}"
              f"{'tests/ray':>10}{'nodes/ray':>10}{'tests 1e6':>10}{'study 1e6':>10}")
        for name in [n for n in args.scenes.split(",") if n]:
            scene = load(name)
            t0 = time.perf_counter()
            tree = build_kdtree(scene)
            build = time.perf_counter() - t0
            render(scene, tree, RenderOptions(size=4, log=True))
            t0 = time.perf_counter()
            res = render(scene, tree, RenderOptions(size=size, log=True, memory_budget=512 << 20),
                         trace_path=os.path.join(tmp, name))
            seconds = time.perf_counter() - t0
            t = res.totals()
            files = sum(os.path.getsize(os.path.join(tmp, name, f)) for f in os.listdir(os.path.join(tmp, name)))
            rec_bytes = os.path.getsize(os.path.join(tmp, name, ARRAY_FILES["records"]))
            row = {"elements": scene.n_elements, "max_depth": scene.max_depth, "rays": t["rays"],
                   "rays_by_type": {k: t[k] for k in ("primary_rays", "shadow_rays", "reflection_rays", "refraction_rays")},
                   "build_seconds": build, "trace_seconds": seconds, "timings": res.timings,
                   "records": t["records"], "bytes_per_record": rec_bytes / max(t["records"], 1),
                   "trace_bytes_per_record_all_files": files / max(t["records"], 1),
                   "intersection_tests": t["intersection_tests"], "node_visits": t["node_visits"],
                   "tests_per_ray": t["intersection_tests"] / t["rays"],
                   "node_visits_per_ray": t["node_visits"] / t["rays"],
                   "study_tests": _study_tests_1e6(name) * 1e6,
                   "tree": res.tree.stats}
            figures["scenes"][name] = row
            print(f"{name:<7}{scene.n_elements:>9}{t['rays']:>11,}{seconds:>9.2f}{t['records']:>14,}"
                  f"{row['bytes_per_record']:>7.2f}{row['tests_per_ray']:>10.1f}{row['node_visits_per_ray']:>10.1f}"
                  f"{t['intersection_tests'] / 1e6:>10.1f}{_study_tests_1e6(name):>10.1f}")
            del res
            shutil.rmtree(os.path.join(tmp, name), ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(figures, default=float))


if __name__ == "__main__":
    main()
