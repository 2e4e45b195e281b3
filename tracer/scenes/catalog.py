"""The study's scenes by name, and user scenes by path.

>>> from tracer.scenes.catalog import load, PAPER_SCENES
>>> PAPER_SCENES
('balls', 'tetra', 'shell', 'room', 'fluid')
>>> load("tetra").n_elements
4096

Named scenes get the paper's maximum depth (balls, tetra, shell: 2; room: 4;
fluid: 5), not the SPD procedure's 5; ``max_depth`` overrides it. Files keep
the depth they carry (:func:`tracer.scenes.nff.read_nff`: a ``# max_depth N``
comment, else 5; OBJ: 5) unless ``max_depth`` is given.
"""
from __future__ import annotations

import os
from pathlib import Path

from tracer.scenes import spd, standins, textured
from rtcommon.validate import InputError, require_int
from tracer.scenes.model import MAX_DEPTH, Scene
from tracer.scenes.study import PAPER_DEPTH, PAPER_ELEMENTS, PAPER_SCENES, canonical_scene_name

__all__ = ["PAPER_SCENES", "NAMED_SCENES", "PAPER_DEPTH", "PAPER_ELEMENTS", "load"]

_GENERATORS = {
    "balls": spd.balls,
    "tetra": spd.tetra,
    "shell": spd.shells,
    "room": standins.room,
    "fluid": standins.fluid,
    "balls-textured": textured.balls_textured,
    "room-textured": textured.room_textured,
}
#: every scene :func:`load` knows by name: the study's five, then their textured variants
NAMED_SCENES = tuple(_GENERATORS)
_SUFFIXES = (".nff", ".obj")


def load(name_or_path, max_depth: int | None = None, *, texels: bool = True) -> Scene:
    """A paper scene by name, or an NFF/OBJ scene from a file.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        One of :data:`PAPER_SCENES` (case-insensitive; ``"shells"`` is
        accepted for ``"shell"``), a textured variant (``balls-textured``,
        ``room-textured``: :mod:`tracer.scenes.textured`), or a path ending in
        ``.nff`` or ``.obj``.
    max_depth : int, optional
        Maximum recursion depth, 1..``MAX_DEPTH`` (64); default the paper's for a named scene and
        the file's (see module docstring) for a path.
    texels : bool
        False: a file's textures keep their sizes only, unread (enough for
        :meth:`Scene.summary`; see :func:`tracer.scenes.nff.parse_nff`).
        Named scenes always make theirs (they are small).

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid names), unsupported file
        type, bad ``max_depth``, or a malformed file
        (:class:`tracer.scenes.nff.NFFError`, :class:`tracer.scenes.obj.OBJError`).
    FileNotFoundError
        A path that does not exist.
    """
    if max_depth is not None:
        max_depth = require_int("max_depth", max_depth, 1, MAX_DEPTH)
    text = os.fspath(name_or_path)
    key = canonical_scene_name(text)
    if key in _GENERATORS and not isinstance(name_or_path, Path):
        scene = _GENERATORS[key]()
        scene.name = key
        paper_depth = PAPER_DEPTH[textured.TEXTURED_SCENES.get(key, key)]
        scene.max_depth = paper_depth if max_depth is None else max_depth
        return scene
    path = Path(text)
    suffix = path.suffix.lower()
    if suffix in _SUFFIXES:
        if not path.exists():
            raise FileNotFoundError(f"scene file not found: {text!r}")
        if suffix == ".nff":
            from tracer.scenes.nff import read_nff

            return read_nff(path, max_depth=max_depth, texels=texels)
        from tracer.scenes.obj import read_obj

        return read_obj(path, max_depth=5 if max_depth is None else max_depth, texels=texels)
    if path.exists():
        raise InputError(f"unsupported scene file {text!r}: expected a .nff or .obj file")
    if path.suffix or os.sep in text or "/" in text:
        raise FileNotFoundError(f"scene file not found: {text!r}")
    raise InputError(f"unknown scene {text!r}: expected one of {', '.join(_GENERATORS)} "
                     "or a path to a .nff or .obj file")
