"""``coherence scene``: what a scene holds, and conversion to NFF."""
from __future__ import annotations

import argparse
import json
import sys

from analyses.commands.options import HelpFormatter, scene_options

HELP = "summarise a paper scene or an NFF/OBJ file; optionally write it as NFF"

EPILOG = """\
SCENE is one of the study's scenes, built in memory with the paper's maximum
depth, or a path to a .nff or .obj file:

  balls  SPD sphereflake, 7382 elements (spheres + floor quad), depth 2
  tetra  SPD Sierpinski tetrahedron, 4096 triangles, depth 2
  shell  SPD Pickover seashell, 5761 spheres, depth 2
  room   CAAD-style interior stand-in, 7786 polygons/triangles, depth 4
  fluid  crown-splash stand-in, 2899 spheres, depth 5

NFF files keep the depth of their '# max_depth N' comment (else 5, the SPD
procedure's); OBJ meshes get depth 5 and a camera and light that frame them.

examples:
  coherence scene room
  coherence scene balls --json
  coherence scene shell --max-depth 5 --nff-out shell.nff
  coherence scene mymesh.obj --nff-out mymesh.nff
"""


def register(subparsers) -> None:
    """Add the ``scene`` subcommand to ``subparsers``."""
    parser = subparsers.add_parser(
        "scene", help=HELP, description=HELP[0].upper() + HELP[1:] + ".", epilog=EPILOG,
        formatter_class=HelpFormatter, parents=[scene_options()])
    parser.add_argument("--max-depth", type=int, metavar="N", default=None,
                        help="maximum recursion depth (default: the paper's for a named "
                             "scene, the file's for a path)")
    parser.add_argument("--nff-out", metavar="PATH", default=None,
                        help="also write the scene as NFF to PATH (atomically)")
    parser.add_argument("--json", action="store_true",
                        help="print the summary as JSON instead of a table")
    parser.set_defaults(func=run)


def _vector(values) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


def format_summary(summary: dict) -> str:
    """The summary of :meth:`tracer.scenes.model.Scene.summary` as a readable table."""
    lines = [f"scene {summary['name']}: {summary['elements']} elements, "
             f"{summary['lights']} lights, max depth {summary['max_depth']}", ""]
    lines.append(f"  {'primitive':<10} {'count':>8}")
    for kind, count in summary["counts"].items():
        lines.append(f"  {kind:<10} {count:>8}")
    lines.append(f"  {'total':<10} {summary['elements']:>8}")
    lines.append("")
    lines.append(f"  {'materials':<13} {summary['materials']}")
    lines.append(f"  {'lights':<13} {summary['lights']}")
    lines.append(f"  {'max depth':<13} {summary['max_depth']}")
    box = summary["bounding_box"]
    if box is None:
        lines.append(f"  {'bounding box':<13} (empty)")
    else:
        lines.append(f"  {'bounding box':<13} min {_vector(box['min'])}  max {_vector(box['max'])}")
    cam = summary["camera"]
    lines.append(f"  {'camera':<13} from {_vector(cam['eye'])} at {_vector(cam['look_at'])} "
                 f"up {_vector(cam['up'])}")
    lines.append(f"  {'':<13} angle {cam['angle']:g} deg, hither {cam['hither']:g}, "
                 f"{cam['resolution'][0]} x {cam['resolution'][1]} pixels")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from analyses.commands import checks
    from tracer.scenes.catalog import load

    # every user error surfaces here, before the scene is built
    checks.check_max_depth(args.max_depth)
    if args.nff_out is not None:
        checks.check_output_file("--nff-out", args.nff_out)
    checks.check_scene_argument(args.scene)
    # a summary needs the textures' sizes, not their texels
    scene = load(args.scene, max_depth=args.max_depth, texels=args.nff_out is not None)
    summary = scene.summary()
    if args.nff_out is not None:
        from tracer.scenes.nff import write_nff

        write_nff(scene, args.nff_out)
        summary["nff_out"] = str(args.nff_out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
        if args.nff_out is not None:
            print(f"\nwrote {args.nff_out}")
    sys.stdout.flush()
    return 0
