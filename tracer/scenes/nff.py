"""Reading (and, from :mod:`tracer.scenes.nff_write`, writing) scenes in Eric Haines's Neutral File Format (NFF).

NFF is parsed by whitespace-separated tokens, not by lines, because writers
differ in where they break lines (``c`` may put its two ends on one line or
two). ``#`` starts a comment to the end of the line. Directives:

================================  ==============================================
``v``                             start of the view, followed by any of
                                  ``from x y z``, ``at x y z``, ``up x y z``,
                                  ``angle deg``, ``hither d``,
                                  ``resolution w h``; the view precedes objects
``b r g b``                       background colour
``l x y z [r g b]``               point light, white without a colour
``f r g b Kd Ks shine T ior``     material of the objects that follow
``c bx by bz br ax ay az ar``     cone/cylinder without caps (negative radii:
                                  inside visible)
``s x y z r``                     sphere
``p n`` + n vertices              planar polygon; 3 vertices make a TRIANGLE
                                  element, more a POLYGON element
``pp n`` + n ``x y z nx ny nz``   polygon patch with vertex normals (PATCH)
================================  ==============================================

The texture extension (our own; a file without these keywords is plain NFF):

``texture NAME FILE``
    a texture read from a PNG or JPEG file (path relative to the NFF file;
    one token: no whitespace, no ``#``)
``texture NAME procedural W H SEED [CELLS]``
    a seeded image of W x H texels (:func:`tracer.rendering.texture.procedural_texture`;
    CELLS default 8)
``usetexture NAME [SCALE]``
    the objects that follow use texture NAME (repeated SCALE times across
    their (u, v), default 1) times the current ``f`` colour, until the next
    ``f`` or ``usetexture none``
``tp n`` + n ``x y z u v``
    ``p`` with (u, v) per vertex (3 vertices: TRIANGLE, more: POLYGON)
``tpp n`` + n ``x y z nx ny nz u v``
    ``pp`` with (u, v) per vertex (PATCH)

A texture NAME is one token, neither a keyword nor ``none``; textures are
numbered in the order they are defined (unused ones too). While a texture
is in use, spheres are mapped by latitude and longitude, ``tp`` and ``tpp``
by their (u, v); ``p``, ``pp`` and ``c`` are errors (they have no (u, v)).
``tp`` and ``tpp`` without a texture in use keep their (u, v) unused. The
fast pass does not know these keywords and leaves such files to the
positional reader.

The reader is strict, as a C reader of the format would be: the view
(``v`` with all six of ``from``, ``at``, ``up``, ``angle``, ``hither`` and
``resolution``) is required, a scene without objects is an error, and numbers
follow C's syntax (``[+-]digits[.digits][e[+-]digits]``; no ``1_0``, no
non-ASCII digits, no ``inf`` or ``nan``); every number of ``f`` but the Phong
exponent ``shine`` is >= 0 (an SPD ``ior`` of 0 is kept: it is an opaque
surface's). A UTF-8 byte-order mark at the start of a file is skipped (one
anywhere else is a token like any other, and refused as such). A non-planar
polygon or a cone with both radii 0 gets one warning per file naming file
and line; an error found after the tokens were read (a zero-length vertex
normal, ``up`` parallel to the view direction, a degenerate polygon) still
names file, line and column.

Speed: a file is read by a fast pass (split on whitespace, convert numbers
in slices, check the geometry with numpy at the end); only when that pass
meets something wrong, or needs a line number for a warning, does the
positional reader run to say where (``benchmarks/bench_nff.py`` compares
:func:`read_nff` with a plain split-and-float pass).

NFF has no recursion depth. :func:`write_nff` records the scene's depth in a
comment line ``# max_depth N`` and the reader honours such a line (N in
1..``MAX_DEPTH`` (64), else an error naming file and line, unless ``max_depth`` is given);
without it the depth is the SPD procedure's 5 (the
:class:`~tracer.scenes.model.Scene` default). :func:`tracer.scenes.catalog.load`
applies the paper's depth per named scene instead.

Materials are deduplicated and numbered in order of first use (see
:class:`~tracer.scenes.model.SceneBuilder`), which makes read -> write -> read exact:
the writer prints every number with the shortest representation that reads
back to the same float64. :func:`write_nff` writes a textured scene's images
as lossless PNG files beside the NFF file (a procedural texture's parameters
are not kept in a :class:`~tracer.scenes.model.Scene`, so its texels are written).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from rtcommon.files import regular_file
from tracer.scenes.nff_fast import (C_INTEGER, C_NUMBER, CAMERA_FIELDS, DEPTH_PRAGMA, KEYWORDS, LINE_BREAKS,
                                    MATERIAL_FIELDS, OBJECT_KEYWORDS, PLANARITY_TOLERANCE, TOKEN, VIEW_KEYWORDS,
                                    Fallback, SceneParts, assemble, parse_fast, polygon_measures,
                                    view_direction_problem)
from tracer.scenes.model import MAX_DEPTH, Camera, ElementKind, Scene, unread_texture
from rtcommon.validate import InputError

__all__ = ["NFFError", "format_nff", "parse_nff", "read_nff", "write_nff"]

#: A UTF-8 byte-order mark (as decoded) at the start of a file: skipped.
BYTE_ORDER_MARK = "\ufeff"

class NFFError(InputError):
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


def _normalise_line_breaks(text: str) -> str:
    # every break str.splitlines() knows becomes "\n", so line numbers agree everywhere
    if text.isascii() and not any(mark in text for mark in "\r\x0b\x0c\x1c\x1d\x1e"):
        return text  # the common case, without a regular-expression pass
    return LINE_BREAKS.sub("\n", text)


def _depth_pragma(text: str, source: str) -> int | None:
    """The depth of the file's last ``# max_depth N`` line (None without one); refused outside 1..``MAX_DEPTH``."""
    found = None
    for found in DEPTH_PRAGMA.finditer(text):
        pass
    if found is None:
        return None
    depth = int(found.group(1))
    if not 1 <= depth <= MAX_DEPTH:
        line = text.count("\n", 0, found.start(1)) + 1
        column = found.start(1) - text.rfind("\n", 0, found.start(1))
        raise NFFError(source, line, column, f"a max_depth in 1..{MAX_DEPTH}", found.group(1))
    return depth


class _Tokens:
    """Tokens of an NFF text with their 1-based line and column (the positional reader's input)."""

    def __init__(self, text: str, source: str):
        self.source = source
        self.items: list[tuple[str, int, int]] = []
        lines = text.split("\n")
        for number, line in enumerate(lines, start=1):
            hash_at = line.find("#")
            if hash_at >= 0:
                line = line[:hash_at]
            for match in TOKEN.finditer(line):
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
        value = float(token) if C_NUMBER.fullmatch(token) else float("nan")
        if not np.isfinite(value):
            raise self.error(expected, self.pos - 1)
        return value

    def numbers(self, count: int, expected: str) -> tuple[float, ...]:
        return tuple(self.number(expected) for _ in range(count))

    def integer(self, expected: str) -> int:
        token = self.next(expected)
        if not C_INTEGER.fullmatch(token):
            raise self.error(expected, self.pos - 1)
        return int(token)


# ------------------------------------------------------------- the positional reader
#: numbers per vertex, and their names, of each polygon keyword
_VERTEX_FIELDS = {"p": (3, "x y z"), "pp": (6, "x y z nx ny nz"), "tp": (5, "x y z u v"),
                  "tpp": (8, "x y z nx ny nz u v")}


def _texture_image(tokens: _Tokens, folder: Path | None, texels: bool) -> np.ndarray:
    """The image of a ``texture NAME ...`` line, read from the tokens after its name:
    a PNG or JPEG file, or ``procedural WIDTH HEIGHT SEED [CELLS]``; shape (H, W, 4) uint8.
    Without ``texels``, an :func:`~tracer.scenes.model.unread_texture` of its size (a file's
    header is read, a procedural image is not made)."""
    from tracer.scenes.images import image_size, read_image
    from tracer.rendering.texture import MAX_TEXELS, procedural_texture

    at = tokens.pos
    what = tokens.next("an image file or 'procedural' after the texture name")
    if what in KEYWORDS:
        raise tokens.error("an image file or 'procedural' after the texture name", at)
    if what == "procedural":
        width = tokens.integer("a positive integer (procedural texture width)")
        height = tokens.integer("a positive integer (procedural texture height)")
        if width < 1 or height < 1:
            raise tokens.error("a positive procedural texture size", tokens.pos - 2)
        if width * height > MAX_TEXELS:
            raise tokens.error(f"a procedural texture of at most {MAX_TEXELS} texels", tokens.pos - 2)
        seed = tokens.integer("an integer >= 0 (procedural texture seed)")
        if seed < 0:
            raise tokens.error("an integer >= 0 (procedural texture seed)", tokens.pos - 1)
        cells = 8
        if not tokens.at_end() and tokens.items[tokens.pos][0] not in KEYWORDS:
            cells = tokens.integer("a positive integer (procedural texture cells) or a keyword")
            if cells < 1:
                raise tokens.error("a positive number of procedural texture cells", tokens.pos - 1)
        return procedural_texture(width, height, seed=seed, cells=cells) if texels else unread_texture(width, height)
    path = Path(what) if folder is None else folder / what
    try:
        return read_image(path) if texels else unread_texture(*image_size(path))
    except (OSError, ValueError) as error:
        raise tokens.error(f"a readable PNG or JPEG image file ({error})", at) from None


def _parse_positioned(text: str, source: str, folder: Path | None = None,
                      texels: bool = True) -> tuple[SceneParts, list[int]]:
    """Read NFF token by token, knowing every token's line and column: the reader that says where.

    Returns the scene's parts (see :func:`assemble`) and, per element, the
    index of its keyword token. Raises :class:`NFFError` at the first fault.
    Relative texture files are looked up in ``folder`` (default: the
    current folder); without ``texels`` textures are sized, not read.
    """
    tokens = _Tokens(text, source)
    parts = SceneParts()
    texture_numbers: dict[str, int] = {}
    texture_in_use = None
    view: dict | None = None
    view_at = 0
    view_tokens: dict = {}
    first_object = None

    while not tokens.at_end():
        start = tokens.pos
        keyword = tokens.next("a keyword")
        if keyword in OBJECT_KEYWORDS and first_object is None:
            first_object = start
        if keyword == "v" or keyword in VIEW_KEYWORDS:
            if first_object is not None:
                raise tokens.error("the view ('v ...') before the first object (view after objects)", start)
            if keyword == "v":
                view, view_at, view_tokens = {}, start, {}
                continue
            if view is None:
                raise tokens.error(f"'v' before the view parameter {keyword!r}", start)
            view_tokens[keyword] = start
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
            parts.background = tokens.numbers(3, "a number (r g b of the background)")
        elif keyword == "l":
            position = tokens.numbers(3, "a number (x y z of the light)")
            color = (1.0, 1.0, 1.0)
            if not tokens.at_end() and tokens.items[tokens.pos][0] not in KEYWORDS:
                color = tokens.numbers(3, "a number (r g b of the light) or a keyword")
            parts.lights.append((*position, *color))
        elif keyword == "f":
            at = tokens.pos
            parts.material = tokens.numbers(8, "a number (f: r g b Kd Ks shine T ior)")
            for k, (name, value) in enumerate(zip(MATERIAL_FIELDS, parts.material)):
                if value < 0.0 and name != "shine":
                    raise tokens.error(f"{name} >= 0 (f: r g b Kd Ks shine T ior)", at + k)
            parts.texture_use, texture_in_use = (), None  # a texture lasts until the next 'f'
        elif keyword == "s":
            values = tokens.numbers(4, "a number (s: x y z radius)")
            if values[3] <= 0.0:
                raise tokens.error("a positive sphere radius", tokens.pos - 1)
            parts.add_sphere(values, start)
        elif keyword == "c":
            if parts.texture_use:
                raise tokens.error(f"no cone while texture {texture_in_use!r} is in use (a cone has no (u, v); "
                                   "'usetexture none' first)", start)
            values = tokens.numbers(8, "a number (c: base x y z r, apex x y z r)")
            if values[:3] == values[4:7]:
                raise tokens.error("a cone apex different from its base (degenerate cone)", tokens.pos - 4)
            parts.add_cone(values, start)
        elif keyword in ("p", "pp", "tp", "tpp"):
            if keyword in ("p", "pp") and parts.texture_use:
                raise tokens.error(f"'t{keyword}' (with u v per vertex) while texture {texture_in_use!r} is in use: "
                                   f"{keyword!r} gives no (u, v) ('usetexture none' first)", start)
            count = tokens.integer(f"a vertex count after {keyword!r}")
            if count < 3:
                raise tokens.error("a polygon with at least 3 vertices (too few vertices)", tokens.pos - 1)
            per_vertex, what = _VERTEX_FIELDS[keyword]
            values = tokens.numbers(per_vertex * count, f"a number ({keyword} {count}: {count} x {what})")
            table = np.array(values).reshape(count, per_vertex)
            degenerate, _ = polygon_measures(table[:, :3], np.array([0, count]))
            if degenerate[0]:
                raise tokens.error("a polygon with non-zero area (degenerate polygon)", start)
            patch = keyword in ("pp", "tpp")
            if patch and not np.all(np.any(table[:, 3:6] != 0.0, axis=1)):
                raise tokens.error(f"a non-zero normal at every vertex of {keyword!r} (zero normal)", start)
            uv = None
            if keyword in ("tp", "tpp"):
                uv = table[:, -2:].ravel().tolist()
                values = table[:, :-2].ravel().tolist()
            parts.add_polygon("pp" if patch else "p", count, values, start, uv)
        elif keyword == "texture":
            name_at = tokens.pos
            texture_name = tokens.next("a texture name after 'texture'")
            if texture_name in KEYWORDS:
                raise tokens.error("a texture name after 'texture' (not a keyword)", name_at)
            if texture_name == "none" or texture_name in texture_numbers:
                what = "reserved" if texture_name == "none" else "already defined"
                raise tokens.error(f"a new texture name ({texture_name!r} is {what})", name_at)
            texture_numbers[texture_name] = parts.add_texture(_texture_image(tokens, folder, texels))
        elif keyword == "usetexture":
            name_at = tokens.pos
            texture_name = tokens.next("a texture name or 'none' after 'usetexture'")
            if texture_name == "none":
                parts.texture_use, texture_in_use = (), None
                continue
            if texture_name not in texture_numbers:
                defined = ", ".join(repr(n) for n in texture_numbers) or "none yet"
                raise tokens.error(f"a texture defined by an earlier 'texture' line or 'none' (defined: {defined})",
                                   name_at)
            scale = 1.0
            if not tokens.at_end() and tokens.items[tokens.pos][0] not in KEYWORDS:
                scale = tokens.number("a number (uv scale of 'usetexture') or a keyword")
                if not scale > 0.0:
                    raise tokens.error("a positive uv scale", tokens.pos - 1)
            parts.texture_use, texture_in_use = (texture_numbers[texture_name], scale), texture_name
        elif keyword not in ("v", *VIEW_KEYWORDS):
            raise tokens.error("a keyword (one of " + ", ".join(KEYWORDS) + ")", start)

    if not parts.kinds:
        raise tokens.error("at least one object (s, p, pp, c, tp or tpp): the scene is empty", len(tokens.items))
    if view is None:
        raise tokens.error("a view ('v' with from, at, up, angle, hither, resolution) before the first object",
                           first_object)
    missing = [keyword for keyword in VIEW_KEYWORDS if CAMERA_FIELDS[keyword] not in view]
    if missing:
        raise tokens.error("a complete view: missing " + ", ".join(repr(m) for m in missing), view_at)
    if view_direction_problem(view):
        raise tokens.error("an 'up' direction not parallel to the view direction (from -> at)", view_tokens["up"])
    try:
        parts.camera = Camera(**view)
    except ValueError as error:
        raise tokens.error(f"a valid view ({error})", view_at) from None
    return parts, parts.tokens


def _warn_about(scene: Scene, element_tokens: list, text: str, source: str) -> None:
    """One warning per kind of oddity in a file, naming the first one's line."""
    findings = []
    kinds = scene.element_kind
    for kind, vertices, offsets in ((ElementKind.POLYGON, scene.polygon_vertices, scene.polygon_offsets),
                                    (ElementKind.PATCH, scene.patch_vertices, scene.patch_offsets)):
        _, deviation = polygon_measures(vertices, offsets)
        bent = np.flatnonzero(deviation > PLANARITY_TOLERANCE)
        if bent.size:
            element = np.flatnonzero(kinds == kind)[bent[0]]
            findings.append((element, f"{'polygon' if kind == ElementKind.POLYGON else 'patch'} is not planar "
                                      f"(a vertex lies {deviation[bent[0]]:.2g} of its size off its plane)",
                             bent.size))
    flat = np.flatnonzero((scene.cone_base_radius == 0.0) & (scene.cone_apex_radius == 0.0))
    if flat.size:
        element = np.flatnonzero(kinds == ElementKind.CONE)[flat[0]]
        findings.append((element, "cone has both radii 0 (it is invisible)", flat.size))
    if not findings:
        return
    items = _Tokens(text, source).items
    for element, what, count in findings:
        _, line, _ = items[element_tokens[element]]
        more = f"; {count - 1} more like it" if count > 1 else ""
        warnings.warn(f"{source}:{line}: {what}{more}", stacklevel=4)


def parse_nff(text: str, source: str = "<string>", *, name: str | None = None,
              max_depth: int | None = None, folder=None, texels: bool = True) -> Scene:
    """Parse NFF text into a :class:`~tracer.scenes.model.Scene`.

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
    folder : str or os.PathLike, optional
        Where relative ``texture`` files are; default the folder of
        ``source`` when it names a file, else the current folder.
    texels : bool
        Read the textures' texels (default). False keeps their sizes only
        (image files' headers are read, procedural images are not made):
        enough for :meth:`~tracer.scenes.model.Scene.summary`; such a scene
        (``Scene.texels_read`` False) cannot be rendered or written.

    Returns
    -------
    Scene
        Elements numbered in file order; materials numbered by first use (as
        :class:`~tracer.scenes.model.SceneBuilder` numbers them).

    Raises
    ------
    NFFError
        On the first fault, with file, line, column and what was expected
        (a missing or unreadable texture image included); no partial scene
        is returned.

    Warns
    -----
    UserWarning
        Once per kind, naming file and line: a polygon or patch that is not
        planar, a cone with both radii 0.
    """
    if name is None:
        name = "scene" if source.startswith("<") else (Path(source).stem or "scene")
    text = _normalise_line_breaks(text.removeprefix(BYTE_ORDER_MARK))
    pragma = None if max_depth is not None else _depth_pragma(text, source)
    depth = int(max_depth) if max_depth is not None else (pragma if pragma is not None else 5)
    try:
        parts = parse_fast(text)
        scene = assemble(parts, name, depth)
    except Fallback:  # a fault, or the texture extension
        if folder is None and not source.startswith("<"):
            folder = Path(source).parent
        parts, _ = _parse_positioned(text, source, None if folder is None else Path(folder), texels)
        scene = assemble(parts, name, depth)
    _warn_about(scene, parts.tokens, text, source)
    return scene


def read_nff(path, *, max_depth: int | None = None, texels: bool = True) -> Scene:
    """Read an NFF file.

    Parameters
    ----------
    path : str or os.PathLike
        The file; the scene is named after its stem.
    max_depth : int, optional
        Recursion depth; default the file's ``# max_depth N`` comment, else 5
        (the SPD procedure's depth, not the paper's 2; use
        :func:`tracer.scenes.catalog.load` for the paper's depths).
    texels : bool
        False: textures keep their sizes only (see :func:`parse_nff`).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    IsADirectoryError, ValueError
        If it is a folder, or not a regular file (a FIFO would block).
    NFFError
        If the file is malformed.
    """
    path = regular_file(path, "an NFF file")
    text = path.read_bytes().decode("utf-8", errors="replace")
    return parse_nff(text, str(path), name=path.stem, max_depth=max_depth, folder=path.parent, texels=texels)


# the writer lives in its own module; these names stay importable from here
from tracer.scenes.nff_write import format_nff, write_nff  # noqa: E402
