"""Checks every subcommand makes before it computes anything.

A run that fails after minutes of rendering, or after filling the disk, is
worse than one that refuses at once. These functions look at the paths and
the sizes a command was given and raise
:class:`rtcommon.validate.InputError` (or an ``OSError`` subclass) with a
one-line message naming the option, so the command line prints
``coherence CMD: error: ...`` and exits with 2 before any work.
"""
from __future__ import annotations

import os
from pathlib import Path

from rtcommon.files import check_writable_ancestor, regular_file
from rtcommon.validate import InputError

#: Bytes a render holds in memory per pixel: the image (3 float64), 18 int64
#: counters, offsets and record counts, with room for temporaries. Measured:
#: balls without logging peaks at 204 MB at 256x256 and 374 MB at 1024x1024,
#: about 180 bytes per pixel beyond the fixed start-up.
RENDER_BYTES_PER_PIXEL = 256
#: Bytes a replay (simulate, report, whatif, paper) holds per pixel: the
#: trace's offsets and counters, the mappings' pixel orders, per-pixel costs
#: and the report's maps, for every trace held at once.
REPLAY_BYTES_PER_PIXEL = 512
#: Image size of the pilot render that estimates a trace's bytes per pixel.
PILOT_SIZE = 32


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo") as stream:
            for line in stream:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not on Linux
        return None


def check_memory(option: str, size: int, *, bytes_per_pixel: int = REPLAY_BYTES_PER_PIXEL, extra_bytes: int = 0,
                 images: int = 1) -> None:
    """Refuse an image size whose per-pixel arrays cannot fit in the memory available now.

    Parameters
    ----------
    option : str
        How the message names the size (``--size``).
    size : int
        Image width and height.
    bytes_per_pixel : int
        :data:`RENDER_BYTES_PER_PIXEL` or :data:`REPLAY_BYTES_PER_PIXEL`.
    extra_bytes : int
        Further bytes held at once (records kept in memory).
    images : int
        Per-pixel array sets held at once.

    Raises
    ------
    InputError
        ``"--size 20000 needs about 190.7 GB of memory, 21.6 GB available"``.
    """
    from analyses.output import size_text

    needed = images * size * size * bytes_per_pixel + extra_bytes
    available = available_memory()
    if available is not None and needed > available:
        raise InputError(f"{option} {size} needs about {size_text(needed)} of memory, {size_text(available)} "
                         "available")


def check_scene_argument(scene, option: str = "SCENE") -> None:
    """A scene given as a path must be a regular file (a FIFO would hang the reader)."""
    from tracer.scenes.catalog import NAMED_SCENES
    from tracer.scenes.study import canonical_scene_name

    if scene is None or canonical_scene_name(str(scene)) in NAMED_SCENES:
        return
    if os.path.lexists(scene):
        check_input_file(option, scene)


def check_disk(option: str, folder, needed: int) -> None:
    """Refuse when ``needed`` bytes will not fit on the file system holding ``folder``."""
    from analyses.output import check_free_space

    check_free_space(option, folder, needed)


def check_input_file(option: str, path) -> Path:
    """``path`` as a Path, refused unless it is an existing regular file (no folder, FIFO, device).

    Raises
    ------
    FileNotFoundError, IsADirectoryError, InputError
        :func:`rtcommon.files.regular_file`'s, with ``option`` in front.
    """
    try:
        return regular_file(path, "a file")
    except (FileNotFoundError, IsADirectoryError, ValueError) as error:
        raise type(error)(f"{option}: {error}") from None


def check_output_file(option: str, path) -> Path:
    """Refuse an output file path that cannot be written, before any work.

    Raises
    ------
    FileNotFoundError
        Its folder does not exist.
    IsADirectoryError
        It names an existing folder.
    PermissionError
        Its folder is not writable.
    InputError
        It exists and is not a regular file, or its folder is a file.
    """
    path = Path(path).expanduser()
    parent = path.parent
    if path.is_dir():
        raise IsADirectoryError(f"{option} {str(path)!r} is a folder, not a file")
    if path.exists() and not path.is_file():
        raise InputError(f"{option} {str(path)!r} exists and is not a regular file")
    if not parent.exists():
        raise FileNotFoundError(f"{option} {str(path)!r}: folder {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise InputError(f"{option} {str(path)!r}: {str(parent)!r} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(f"{option} {str(path)!r}: folder {str(parent)!r} is not writable")
    return path


def check_trace_folder(option: str, path) -> Path:
    """Refuse a trace output folder that is a file, a non-trace folder, or unwritable."""
    path = Path(path).expanduser()
    if path.exists():
        if not path.is_dir():
            raise NotADirectoryError(f"{option} {str(path)!r} exists and is a file, not a trace folder")
        from tracer.trace.check import META_FILE

        if not (path / META_FILE).is_file() and any(path.iterdir()):
            raise InputError(f"{option} {str(path)!r} exists and is not a trace folder; not overwriting")
    check_writable_ancestor(path.parent, f"{option} {str(path)!r}")
    return path


def check_range(option: str, value, minimum=None, maximum=None) -> None:
    """Raise InputError naming ``option`` unless every value (one or a list) is in [minimum, maximum]."""
    for item in value if isinstance(value, (list, tuple)) else [value]:
        if item is None:
            continue
        if item != item or (minimum is not None and item < minimum) or (maximum is not None and item > maximum):
            if minimum is not None and maximum is not None:
                wanted = f"in [{minimum}, {maximum}]"
            else:
                wanted = f">= {minimum}" if minimum is not None else f"<= {maximum}"
            raise InputError(f"{option} must be {wanted}, got {item}")


def check_max_depth(value) -> None:
    """Raise InputError naming ``--max-depth`` unless ``value`` (None: the scene's) is a depth the renderer takes."""
    from tracer.scenes.model import MAX_DEPTH

    check_range("--max-depth", value, 1, MAX_DEPTH)


def require_distributed() -> None:
    """Raise InputError naming the pip command of the ``cluster`` extra when Dask's ``distributed`` is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise InputError("--dask needs the 'distributed' package: pip install 'raytrace-coherence[cluster]'") from None
