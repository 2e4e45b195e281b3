"""An on-disk cache of rendered access traces, so a second report reuses them.

Rendering with access logging is the one step of an analysis that depends on
the scene's geometry; every mapping, process count and cache configuration
afterwards is a replay of the stored trace (docs/design.md, "Layers"). The cache keys a
trace by everything that decides its content:

- the scene: its name for a built-in scene (``balls`` ...), or the SHA-256 of
  the file's bytes for an NFF/OBJ path (so editing the file misses the cache);
- the image size, the kd-tree builder, the ray-tree depth and the workload
  (:data:`tracer.rendering.workload.WORKLOADS`, with its parameters, the
  tree of its tree variant included: :mod:`tracer.rendering.tree_variants`);
- the package version, the trace format version and a digest of the
  ``tracer`` package's source files (an editable checkout changes the
  renderer without changing the version).

The cache folder is ``cache_dir`` when given (the CLI's ``--cache``), else
the ``COHERENCE_CACHE`` environment variable, else
``~/.cache/raytrace-coherence``; whichever names it, its layout is the same::

    <cache>/traces/<scene>-<size>[-<workload>][-<tree variant>]-<kd>-d<depth>-<hash>/
                   (workload left out for "modern", tree variant for the default)
        trace/         the AccessTrace (pixel_offsets.npy, records.npy, ...,
                       meta.json with a checksum of every array and header,
                       meta.json.xxh3 with meta.json's)
        image.png      the rendered image
        render.json    tree statistics, kd-tree config, counter totals,
                       timings of the render, the key's ingredients, the
                       image's checksum and the trace's meta.json.xxh3
        render.json.xxh3   the checksum of render.json
    <cache>/scenes/    NFF files generated for what-if scene sizes

So one digest, ``render.json.xxh3``, covers every byte of an entry.
An entry is written into a temporary sibling folder and renamed into place,
so readers never see half an entry; two processes racing for one key both
render, and the first rename wins. Every load verifies the checksums: a
damaged entry, or one missing any checksum, is reported in one line (a
warning), evicted and rendered again. Temporary folders of runs that died are removed by the next run. A
cache folder that cannot be written is read from, and new traces are
rendered into a temporary folder for this process only, with a warning.

>>> scene, trace, info = cached_trace("tetra", 64)        # doctest: +SKIP
>>> info["cached"]                                         # doctest: +SKIP
False
"""
from __future__ import annotations

import atexit
import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import xxhash

from rtcommon.files import make_temp_dir, remove_stale_temporaries
from rtcommon.jsonio import json_default
from rtcommon.validate import InputError, require_bool, require_int
from tracer.trace.check import META_CHECKSUM, matches_checksum, write_with_checksum

__all__ = ["cached_trace", "cache_root", "check_cache_dir", "default_cache_dir", "trace_key", "CACHE_ENV"]

#: Environment variable naming the cache folder (holding ``traces/``).
CACHE_ENV = "COHERENCE_CACHE"

_INFO = "render.json"
_INFO_DIGEST = "render.json.xxh3"  # XXH3-64 of render.json's bytes, beside it
_TRACE_DIGEST = META_CHECKSUM  # the trace's own digest, which covers all of its files
_IMAGE = "image.png"  # the rendered image, beside the trace folder
_KD_BUILDERS = ("sah", "median")
_PRIVATE_CACHES: dict = {}
_PILOT_SIZE = 32  # image size of the render that estimates a trace's bytes per pixel  # read-only cache root -> this process's temporary stand-in


def cache_root(cache_dir=None) -> Path:
    """The cache folder: ``cache_dir``, else ``$COHERENCE_CACHE``, else ``~/.cache/raytrace-coherence``."""
    if cache_dir is not None and os.fspath(cache_dir) != "":
        return Path(cache_dir).expanduser()
    root = os.environ.get(CACHE_ENV)
    if root:
        return Path(root).expanduser()
    return Path.home() / ".cache" / "raytrace-coherence"


def default_cache_dir() -> Path:
    """Folder of trace entries: ``<cache_root()>/traces``."""
    return cache_root() / "traces"


def check_cache_dir(cache_dir=None) -> Path:
    """The cache root, refused up front when it (or a parent on its path) is a file.

    Raises
    ------
    NotADirectoryError
        Naming where the path came from (``--cache`` or ``$COHERENCE_CACHE``).
    """
    root = cache_root(cache_dir)
    origin = "cache folder" if cache_dir is not None else (f"${CACHE_ENV}" if os.environ.get(CACHE_ENV)
                                                          else "cache folder")
    for path in (root / "traces", root / "scenes", root, *root.parents):
        if path.exists():
            if not path.is_dir():
                raise NotADirectoryError(f"{origin} {str(root)!r}: {str(path)!r} is a file, not a folder")
            if path != root / "traces" and path != root / "scenes":
                break
    return root


def _writable_traces_folder(root: Path) -> Path:
    """``root/traces``, or a temporary stand-in (with a warning) when the cache cannot be written."""
    folder = root / "traces"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = make_temp_dir(folder / "probe")
        probe.rmdir()
        return folder
    except OSError as error:
        if root not in _PRIVATE_CACHES:
            stand_in = Path(tempfile.mkdtemp(prefix="coherence-cache-"))
            atexit.register(shutil.rmtree, stand_in, ignore_errors=True)
            _PRIVATE_CACHES[root] = stand_in
            warnings.warn(f"trace cache {str(root)!r} is not writable ({error.strerror or error}); "
                          "rendering without caching", stacklevel=3)
        return _PRIVATE_CACHES[root]


def _source_digest() -> str:
    """SHA-256 of the tracer package's ``.py`` files, its subpackages' included (path and bytes)."""
    import tracer

    digest = hashlib.sha256()
    package = Path(tracer.__file__).parent
    for path in sorted(package.rglob("*.py")):
        digest.update(path.relative_to(package).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _scene_identity(name_or_path) -> tuple[str, str]:
    """(short label, identity string) of a scene name or file."""
    from tracer.scenes.catalog import NAMED_SCENES
    from tracer.scenes.study import canonical_scene_name

    text = os.fspath(name_or_path)
    lowered = canonical_scene_name(text)
    if lowered in NAMED_SCENES and not isinstance(name_or_path, Path):
        return lowered, f"name:{lowered}"
    path = Path(text)
    if not path.is_file():
        if path.suffix.lower() not in (".nff", ".obj"):
            raise InputError(f"unknown scene {text!r}: expected one of {', '.join(NAMED_SCENES)} "
                             "or a path to a .nff or .obj file")
        raise FileNotFoundError(f"no such scene file: {text!r}")
    content = hashlib.sha256(path.read_bytes()).hexdigest()
    label = "".join(c if c.isalnum() or c in "-_" else "_" for c in path.stem)[:40] or "scene"
    return label, f"file:{content}"


def trace_key(name_or_path, size: int, *, kd: str = "sah", max_depth: int, workload: str = "modern",
              path_samples: tuple = (1, 0),
              tree_variant: str | None = None, ray_data: bool = False) -> str:
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
    workload : str
        A :data:`tracer.rendering.workload.WORKLOADS` name; its parameters are hashed too.
    tree_variant : str, optional
        A :data:`tracer.rendering.tree_variants.TREE_VARIANTS` name: the
        workload's tree is that rule's (hashed with the workload); None or
        the default leaves the key as it was.
    path_samples : (int, int)
        Samples per pixel and seed of a path-traced workload (hashed for it
        only).
    ray_data : bool
        The workload made to log the tracer's per-ray data
        (:func:`with_ray_data`); the label then ends ``-raydata``. False, or
        a workload that logs it already, leaves the key as it was.
    """
    from coherence import __version__
    from tracer.trace.access import FORMAT_VERSION
    from tracer.rendering.tree_variants import STUDY_TREE_VARIANT, workload_with_tree

    label, identity = _scene_identity(name_or_path)
    preset = workload_with_tree(workload, tree_variant)
    logged = with_ray_data(preset, ray_data)
    ingredients = {"scene": identity, "size": int(size), "kd": kd, "max_depth": int(max_depth),
                   "workload": logged.to_dict(),
                   "version": __version__, "format_version": FORMAT_VERSION, "tracer_source": _source_digest()}
    if preset.renderer == "pathtrace":
        ingredients["path_samples"] = [int(path_samples[0]), int(path_samples[1])]
    digest = hashlib.sha256(json.dumps(ingredients, sort_keys=True).encode()).hexdigest()[:16]
    named = "" if preset.name == "modern" else f"-{preset.name}"
    if tree_variant not in (None, STUDY_TREE_VARIANT):
        named += f"-{tree_variant}"
    if logged is not preset:
        named += "-raydata"
    return f"{label}-{int(size)}{named}-{kd}-d{int(max_depth)}-{digest}"


def with_ray_data(workload, ray_data: bool):
    """``workload`` (a :class:`tracer.rendering.workload.Workload`) logging its per-ray data when ``ray_data``.

    The same object when ``ray_data`` is False, when the workload logs that
    data already, or when its renderer is not Whitted's (the path tracer
    logs none).
    """
    from dataclasses import replace

    if not require_bool("ray_data", ray_data) or workload.log_ray_data or workload.renderer != "whitted":
        return workload
    return replace(workload, log_ray_data=True)


def preset_and_ray_data(workload) -> tuple[str, bool]:
    """The preset's name and whether its ray data is logged, for a workload as :func:`cached_trace` takes it.

    Raises
    ------
    ValueError
        Neither a preset's name nor a preset made to log its ray data by :func:`with_ray_data`.
    """
    from tracer.rendering.workload import WORKLOADS, Workload

    if isinstance(workload, str) and workload in WORKLOADS:
        return workload, False
    if isinstance(workload, Workload) and workload.name in WORKLOADS and \
            workload == with_ray_data(WORKLOADS[workload.name], True):
        return workload.name, True
    raise InputError(f"workload must be one of {', '.join(WORKLOADS)} or such a preset logging its ray data "
                     f"(analyses.traces.with_ray_data), got {workload!r}")


def cached_trace(scene_name_or_path, size: int, *, cache_dir=None, kd: str | None = None,
                 max_depth: int | None = None, progress: bool = True, workload: str = "modern",
                 memory_budget: int | None = None, tree_variant: str | None = None, path_samples: tuple = (1, 0)):
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
    kd : {"sah", "median"}, optional
        kd-tree builder with its default parameters; default the
        workload's tree (SAH for ``"modern"``).
    max_depth : int, optional
        Ray-tree depth; default the scene's.
    progress : bool
        Show a progress bar on stderr while rendering.
    workload : str or Workload
        The tracer imitated: a :data:`tracer.rendering.workload.WORKLOADS`
        name, or a preset made to log its per-ray data and frame-buffer
        writes by :func:`with_ray_data` (what a run under a platform
        renders; its entry is keyed apart, see :func:`trace_key`).
    memory_budget : int, optional
        Bytes of records a render holds in RAM before it writes them to the
        entry in chunks (default :data:`tracer.rendering.render.DEFAULT_MEMORY_BUDGET`).
    tree_variant : str, optional
        The workload's tree rule by name
        (:data:`tracer.rendering.tree_variants.TREE_VARIANTS`); default the
        workload's own.
    path_samples : (int, int)
        Samples per pixel and seed of the ``pathtrace`` workload
        (:class:`tracer.rendering.render.RenderOptions` ``spp`` and ``seed``);
        the other workloads take ``(1, 0)``.

    Returns
    -------
    scene : tracer.scenes.model.Scene
    trace : tracer.trace.access.AccessTrace
        Records memory-mapped from the cache.
    render_info : dict
        ``key``, ``path`` (the entry folder), ``png`` (image path), ``cached``
        (whether it was loaded), ``size``, ``kd``, ``max_depth``, ``workload``, ``tree_variant``
        (as asked, None when not), ``tree``
        (statistics), ``kd_config``, ``totals`` (counter sums), ``timings``
        (seconds of the original render).

    Raises
    ------
    ValueError
        Unknown scene name, workload or tree variant, bad size or builder, a tree variant with another
        builder, malformed scene file.
    FileNotFoundError
        A scene path that does not exist.
    """
    from tracer.scenes.catalog import load
    from tracer.trace.access import AccessTrace
    from tracer.kd.tree import KdTreeConfig
    from tracer.rendering.tree_variants import workload_with_tree
    from tracer.rendering.workload import WORKLOADS

    from tracer.trace.access import TraceIntegrityError

    size = require_int("size", size, 1)
    workload, ray_data = preset_and_ray_data(workload)
    preset = workload_with_tree(workload, tree_variant)
    if kd is None:
        kd = preset.kd_config.builder
    elif kd not in _KD_BUILDERS:
        raise InputError(f"kd must be one of {_KD_BUILDERS}, got {kd!r}")
    explicit_kd = kd if kd != preset.kd_config.builder else None
    if explicit_kd and preset is not WORKLOADS[workload]:
        raise InputError(f"tree variant {tree_variant} is a {preset.kd_config.builder} tree; kd {kd} builds another")
    root = check_cache_dir(cache_dir)
    scene = load(scene_name_or_path, max_depth=max_depth)
    key = trace_key(scene_name_or_path, size, kd=kd, max_depth=scene.max_depth, workload=workload,
                    tree_variant=tree_variant, path_samples=path_samples, ray_data=ray_data)
    preset = with_ray_data(preset, ray_data)
    entry = root / "traces" / key
    remove_stale_temporaries(entry.parent)  # on a hit too: a killed run's leftovers go at the next run
    try:
        info = _read_entry(entry)
        if info is not None:
            trace = AccessTrace.load(entry / "trace", mmap=True)
            _check_entry(entry, key, info, trace)
    except (FileNotFoundError, NotADirectoryError, TraceIntegrityError) as error:  # damaged: evict, render again
        warnings.warn(f"damaged trace cache entry {key}: {getattr(error, 'detail', error)}; "
                      "evicting it and rendering again", stacklevel=2)
        trace = None
        _remove(entry)
        info = None
    if info is None:
        folder = _writable_traces_folder(root)
        entry = folder / key
        if entry.is_symlink() or entry.exists() and not entry.is_dir():
            warnings.warn(f"damaged trace cache entry {key}: a file, not a folder; "
                          "evicting it and rendering again", stacklevel=2)
            _remove(entry)
        overrides = {"kd_config": KdTreeConfig(builder=explicit_kd) if explicit_kd else None,
                     "spp": int(path_samples[0]), "seed": int(path_samples[1])}
        _render_entry(scene, size, kd, overrides, preset, key, entry, progress, memory_budget, tree_variant)
        info = _read_entry(entry)
        if info is None:
            raise RuntimeError(f"trace cache entry {entry} was not written completely")
        trace = AccessTrace.load(entry / "trace", mmap=True)
        info["cached"] = False
    else:
        info["cached"] = True
    info["path"] = str(entry)
    info["png"] = str(entry / _IMAGE)
    return scene, trace, info


def _remove(path: Path) -> None:
    """Delete a cache entry's path, whether a folder, a file or a link (what is already gone is fine)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except FileNotFoundError:
            pass


def _check_entry(entry: Path, key: str, info: dict, trace) -> None:
    """The rest of an entry against its verified ``render.json``: the image's checksum, the trace's digest
    (the entry's own trace, not another's) and the trace's size.

    Raises
    ------
    TraceIntegrityError
    """
    from tracer.trace.access import TraceIntegrityError

    try:
        image = xxhash.xxh3_64_hexdigest((entry / _IMAGE).read_bytes())
    except (FileNotFoundError, NotADirectoryError):
        raise TraceIntegrityError(f"{_IMAGE} is missing") from None
    if image != info.get("image_checksum"):
        raise TraceIntegrityError(f"{_IMAGE} does not match its checksum")
    if (entry / "trace" / _TRACE_DIGEST).read_text(encoding="ascii", errors="replace").strip() != \
            info.get("trace_digest"):
        raise TraceIntegrityError(f"the trace is not the one {_INFO} was written with")
    size = info.get("size")
    if info.get("key") != key or (trace.width, trace.height) != (size, size):
        raise TraceIntegrityError(f"{_INFO} (key {info.get('key')}, size {size}) does not describe its "
                                  f"{trace.width}x{trace.height} trace")


def _read_entry(entry: Path) -> dict | None:
    """The entry's ``render.json``, verified against ``render.json.xxh3``; None when there is no entry.

    Raises
    ------
    TraceIntegrityError
        The digest is missing or differs, or the file is not a JSON object.
    """
    from tracer.trace.access import TraceIntegrityError

    try:
        data = (entry / _INFO).read_bytes()
    except (FileNotFoundError, NotADirectoryError):
        return None
    matches = matches_checksum(entry / _INFO, data)
    if matches is None:
        raise TraceIntegrityError(f"{_INFO_DIGEST} is missing")
    if not matches:
        raise TraceIntegrityError(f"{_INFO} does not match its checksum")
    try:
        info = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        info = None
    if not isinstance(info, dict):
        raise TraceIntegrityError(f"{_INFO} is damaged (not a JSON object)")
    return info


def _complete(entry: Path) -> bool:
    """Whether ``entry`` holds an entry with a verified ``render.json`` (a concurrent run's)."""
    from tracer.trace.access import TraceIntegrityError

    try:
        return _read_entry(entry) is not None
    except TraceIntegrityError:
        return False


def _render_entry(scene, size: int, kd: str, overrides: dict, workload, key: str, entry: Path,
                  progress: bool, memory_budget: int | None, tree_variant: str | None) -> None:
    # overrides: RenderOptions fields: kd_config (a builder other than the workload's, with its defaults, or
    # None), spp and seed; workload: the Workload object, its tree the variant's; tree_variant: the name
    # asked for, recorded as asked
    from tqdm.auto import tqdm

    from tracer.rendering.render import DEFAULT_MEMORY_BUDGET, RenderOptions, render, save_png

    tree = None
    if size > _PILOT_SIZE:  # the trace streams to disk: see first that it will fit
        from analyses.output import check_free_space

        pilot = render(scene, options=RenderOptions(size=_PILOT_SIZE, keep_records=False, workload=workload,
                                                    **overrides))
        bytes_per_pixel = 4 * pilot.n_records / (pilot.width * pilot.height)
        check_free_space(f"the trace of {scene.name} at {size}x{size}", entry.parent,
                         int(1.25 * bytes_per_pixel * size * size))
        tree = pilot.tree  # the same tree the render would build
        del pilot
    tmp = make_temp_dir(entry)
    try:
        bar = tqdm(total=1, desc=f"rendering {scene.name} {size}x{size} (logging accesses)", unit="image",
                   disable=not progress, leave=False, file=sys.stderr)
        start = time.perf_counter()
        budget = DEFAULT_MEMORY_BUDGET if memory_budget is None else memory_budget
        result = render(scene, tree, RenderOptions(size=size, workload=workload, memory_budget=budget,
                                                   **overrides),
                        trace_path=tmp / "trace", metadata={"cache_key": key})
        seconds = time.perf_counter() - start
        bar.update(1)
        bar.close()
        save_png(result.image, tmp / _IMAGE)
        info = {
            "key": key, "scene": scene.name, "size": size, "kd": kd, "max_depth": int(scene.max_depth),
            "workload": workload.name, "tree_variant": tree_variant,
            "tree": result.tree.stats, "kd_config": result.tree.config.to_dict(), "totals": result.totals(),
            "timings": {**result.timings, "wall": seconds},
            "image_checksum": xxhash.xxh3_64_hexdigest((tmp / _IMAGE).read_bytes()),
            "trace_digest": (tmp / "trace" / _TRACE_DIGEST).read_text(encoding="ascii").strip(),
        }
        data = (json.dumps(info, indent=1, default=json_default) + "\n").encode("utf-8")
        write_with_checksum(tmp / _INFO, data)
        del result
        try:
            os.replace(tmp, entry)
        except OSError:
            if not _complete(entry):  # not a concurrent writer's complete entry: replace it
                _remove(entry)
                os.replace(tmp, entry)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

