"""NFF reading speed: ``read_nff`` against a plain split-and-float pass over the same file.

The peer is the least any reader must do: read the file, split it on
whitespace and convert every token that is a number to a float. The reader
also strips comments, checks number syntax and the view, builds the scene
arrays, and checks every polygon for degeneracy and planarity. Prints, per
file, both times (best of 5) and their ratio.

Files: the SPD references beside DESIGN.md (gears, tetra, balls, shells) and,
as a patch-heavy stand-in for SPD teapot (not in the references), a sphere
tessellated into ``pp 3`` triangles written to a temporary folder.

    python benchmarks/bench_nff.py [FILE.nff ...]
"""
import sys
import tempfile
from pathlib import Path

import numpy as np

from timing import best_of
from tracer.scenes.nff import read_nff

REFERENCE = Path("/work/shared/reference/spd")


def plain_pass(path: Path) -> int:
    numbers = 0
    for token in path.read_text().split():
        try:
            float(token)
            numbers += 1
        except ValueError:
            pass
    return numbers


def patch_sphere(folder: Path, rings: int = 90, segments: int = 120) -> Path:
    """A unit sphere as ``pp 3`` patches with vertex normals (2 x rings x segments of them)."""
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    point = lambda t, p: np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    lines = ["v", "from 0 -4 1", "at 0 0 0", "up 0 0 1", "angle 40", "hither 0.01", "resolution 512 512",
             "l 3 -3 3", "f 0.8 0.4 0.2 0.7 0.3 10 0 1"]
    for i in range(rings):
        for j in range(segments):
            a, b = point(theta[i], phi[j]), point(theta[i + 1], phi[j])
            c, d = point(theta[i + 1], phi[j + 1]), point(theta[i], phi[j + 1])
            for triangle in ((a, b, c), (a, c, d)):
                if min(np.linalg.norm(np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])), 1) < 1e-9:
                    continue
                lines.append("pp 3")
                lines.extend(" ".join(f"{x:.6g}" for x in (*v, *v)) for v in triangle)
    path = folder / "patch-sphere.nff"
    path.write_text("\n".join(lines) + "\n")
    return path


def main():
    files = [Path(arg) for arg in sys.argv[1:]]
    if not files:
        files = [REFERENCE / f"{name}.nff" for name in ("gears", "tetra", "balls", "shells")]
        files.append(patch_sphere(Path(tempfile.mkdtemp(prefix="bench-nff-"))))
    print(f"{'file':<20}{'MB':>6}{'read_nff s':>12}{'split+float s':>15}{'ratio':>8}")
    for path in files:
        read_nff(path)  # warm the imports
        reader, _ = best_of(5, lambda: read_nff(path))
        plain, _ = best_of(5, lambda: plain_pass(path))
        print(f"{path.name:<20}{path.stat().st_size / 1e6:>6.2f}{reader:>12.3f}{plain:>15.3f}{reader / plain:>8.2f}")


if __name__ == "__main__":
    main()
