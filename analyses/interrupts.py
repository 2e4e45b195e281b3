"""Ctrl-C for the command line: one line, exit by SIGINT, and never inside numba's callbacks.

:class:`InterruptsOutsideNumba` holds an interrupt while numba or llvmlite
code is on the Python stack (raising it there crashed the process: a segfault);
:func:`exit_by_sigint` ends the process the way an interrupted Unix tool does.
"""
from __future__ import annotations

import sys


class InterruptsOutsideNumba:
    """While the command runs, Ctrl-C raises KeyboardInterrupt only in Python code numba did not call.

    numba's compiled code calls back into Python: boxing a returned array
    runs ``numba.core.serialize._numba_unpickle``, compiling runs numba's
    and llvmlite's Python code (llvmlite's object-cache notifier through a
    ctypes callback). A KeyboardInterrupt raised in there is not unwound
    the way Python code expects: the tuple a kernel returns keeps a NULL
    item in place of the array whose boxing failed, and unpacking it
    crashes (rc -11); in a ctypes callback it is printed and
    lost, and the half-compiled function then fails with a RuntimeError.
    So while a numba or llvmlite frame is on the stack the interrupt is
    held, and delivered again every few milliseconds until it lands in
    code outside them. Installed only in the main thread and only over
    Python's own handler (an ignored SIGINT stays ignored).
    """

    RETRY_SECONDS = 0.01

    def __enter__(self):
        import signal
        import threading

        self.pending = False
        self.active = False
        self.timer = None
        self.previous = None
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self.previous = signal.signal(signal.SIGINT, self._handle)
            self.active = True
        return self

    def _handle(self, signum, frame):
        import threading

        if _numba_on_stack(frame):
            self.pending = True
            if self.timer is None or not self.timer.is_alive():
                self.timer = threading.Timer(self.RETRY_SECONDS, self._retry)
                self.timer.daemon = True
                self.timer.start()
            return
        self.pending = False
        raise KeyboardInterrupt

    def _retry(self):
        import _thread

        if self.active and self.pending:
            _thread.interrupt_main()  # runs _handle again, as a new SIGINT would

    def __exit__(self, kind, value, traceback):
        import signal

        if self.active:
            self.active = False
            signal.signal(signal.SIGINT, self.previous)
        if self.timer is not None:
            self.timer.cancel()
        if self.pending and kind is None:
            raise KeyboardInterrupt
        return False


def _numba_on_stack(frame) -> bool:
    """Whether ``frame`` or a frame that called it belongs to numba or llvmlite."""
    while frame is not None:
        if str(frame.f_globals.get("__name__", "")).partition(".")[0] in ("numba", "llvmlite"):
            return True
        frame = frame.f_back
    return False


def exit_by_sigint(status: int) -> None:
    """Leave at once, the way an interrupted Unix tool does: killed by SIGINT (the shell says 130),
    so that a calling script sees the interrupt. The unwinding has already removed temporaries
    (and any left are named by PID, so the next run removes them)."""
    import os
    import signal

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGINT)
    sys.exit(status)  # pragma: no cover - only if the signal could not be delivered
