"""``coherence render``: render a scene once and log every scene access per pixel."""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

from analyses.commands.options import (HelpFormatter, check_at_least, scene_options, size_options, tree_options,
                                       workload_from_args, workload_options)
from rtcommon.files import write_bytes_atomic
from rtcommon.validate import InputError

HELP = "render a scene with the instrumented ray tracer; report rays, tests, node visits, records"

EPILOG = """\
SCENE is one of the study's scenes (built in memory with the paper's maximum
depth) or a path to a .nff or .obj file.

The renderer shoots one ray per pixel centre (or, with --corner-rays, a
(W+1) x (H+1) grid through the pixel corners, as SPD's published counts do),
shades by Whitted's rules with shadow, reflection and refraction rays, and
with --trace writes the ordered list of scene records every pixel read
(kd-tree nodes, leaf index entries, primitives tested, materials, lights):
the input of every later cache replay. Progress goes to stderr, results to
stdout.

examples:
  coherence render tetra --size 128 --png tetra.png
  coherence render balls --trace traces/balls-512
  coherence render shell --kd median --json
  coherence render balls --workload study1997 --no-log
  coherence render balls --workload pathtrace --spp 4 --max-depth 4 --size 64 --trace traces/balls-pt
  coherence render /work/shared/reference/spd/balls.nff --corner-rays --max-depth 5 --epsilon spd

The last example counts rays the way SPD's published figures do (Havran 1999:
balls 959,244 shadow and 179,884 reflection rays); --epsilon spd ignores hits
within 0.01 of a secondary ray's origin, the tolerance those figures imply.
"""


def register(subparsers) -> None:
    """Add the ``render`` subcommand to ``subparsers``."""
    parser = subparsers.add_parser(
        "render", help=HELP, description=HELP[0].upper() + HELP[1:] + ".", epilog=EPILOG,
        formatter_class=HelpFormatter, parents=[scene_options(), size_options(),
                                                    tree_options(kd_default=None, kd_why="the workload's"),
                                                    workload_options()])
    parser.add_argument("--png", metavar="PATH", help="save the image as PNG")
    parser.add_argument("--trace", metavar="DIR",
                        help="save the access trace to directory DIR (atomically)")
    parser.add_argument("--corner-rays", action="store_true",
                        help="trace (N+1)^2 rays through pixel corners (SPD counting)")
    parser.add_argument("--epsilon", type=_epsilon, metavar="E", default=None,
                        help="ignore hits closer than E (scene units) to the origin of a "
                             "reflection, refraction or shadow ray; 'spd' = 0.01, which "
                             "reproduces SPD's published counts (default: 1e-8 of the "
                             "scene's diagonal)")
    parser.add_argument("--no-log", action="store_true",
                        help="render without logging accesses (faster; no --trace)")
    parser.add_argument("--memory-budget", type=float, metavar="MB", default=1024.0,
                        help="memory for the records of one logging batch, in MB (default 1024); the records "
                             "go to --trace DIR in chunks, or without --trace are only counted")
    parser.add_argument("--texture-filter", choices=("trilinear", "bilinear", "nearest"), default="trilinear",
                        help="how textured surfaces filter their texels (default: trilinear; the level of "
                             "detail comes from ray cones)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=run)


def _epsilon(text: str) -> float:
    from tracer.rendering.render import SPD_EPSILON

    if text.strip().lower() == "spd":
        return SPD_EPSILON
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive distance or 'spd', got {text!r}") from None
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a positive finite distance or 'spd', got {text!r}")
    return value


def _png_bytes(image) -> bytes:
    """The PNG that ``tracer.rendering.render.save_png`` writes, as bytes (written atomically by the caller)."""
    import io

    import matplotlib.pyplot as plt
    import numpy as np

    buffer = io.BytesIO()
    plt.imsave(buffer, np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0), format="png")
    return buffer.getvalue()


def _load_scene(name: str, max_depth):
    try:
        from tracer.scenes.catalog import load
    except ImportError as error:  # pragma: no cover - scenes module missing
        raise InputError(f"cannot load scene {name!r}: tracer.scenes.catalog is unavailable ({error})") from None
    return load(name, max_depth=max_depth)


def report(result, scene_name: str, seconds: float) -> dict:
    """The figures ``coherence render`` prints, as a JSON-serialisable dict."""
    t = result.totals()
    rays = max(t["rays"], 1)
    out = {
        "scene": scene_name,
        "width": result.width, "height": result.height,
        "rays": {"primary": t["primary_rays"], "shadow": t["shadow_rays"],
                 "reflection": t["reflection_rays"], "refraction": t["refraction_rays"],
                 "total": t["rays"]},
        "hits": {"primary": t["primary_hits"], "reflection": t["reflection_hits"],
                 "refraction": t["refraction_hits"], "shadow_blocked": t["shadow_blocked"]},
        "intersection_tests": {k[6:]: t[k] for k in t if k.startswith("tests_")},
        "node_visits": t["node_visits"], "leaf_visits": t["leaf_visits"],
        "index_reads": t["index_reads"], "shading": t["shading"], "light_reads": t["light_reads"],
        "root_tests": t["root_tests"],
        "per_ray": {"tests": t["intersection_tests"] / rays, "node_visits": t["node_visits"] / rays},
        "records": t.get("records"),
        "bytes_per_record": 4 if result.n_records is not None else None,
        "epsilon": result.epsilon,
        "tree": result.tree.stats, "kd_config": result.tree.config.to_dict(), "workload": result.workload,
        "timings": result.timings, "seconds": seconds,
    }
    out["intersection_tests"]["total"] = t["intersection_tests"]
    if t["texture_lookups"]:  # textured scenes only, so untextured output stays as it was
        out["textures"] = {"lookups": t["texture_lookups"], "texel_reads": t["texel_reads"],
                           "filter": result.texture_filter}
    return out


def _table(rep: dict) -> str:
    r, h, it = rep["rays"], rep["hits"], rep["intersection_tests"]
    lines = [f"scene {rep['scene']}: {rep['width']}x{rep['height']} samples, "
             f"workload {rep['workload']['name']}, "
             f"kd {rep['kd_config']['builder']} ({rep['tree']['nodes']} nodes, depth {rep['tree']['depth']})", "",
             f"  {'rays':<22}{'count':>14}{'hits':>14}"]
    lines.append(f"  {'primary':<22}{r['primary']:>14,}{h['primary']:>14,}")
    lines.append(f"  {'shadow (blocked)':<22}{r['shadow']:>14,}{h['shadow_blocked']:>14,}")
    lines.append(f"  {'reflection':<22}{r['reflection']:>14,}{h['reflection']:>14,}")
    lines.append(f"  {'refraction':<22}{r['refraction']:>14,}{h['refraction']:>14,}")
    lines.append(f"  {'total':<22}{r['total']:>14,}")
    lines.append("")
    for kind, n in it.items():
        if n or kind == "total":
            lines.append(f"  {'tests ' + kind:<22}{n:>14,}")
    lines.append(f"  {'node visits':<22}{rep['node_visits']:>14,}")
    lines.append(f"  {'per ray':<22}{rep['per_ray']['tests']:>14.2f} tests {rep['per_ray']['node_visits']:.2f} nodes")
    if "textures" in rep:
        lines.append(f"  {'texture lookups':<22}{rep['textures']['lookups']:>14,}")
        lines.append(f"  {'texel reads':<22}{rep['textures']['texel_reads']:>14,}")
    if rep["records"] is not None:
        lines.append(f"  {'records':<22}{rep['records']:>14,}  ({rep['bytes_per_record']} bytes each)")
    lines.append(f"  {'time':<22}{rep['seconds']:>14.2f} s")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from analyses.commands import checks
    from tracer.kd.tree import KdTreeConfig
    from tracer.rendering.render import RenderOptions, render

    # every user error surfaces here, before the scene is built or a ray is traced
    check_at_least(args, size=1)
    checks.check_max_depth(args.max_depth)
    if args.no_log and args.trace:
        raise InputError("--trace needs logging; drop --no-log")
    if not args.memory_budget > 0 or args.memory_budget != args.memory_budget:
        raise InputError(f"--memory-budget must be > 0 MB, got {args.memory_budget}")
    budget = max(4, int(min(args.memory_budget, 2.0 ** 50) * 2**20))
    if args.png:
        checks.check_output_file("--png", args.png)
        if Path(args.png).suffix.lower() != ".png":
            raise InputError(f"--png {args.png!r} must end in .png (the image is written as PNG)")
    if args.trace:
        checks.check_trace_folder("--trace", args.trace)
    checks.check_scene_argument(args.scene)
    workload = workload_from_args(args)
    samples = args.size + 1 if args.corner_rays else args.size
    # without --trace the records are counted, not kept: no trace is held in memory
    checks.check_memory("--size", samples, bytes_per_pixel=checks.RENDER_BYTES_PER_PIXEL)
    print(f"loading {args.scene} ...", file=sys.stderr)
    scene = _load_scene(args.scene, args.max_depth)
    kd_config = KdTreeConfig(builder=args.kd) if args.kd else None
    options = RenderOptions(size=args.size, corner_rays=args.corner_rays, log=not args.no_log,
                            keep_records=args.trace is not None, kd_config=kd_config, memory_budget=budget,
                            epsilon=args.epsilon, workload=workload, texture_filter=args.texture_filter,
                            spp=1 if args.spp is None else args.spp, seed=0 if args.seed is None else args.seed)
    tree = None
    if args.trace:
        pilot = render(scene, options=replace(options, size=checks.PILOT_SIZE, corner_rays=False,
                                              keep_records=False))
        per_sample = 4 * pilot.n_records / (pilot.width * pilot.height)
        checks.check_disk("--trace", args.trace, int(1.25 * per_sample * samples * samples))
        tree = pilot.tree
        del pilot
    print(f"rendering {scene.name} at {args.size}x{args.size} "
          f"({'with' if not args.no_log else 'without'} access logging) ...", file=sys.stderr)
    start = time.perf_counter()
    result = render(scene, tree, options, trace_path=args.trace,
                    metadata={"command": "coherence render " + " ".join(sys.argv[2:])})
    seconds = time.perf_counter() - start
    if args.png:
        write_bytes_atomic(args.png, _png_bytes(result.image))
        print(f"wrote {args.png}", file=sys.stderr)
    if args.trace:
        print(f"wrote trace {args.trace}", file=sys.stderr)
    rep = report(result, scene.name, seconds)
    print(json.dumps(rep, indent=1) if args.json else _table(rep))
    return 0
