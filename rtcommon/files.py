"""Atomic file writing: a reader sees the old file or the whole new one, never half.

Temporary files and folders are named ``.<name>~<host>~<pid>~<random>.tmp``
beside their target, so that a later run can tell whose they are: one whose
process is gone from this host is stale (:func:`remove_stale_temporaries`),
one of a live process (a concurrent run) is never touched.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import tempfile
from pathlib import Path
from typing import NamedTuple
from rtcommon.validate import InputError

#: What every temporary name ends with.
TEMP_SUFFIX = ".tmp"
_TEMP_NAME = re.compile(r"^\.(?P<name>.+)~(?P<host>[A-Za-z0-9_-]+)~(?P<pid>\d+)~[^~]*\.tmp$")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname() or "host")[:64] or "host"


def temp_prefix(name: str) -> str:
    """Prefix of a temporary file or folder standing in for ``name`` (host and PID inside)."""
    return f".{name}~{_host()}~{os.getpid()}~"


def make_temp_dir(target: str | os.PathLike) -> Path:
    """A new empty folder beside ``target`` (parents created) named by :func:`temp_prefix`."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=temp_prefix(target.name), suffix=TEMP_SUFFIX, dir=target.parent))


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):  # someone else's live process, or nonsense: keep
        return True
    return not _zombie(pid)


def _zombie(pid: int) -> bool:
    """Whether ``pid`` has died and only waits to be reaped (Linux ``/proc``; False where unknown).

    A run killed by SIGKILL stays a zombie until its parent collects it, and
    ``kill(pid, 0)`` still succeeds on it: an immediate rerun would otherwise
    take its temporaries for a live run's.
    """
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            fields = stat.read().rsplit(b")", 1)[-1].split()
    except OSError:
        return False
    return bool(fields) and fields[0] in (b"Z", b"X")


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Delete temporaries in ``folder`` left by processes of this host that no longer run.

    Only names of the :func:`temp_prefix` form are considered; those of other
    hosts (a shared file system) and of live processes are kept.

    Returns
    -------
    list of pathlib.Path
        What was removed.
    """
    folder = Path(folder)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    host = _host()
    for entry in entries:
        match = _TEMP_NAME.match(entry.name)
        if not match or match["host"] != host:
            continue
        pid = int(match["pid"])
        if pid == os.getpid() or _process_alive(pid):
            continue
        path = Path(entry.path)
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(path)
            else:
                path.unlink()
            removed.append(path)
        except OSError:
            pass  # another run cleaned it, or we may not: leave it
    return removed


def check_writable_ancestor(path: str | os.PathLike, label: str) -> Path:
    """The nearest existing folder at or above ``path``, which must be a writable folder.

    What a file or folder to be created at ``path`` needs; ``label`` starts
    each message (the option and the path the user gave).

    Raises
    ------
    NotADirectoryError
        The nearest existing entry is a file.
    PermissionError
        It is a folder this process may not write to.
    """
    probe = Path(path)
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise NotADirectoryError(f"{label}: {str(probe)!r} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise PermissionError(f"{label}: folder {str(probe)!r} is not writable")
    return probe


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it.

    The file gets the permissions a plain ``open`` would give (0666 less the
    umask), not the private 0600 of a temporary file.
    """
    if isinstance(data, str):
        raise TypeError("write_bytes_atomic needs bytes, not str (use write_text_atomic)")
    write_files_atomic({path: data})


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8, newlines kept as ``\\n``) atomically; see :func:`write_bytes_atomic`."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_files_atomic(files: dict) -> None:
    """Write several files as one unit: every one to a temporary name first, then all renamed.

    Nothing is renamed until every temporary is complete, and Ctrl-C is held
    off during the renames, so an interrupted run leaves the old set of files
    or the new one, never a mixture.

    Parameters
    ----------
    files : dict of path to bytes or str
        Contents by target path (``str`` is written as UTF-8).
    """
    umask = os.umask(0)
    os.umask(umask)
    temporaries = []
    try:
        for path, data in files.items():
            path = Path(path)
            handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=temp_prefix(path.name), suffix=TEMP_SUFFIX)
            temporaries.append((temporary, path))
            with os.fdopen(handle, "wb") as stream:
                stream.write(data.encode("utf-8") if isinstance(data, str) else data)
            os.chmod(temporary, 0o666 & ~umask)
        with _interrupts_deferred():
            for temporary, path in temporaries:
                os.replace(temporary, path)
    except BaseException:
        for temporary, _ in temporaries:
            Path(temporary).unlink(missing_ok=True)
        raise


class _interrupts_deferred:
    """Hold SIGINT until the block ends (main thread only; elsewhere a no-op)."""

    def __enter__(self):
        self.pending = False
        self.previous = None
        try:
            self.previous = signal.signal(signal.SIGINT, self._hold)
        except ValueError:  # not the main thread
            self.previous = None
        return self

    def _hold(self, signum, frame):
        self.pending = True

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)
            if self.pending:
                raise KeyboardInterrupt
        return False


def read_text_file(path: str | os.PathLike, expected: str) -> str:
    """The text of a UTF-8 file, a byte-order mark (as some editors write) skipped.

    Raises
    ------
    rtcommon.validate.InputError
        Naming the file, the line and ``expected`` (e.g. "a TOML what-if
        study") when the bytes are not UTF-8.
    """
    from rtcommon.validate import InputError

    data = Path(path).read_bytes()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise InputError(f"{path}:{line}: not a text file (byte {error.start} is not UTF-8); expected "
                         f"{expected}") from None


def regular_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if it is an existing regular file, else a clear error.

    ``what`` names the file with its article (``"an NFF file"``); messages
    read ``no such NFF file: 'p'``, ``not an NFF file: 'p' is a folder`` and
    ``not an NFF file: 'p' is not a regular file`` (a FIFO or device, which
    would hang or be read only once).

    Raises
    ------
    FileNotFoundError, IsADirectoryError, ValueError
    """
    import stat

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise FileNotFoundError(f"no such {what.split(' ', 1)[-1]}: {str(path)!r}") from None
    if stat.S_ISDIR(mode):
        raise IsADirectoryError(f"not {what}: {str(path)!r} is a folder")
    if not stat.S_ISREG(mode):
        raise InputError(f"not {what}: {str(path)!r} is not a regular file")
    return path


class NpyHeader(NamedTuple):
    """What a ``.npy`` file's header says, and its bytes (:func:`read_npy_header`)."""

    raw: bytes            #: the header's bytes, magic string included; the data follow them
    dtype: object         #: numpy.dtype as written (byte order included)
    shape: tuple
    fortran_order: bool


def read_npy_header(path: str | os.PathLike) -> NpyHeader:
    """The header of the ``.npy`` file at ``path``, read without numpy's advice about pickles.

    Raises
    ------
    ValueError
        One line saying what is wrong: not a ``.npy`` file (its first bytes
        are not the magic string), an unknown format version, or a header
        numpy cannot parse.
    OSError
        The file cannot be read.
    """
    import numpy as np

    readers = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
    with open(path, "rb") as stream:
        start = stream.read(len(np.lib.format.MAGIC_PREFIX) + 2)
        if not start.startswith(np.lib.format.MAGIC_PREFIX) or len(start) < len(np.lib.format.MAGIC_PREFIX) + 2:
            raise InputError("not a .npy file: it does not begin with the .npy magic string")
        version = (start[-2], start[-1])
        if version not in readers:
            raise InputError(f"unsupported .npy format version {version[0]}.{version[1]}")
        try:
            shape, fortran_order, dtype = readers[version](stream)
        except (ValueError, SyntaxError, TypeError, EOFError) as error:
            raise InputError(f"unreadable .npy header ({str(error).splitlines()[0]})") from None
        size = stream.tell()
        stream.seek(0)
        return NpyHeader(stream.read(size), dtype, tuple(shape), bool(fortran_order))
