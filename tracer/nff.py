"""Reading and writing scenes in Eric Haines's Neutral File Format (NFF).

NFF is parsed by whitespace-separated tokens, not by lines, because writers
differ in where they break lines (``c`` may put its two ends on one line or
two). ``#`` starts a comment to the end of the line. Directives:

==============================  ==============================================
``v``                           start of the view, followed by any of
                                ``from x y z``, ``at x y z``, ``up x y z``,
                                ``angle deg``, ``hither d``,
                                ``resolution w h``; the view precedes objects
``b r g b``                     background colour
``l x y z [r g b]``             point light, white without a colour
``f r g b Kd Ks shine T ior``   material of the objects that follow
``c bx by bz br ax ay az ar``   cone/cylinder without caps (negative radii:
                                inside visible)
``s x y z r``                   sphere
``p n`` + n vertices            planar polygon; 3 vertices make a TRIANGLE
                                element, more a POLYGON element
``pp n`` + n ``x y z nx ny nz`` polygon patch with vertex normals (PATCH)
==============================  ==============================================

NFF has no recursion depth. :func:`write_nff` records the scene's depth in a
comment line ``# max_depth N`` and the reader honours such a line; without it
the depth is the SPD procedure's 5 (the :class:`~tracer.scene.Scene` default).
:func:`tracer.scenes.load` applies the paper's depth per named scene instead.

Materials are deduplicated and numbered in order of first use (see
:class:`~tracer.scene.SceneBuilder`), which makes read -> write -> read exact:
the writer prints every number with the shortest representation that reads
back to the same float64.
"""
from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

import numpy as np

from tracer.scene import Camera, ElementKind, Material, Scene, SceneBuilder

__all__ = ["NFFError", "parse_nff", "read_nff", "write_nff"]

_TOKEN = re.compile(r"\S+")
_DEPTH_PRAGMA = re.compile(r"^\s*#\s*max_depth\s+(\d+)\s*$")
_VIEW_KEYWORDS = ("from", "at", "up", "angle", "hither", "resolution")
_OBJECT_KEYWORDS = ("c", "s", "p", "pp")
_KEYWORDS = ("v", *_VIEW_KEYWORDS, "b", "l", "f", *_OBJECT_KEYWORDS)


class NFFError(ValueError):
    """A malformed NFF file.

    Attributes
    ----------
    file : str
        Path or source name.
    line, column : int
        1-based position of the offending token (or of the end of the file).
    expected : str
        What the parser expected there.
    found : str or None
        The token found, ``None`` at the end of the file.
    """

    def __init__(self, file: str, line: int, column: int, expected: str, found: str | None):
        self.file = file
        self.line = line
        self.column = column
        self.expected = expected
        self.found = found
        what = "end of file" if found is None else repr(found)
        super().__init__(f"{file}:{line}:{column}: expected {expected}, found {what}")


class _Tokens:
    """Tokens of an NFF text with their 1-based line and column."""

    def __init__(self, text: str, source: str):
        self.source = source
        self.items: list[tuple[str, int, int]] = []
        self.max_depth: int | None = None
        lines = text.splitlines()
        for number, line in enumerate(lines, start=1):
            hash_at = line.find("#")
            if hash_at >= 0:
                pragma = _DEPTH_PRAGMA.match(line[hash_at:])
                if pragma and not line[:hash_at].strip():
                    self.max_depth = int(pragma.group(1))
                line = line[:hash_at]
            for match in _TOKEN.finditer(line):
                self.items.append((match.group(), number, match.start() + 1))
        last = lines[-1] if lines else ""
        self.end = (max(len(lines), 1), len(last) + 1)
        self.pos = 0

    def at_end(self) -> bool:
        return self.pos >= len(self.items)

    def error(self, expected: str, at: int | None = None) -> NFFError:
        """An NFFError at token ``at`` (default: the next token)."""
        at = self.pos if at is None else at
        if at >= len(self.items):
            return NFFError(self.source, *self.end, expected, None)
        token, line, column = self.items[at]
        return NFFError(self.source, line, column, expected, token)

    def next(self, expected: str) -> str:
        if self.at_end():
            raise self.error(expected)
        token = self.items[self.pos][0]
        self.pos += 1
        return token

    def number(self, expected: str) -> float:
        token = self.next(expected)
        try:
            value = float(token)
        except ValueError:
            value = float("nan")
        if not np.isfinite(value):
            raise self.error(expected, self.pos - 1)
        return value

    def numbers(self, count: int, expected: str) -> tuple[float, ...]:
        return tuple(self.number(expected) for _ in range(count))

    def integer(self, expected: str) -> int:
        token = self.next(expected)
        if not re.fullmatch(r"[+-]?\d+", token):
            raise self.error(expected, self.pos - 1)
        return int(token)


def _is_degenerate(vertices: np.ndarray) -> bool:
    """Zero area (Newell normal vanishes relative to the polygon's extent)."""
    shifted = np.roll(vertices, -1, axis=0)
    normal = np.array([
        np.sum((vertices[:, 1] - shifted[:, 1]) * (vertices[:, 2] + shifted[:, 2])),
        np.sum((vertices[:, 2] - shifted[:, 2]) * (vertices[:, 0] + shifted[:, 0])),
        np.sum((vertices[:, 0] - shifted[:, 0]) * (vertices[:, 1] + shifted[:, 1])),
    ])
    extent = float(np.max(np.ptp(vertices, axis=0)))
    return extent == 0.0 or float(np.linalg.norm(normal)) <= 1e-12 * extent * extent


def parse_nff(text: str, source: str = "<string>", *, name: str | None = None,
              max_depth: int | None = None) -> Scene:
    """Parse NFF text into a :class:`~tracer.scene.Scene`.

    Parameters
    ----------
    text : str
        The NFF document.
    source : str
        Name used in error messages (a path, or ``"<string>"``).
    name : str, optional
        Scene name; default the stem of ``source``.
    max_depth : int, optional
        Recursion depth; default the file's ``# max_depth N`` line, else 5.

    Returns
    -------
    Scene
        Elements numbered in file order.

    Raises
    ------
    NFFError
        On the first malformed token, with file, line, column and what was
        expected; no partial scene is returned.
    """
    tokens = _Tokens(text, source)
    if name is None:
        name = "scene" if source.startswith("<") else (Path(source).stem or "scene")
    builder = SceneBuilder(name)
    view: dict | None = None
    view_at = 0
    seen_object = False

    while not tokens.at_end():
        start = tokens.pos
        keyword = tokens.next("a keyword")
        if keyword in _OBJECT_KEYWORDS:
            seen_object = True
        if keyword == "v" or keyword in _VIEW_KEYWORDS:
            if seen_object:
                raise tokens.error("the view ('v ...') before the first object (view after objects)",
                                   start)
            if keyword == "v":
                view = {}
                view_at = start
                continue
            if view is None:
                raise tokens.error(f"'v' before the view parameter {keyword!r}", start)
        if keyword == "from":
            view["eye"] = tokens.numbers(3, "a number (x y z of 'from')")
        elif keyword == "at":
            view["look_at"] = tokens.numbers(3, "a number (x y z of 'at')")
        elif keyword == "up":
            view["up"] = tokens.numbers(3, "a number (x y z of 'up')")
        elif keyword == "angle":
            view["angle"] = tokens.number("a number (field of view in degrees)")
            if not 0.0 < view["angle"] < 180.0:
                raise tokens.error("an angle in (0, 180) degrees", tokens.pos - 1)
        elif keyword == "hither":
            view["hither"] = tokens.number("a number (hither distance)")
            if view["hither"] < 0.0:
                raise tokens.error("a hither distance >= 0", tokens.pos - 1)
        elif keyword == "resolution":
            width = tokens.integer("a positive integer (resolution width)")
            height = tokens.integer("a positive integer (resolution height)")
            if width < 1 or height < 1:
                raise tokens.error("a positive resolution", tokens.pos - 2)
            view["resolution"] = (width, height)
        elif keyword == "b":
            builder.background = tokens.numbers(3, "a number (r g b of the background)")
        elif keyword == "l":
            position = tokens.numbers(3, "a number (x y z of the light)")
            color = (1.0, 1.0, 1.0)
            if not tokens.at_end() and tokens.items[tokens.pos][0] not in _KEYWORDS:
                color = tokens.numbers(3, "a number (r g b of the light) or a keyword")
            builder.light(position, color)
        elif keyword == "f":
            values = tokens.numbers(8, "a number (f: r g b Kd Ks shine T ior)")
            builder.material(Material(values[:3], *values[3:]))
        elif keyword == "s":
            *center, radius = tokens.numbers(4, "a number (s: x y z radius)")
            if radius <= 0.0:
                raise tokens.error("a positive sphere radius", tokens.pos - 1)
            builder.sphere(center, radius)
        elif keyword == "c":
            values = tokens.numbers(8, "a number (c: base x y z r, apex x y z r)")
            if values[:3] == values[4:7]:
                raise tokens.error("a cone apex different from its base (degenerate cone)",
                                   tokens.pos - 4)
            builder.cone(values[:3], values[3], values[4:7], values[7])
        elif keyword in ("p", "pp"):
            count = tokens.integer(f"a vertex count after {keyword!r}")
            if count < 3:
                raise tokens.error("a polygon with at least 3 vertices (too few vertices)",
                                   tokens.pos - 1)
            per_vertex = 3 if keyword == "p" else 6
            what = "x y z" if keyword == "p" else "x y z nx ny nz"
            values = np.array(tokens.numbers(per_vertex * count,
                                             f"a number ({keyword} {count}: {count} x {what})"))
            values = values.reshape(count, per_vertex)
            if _is_degenerate(values[:, :3]):
                raise tokens.error("a polygon with non-zero area (degenerate polygon)", start)
            if keyword == "p":
                builder.polygon(values)
            else:
                builder.patch(values[:, :3], values[:, 3:])
        elif keyword not in ("v", *_VIEW_KEYWORDS):
            raise tokens.error("a keyword (one of " + ", ".join(_KEYWORDS) + ")", start)

    if view is not None:
        try:
            builder.camera = Camera(**view)
        except ValueError as error:
            raise tokens.error(f"a valid view ({error})", view_at) from None
    if max_depth is not None:
        builder.max_depth = int(max_depth)
    elif tokens.max_depth is not None:
        builder.max_depth = tokens.max_depth
    return builder.build()


def read_nff(path, *, max_depth: int | None = None) -> Scene:
    """Read an NFF file.

    Parameters
    ----------
    path : str or os.PathLike
        The file; the scene is named after its stem.
    max_depth : int, optional
        Recursion depth; default the file's ``# max_depth N`` comment, else 5
        (the SPD procedure's depth, not the paper's 2; use
        :func:`tracer.scenes.load` for the paper's depths).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    NFFError
        If the file is malformed.
    """
    path = Path(path)
    if not path.is_file():
        if path.exists():
            raise IsADirectoryError(f"not an NFF file: {str(path)!r}")
        raise FileNotFoundError(f"no such NFF file: {str(path)!r}")
    text = path.read_text(encoding="utf-8", errors="replace")
    return parse_nff(text, str(path), name=path.stem, max_depth=max_depth)


def _fmt(value) -> str:
    """Shortest text that reads back as the same float64."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _join(values) -> str:
    return " ".join(_fmt(v) for v in values)


def format_nff(scene: Scene) -> str:
    """The NFF text of ``scene`` (see :func:`write_nff`)."""
    cam = scene.camera
    out = [
        f"# {scene.name}: {scene.n_elements} elements, written by raytrace-coherence",
        f"# max_depth {int(scene.max_depth)}",
        "b " + _join(scene.background),
        "v",
        "from " + _join(cam.eye),
        "at " + _join(cam.look_at),
        "up " + _join(cam.up),
        "angle " + _fmt(cam.angle),
        "hither " + _fmt(cam.hither),
        f"resolution {cam.resolution[0]} {cam.resolution[1]}",
    ]
    for position, color in zip(scene.light_position, scene.light_color):
        if np.all(color == 1.0):
            out.append("l " + _join(position))
        else:
            out.append("l " + _join(position) + " " + _join(color))
    materials = np.column_stack([scene.material_color, scene.material_kd, scene.material_ks,
                                 scene.material_shine, scene.material_t, scene.material_ior])
    current = -1
    for kind, index, material in zip(scene.element_kind, scene.element_index,
                                     scene.element_material):
        if material != current:
            out.append("f " + _join(materials[material]))
            current = material
        if kind == ElementKind.SPHERE:
            out.append("s " + _join(scene.sphere_center[index]) + " "
                       + _fmt(scene.sphere_radius[index]))
        elif kind == ElementKind.TRIANGLE:
            out.append("p 3")
            out.extend(_join(v) for v in scene.triangle_vertices[index])
        elif kind == ElementKind.POLYGON:
            vertices = scene.polygon_vertices[scene.polygon_offsets[index]:
                                              scene.polygon_offsets[index + 1]]
            out.append(f"p {len(vertices)}")
            out.extend(_join(v) for v in vertices)
        elif kind == ElementKind.PATCH:
            lo, hi = scene.patch_offsets[index], scene.patch_offsets[index + 1]
            out.append(f"pp {hi - lo}")
            out.extend(_join(v) + " " + _join(n) for v, n in
                       zip(scene.patch_vertices[lo:hi], scene.patch_normals[lo:hi]))
        elif kind == ElementKind.CONE:
            out.append("c " + _join(scene.cone_base[index]) + " "
                       + _fmt(scene.cone_base_radius[index]))
            out.append("  " + _join(scene.cone_apex[index]) + " "
                       + _fmt(scene.cone_apex_radius[index]))
        else:
            raise ValueError(f"element kind {kind} has no NFF form")
    out.append("")
    return "\n".join(out)


def write_nff(scene: Scene, path) -> Path:
    """Write ``scene`` as NFF, atomically (temporary file, then rename).

    Every number is printed with the shortest text that reads back to the
    same float64, so :func:`read_nff` gives back identical arrays; the depth
    goes into a ``# max_depth N`` comment.

    Parameters
    ----------
    scene : Scene
    path : str or os.PathLike
        Destination; its folder must exist.

    Returns
    -------
    Path
        The written path.
    """
    path = Path(path)
    text = format_nff(scene)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
    return path
