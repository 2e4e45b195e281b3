"""Output folders: checked before any long work starts, then created."""
from __future__ import annotations

import os
from pathlib import Path

from rtcommon.files import check_writable_ancestor
from rtcommon.validate import InputError


def size_text(n_bytes: float) -> str:
    """``n_bytes`` in the largest unit it fills at least once, one decimal: ``"31.2 GB"``, ``"9.8 kB"``,
    ``"12 bytes"`` (units of 1024)."""
    for unit, scale in (("GB", 2**30), ("MB", 2**20), ("kB", 2**10)):
        if abs(n_bytes) >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes:.0f} bytes"


def check_free_space(what: str, folder, needed: int) -> None:
    """Refuse when ``needed`` bytes will not fit on the file system holding ``folder`` (or its nearest parent).

    Raises
    ------
    InputError
        ``"<what> needs about 31.2 GB of disk space in '/data', 12.0 GB free"``.
    """
    import shutil

    probe = Path(folder).expanduser().absolute()
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    try:
        free = shutil.disk_usage(probe).free
    except OSError:
        return
    if needed > free:
        raise InputError(f"{what} needs about {size_text(needed)} of disk space in {str(probe)!r}, "
                         f"{size_text(free)} free")


def check_output_folder(out) -> Path:
    """Raise unless ``out`` is, or can become, a writable folder; create nothing.

    Raises
    ------
    InputError
        ``out`` is an existing file, or an empty name (``Path('')`` would be
        the current folder, which the user did not name).
    NotADirectoryError
        A parent on its path is a file.
    PermissionError
        ``out`` (or its nearest existing parent) is not writable.
    """
    if not str(out).strip():
        raise InputError(f"output folder {str(out)!r} is an empty name; give a folder ('.' for the current one)")
    path = Path(out).expanduser()
    if path.exists() and not path.is_dir():
        raise InputError(f"output folder {str(out)!r} exists and is not a folder")
    check_writable_ancestor(path, f"output folder {str(out)!r}")
    return path


def prepare_output_folder(out) -> Path:
    """Check ``out`` (see :func:`check_output_folder`), create it and prove it writable with a probe file.

    Raises
    ------
    InputError, PermissionError
        With the folder named, when it cannot be created or written.
    """
    import tempfile

    path = check_output_folder(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
        handle, probe = tempfile.mkstemp(dir=path, prefix=".probe.", suffix=".tmp")
        os.close(handle)
        os.unlink(probe)
    except PermissionError as error:
        raise PermissionError(f"output folder {str(out)!r} is not writable: {error.strerror}") from None
    except OSError as error:
        raise InputError(f"cannot create output folder {str(out)!r}: {error.strerror}") from None
    return path


def csv_text(frame) -> str:
    """A table as the CSV text every output file uses: no index, ``\n`` line ends, floats to 10 significant digits."""
    return frame.to_csv(index=False, lineterminator="\n", float_format="%.10g")
