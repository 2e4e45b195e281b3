"""An on-disk cache of rendered access traces, so a second report reuses them.

Rendering with access logging is the one step of an analysis that depends on
the scene's geometry; every mapping, process count and cache configuration
afterwards is a replay of the stored trace (DESIGN.md §4). The cache keys a
trace by everything that decides its content:

- the scene: its name for a built-in scene (``balls`` ...), or the SHA-256 of
  the file's bytes for an NFF/OBJ path (so editing the file misses the cache);
- the image size, the kd-tree builder and the ray-tree depth;
- the package version, the trace format version and a digest of the
  ``tracer`` package's source files (an editable checkout changes the
  renderer without changing the version).

Layout of the cache folder (default ``~/.cache/raytrace-coherence/traces``,
overridden by the ``COHERENCE_CACHE`` environment variable or ``cache_dir``)::

    <cache>/<scene>-<size>-<kd>-d<depth>-<hash>/
        trace/         the AccessTrace (pixel_offsets.npy, records.npy, ...)
        image.png      the rendered image
        render.json    tree statistics, kd-tree config, counter totals,
                       timings of the render, and the key's ingredients

An entry is written into a temporary sibling folder and renamed into place,
so readers never see half an entry; two processes racing for one key both
render, and the first rename wins.

>>> scene, trace, info = cached_trace("tetra", 64)        # doctest: +SKIP
>>> info["cached"]                                         # doctest: +SKIP
False
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from rtcommon.jsonio import json_default
from rtcommon.validate import require_int

__all__ = ["cached_trace", "default_cache_dir", "trace_key", "CACHE_ENV"]

#: Environment variable naming the cache folder (holding ``traces/``).
CACHE_ENV = "COHERENCE_CACHE"

_INFO = "render.json"
_KD_BUILDERS = ("sah", "median")


def default_cache_dir() -> Path:
    """``$COHERENCE_CACHE/traces`` or ``~/.cache/raytrace-coherence/traces``."""
    root = os.environ.get(CACHE_ENV)
    if root:
        return Path(root).expanduser() / "traces"
    return Path.home() / ".cache" / "raytrace-coherence" / "traces"


def _source_digest() -> str:
    """SHA-256 of the tracer package's ``.py`` files (name and bytes)."""
    import tracer

    digest = hashlib.sha256()
    for path in sorted(Path(tracer.__file__).parent.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _scene_identity(name_or_path) -> tuple[str, str]:
    """(short label, identity string) of a scene name or file."""
    from tracer.study import PAPER_SCENES, canonical_scene_name

    text = os.fspath(name_or_path)
    lowered = canonical_scene_name(text)
    if lowered in PAPER_SCENES and not isinstance(name_or_path, Path):
        return lowered, f"name:{lowered}"
    path = Path(text)
    if not path.is_file():
        if path.suffix.lower() not in (".nff", ".obj"):
            raise ValueError(f"unknown scene {text!r}: expected one of {', '.join(PAPER_SCENES)} "
                             "or a path to a .nff or .obj file")
        raise FileNotFoundError(f"no such scene file: {text!r}")
    content = hashlib.sha256(path.read_bytes()).hexdigest()
    label = "".join(c if c.isalnum() or c in "-_" else "_" for c in path.stem)[:40] or "scene"
    return label, f"file:{content}"


def trace_key(name_or_path, size: int, *, kd: str = "sah", max_depth: int) -> str:
    """Folder name of a cache entry: readable prefix plus a hash of every ingredient.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        Built-in scene name or NFF/OBJ path.
    size : int
        Image width and height.
    kd : {"sah", "median"}
    max_depth : int
        The ray-tree depth actually rendered (the scene's when not overridden).
    """
    from coherence import __version__
    from tracer.trace import FORMAT_VERSION

    label, identity = _scene_identity(name_or_path)
    ingredients = {"scene": identity, "size": int(size), "kd": kd, "max_depth": int(max_depth),
                   "version": __version__, "format_version": FORMAT_VERSION, "tracer_source": _source_digest()}
    digest = hashlib.sha256(json.dumps(ingredients, sort_keys=True).encode()).hexdigest()[:16]
    return f"{label}-{int(size)}-{kd}-d{int(max_depth)}-{digest}"


def cached_trace(scene_name_or_path, size: int, *, cache_dir=None, kd: str = "sah", max_depth: int | None = None,
                 progress: bool = True):
    """The scene and its access trace at ``size`` x ``size``, rendered once and then loaded.

    Parameters
    ----------
    scene_name_or_path : str or os.PathLike
        A built-in scene (``balls``, ``tetra``, ``shell``, ``room``,
        ``fluid``) or an NFF/OBJ file.
    size : int
        Image width and height in pixels.
    cache_dir : path, optional
        Folder of cache entries (default :func:`default_cache_dir`).
    kd : {"sah", "median"}
        kd-tree builder.
    max_depth : int, optional
        Ray-tree depth; default the scene's.
    progress : bool
        Show a progress bar on stderr while rendering.

    Returns
    -------
    scene : tracer.scene.Scene
    trace : tracer.trace.AccessTrace
        Records memory-mapped from the cache.
    render_info : dict
        ``key``, ``path`` (the entry folder), ``png`` (image path), ``cached``
        (whether it was loaded), ``size``, ``kd``, ``max_depth``, ``tree``
        (statistics), ``kd_config``, ``totals`` (counter sums), ``timings``
        (seconds of the original render).

    Raises
    ------
    ValueError
        Unknown scene name, bad size or builder, malformed scene file.
    FileNotFoundError
        A scene path that does not exist.
    """
    from tracer.scenes import load
    from tracer.trace import AccessTrace

    size = require_int("size", size, 1)
    if kd not in _KD_BUILDERS:
        raise ValueError(f"kd must be one of {_KD_BUILDERS}, got {kd!r}")
    scene = load(scene_name_or_path, max_depth=max_depth)
    key = trace_key(scene_name_or_path, size, kd=kd, max_depth=scene.max_depth)
    root = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    entry = root / key
    info = _read_entry(entry)
    if info is not None:
        try:
            trace = AccessTrace.load(entry / "trace", mmap=True)
        except (FileNotFoundError, ValueError):  # damaged entry: render it again
            shutil.rmtree(entry, ignore_errors=True)
            info = None
    if info is None:
        _render_entry(scene, size, kd, key, entry, progress)
        info = _read_entry(entry)
        if info is None:
            raise RuntimeError(f"trace cache entry {entry} was not written completely")
        trace = AccessTrace.load(entry / "trace", mmap=True)
        info["cached"] = False
    else:
        info["cached"] = True
    info["path"] = str(entry)
    info["png"] = str(entry / "image.png")
    return scene, trace, info


def _read_entry(entry: Path) -> dict | None:
    try:
        info = json.loads((entry / _INFO).read_text())
    except (FileNotFoundError, NotADirectoryError, json.JSONDecodeError):
        return None
    if not (entry / "image.png").is_file() or not (entry / "trace" / "meta.json").is_file():
        return None
    return info


def _render_entry(scene, size: int, kd: str, key: str, entry: Path, progress: bool) -> None:
    from tqdm.auto import tqdm

    from tracer.kdtree import KdTreeConfig
    from tracer.render import render, save_png

    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{key}.", suffix=".tmp", dir=entry.parent))
    try:
        bar = tqdm(total=1, desc=f"rendering {scene.name} {size}x{size} (logging accesses)", unit="image",
                   disable=not progress, leave=False, file=sys.stderr)
        start = time.perf_counter()
        result = render(scene, size=size, kd_config=KdTreeConfig(builder=kd), trace_path=tmp / "trace",
                        metadata={"cache_key": key})
        seconds = time.perf_counter() - start
        bar.update(1)
        bar.close()
        save_png(result.image, tmp / "image.png")
        info = {
            "key": key, "scene": scene.name, "size": size, "kd": kd, "max_depth": int(scene.max_depth),
            "tree": result.tree.stats, "kd_config": result.tree.config.to_dict(), "totals": result.totals(),
            "timings": {**result.timings, "wall": seconds},
        }
        (tmp / _INFO).write_text(json.dumps(info, indent=1, default=json_default) + "\n")
        del result
        try:
            os.replace(tmp, entry)
        except OSError:
            if _read_entry(entry) is None:  # not a concurrent writer's complete entry: replace it
                shutil.rmtree(entry, ignore_errors=True)
                os.replace(tmp, entry)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

