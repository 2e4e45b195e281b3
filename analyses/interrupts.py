"""Ctrl-C for the command line: one line, exit by SIGINT, never lost and never inside numba's callbacks.

:class:`InterruptsOutsideNumba` delivers an interrupt as KeyboardInterrupt
only where Python unwinds it: not while numba or llvmlite code is on the
stack (raising there crashed the process), and again when it was raised
where Python prints an exception and drops it. :func:`exit_by_sigint` ends
the process the way an interrupted Unix tool does.
"""
from __future__ import annotations

import sys


class InterruptsOutsideNumba:
    """While the command runs, Ctrl-C raises KeyboardInterrupt only in Python code numba did not call, and always.

    numba's compiled code calls back into Python: boxing a returned array
    runs ``numba.core.serialize._numba_unpickle``, compiling runs numba's
    and llvmlite's Python code (llvmlite's object-cache notifier through a
    ctypes callback). A KeyboardInterrupt raised in there is not unwound
    the way Python code expects: the tuple a kernel returns keeps a NULL
    item in place of the array whose boxing failed, and unpacking it
    crashes with a segmentation fault; in a ctypes callback it is printed
    and lost, and the half-compiled function then fails with a
    RuntimeError. So while a numba or llvmlite frame is on the stack the
    interrupt is held, and delivered again every few milliseconds until it
    lands in code outside them. Holding it through a compilation can take
    half a minute on the first run after an install, so if numba is still
    compiling :data:`ANNOUNCE_SECONDS` after the interrupt, one line says
    the interrupt was received.

    Python also drops an exception raised where nothing can catch it: in a
    weakref callback (a ``WeakKeyDictionary``'s clean-up), a ``__del__``
    method, a garbage-collector callback. It prints "Exception ignored"
    and runs on, and the command would finish with exit 0. While the
    command runs, such a KeyboardInterrupt is taken from
    ``sys.unraisablehook`` without a word and delivered again; and should
    an interrupt be lost where even that hook does not see it, leaving the
    block normally raises it.

    Installed only in the main thread and only over Python's own handler
    (an ignored SIGINT stays ignored).

    Parameters
    ----------
    name : str
        How the announcement starts, e.g. ``"coherence report"``.
    """

    #: How often a held interrupt is delivered again.
    RETRY_SECONDS = 0.01
    #: How long an interrupt is held in a compilation before a line says so.
    ANNOUNCE_SECONDS = 0.5

    def __init__(self, name: str = "coherence"):
        self.name = name

    def __enter__(self):
        import signal
        import threading

        self.pending = False
        self.received = False
        self.active = False
        self.announced = False
        self.compiling = False
        self.retrying = False
        self.timer = None
        self.announcer = None
        self.previous = None
        self.previous_hook = None
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self.previous = signal.signal(signal.SIGINT, self._handle)
            self.previous_hook = sys.unraisablehook
            sys.unraisablehook = self._unraisable
            self.main_thread = threading.main_thread().ident
            self.active = True
        return self

    def _handle(self, signum, frame):
        self.received = True
        if not self.active:
            return  # a retry arriving as the block ends: __exit__ raises for it
        if _numba_on_stack(frame):
            self.compiling = _numba_compiling(frame)
            self._hold()
            return
        self.pending = False
        raise KeyboardInterrupt

    def _hold(self):
        """Deliver the interrupt again in :data:`RETRY_SECONDS` (and announce a long hold once)."""
        import threading

        if not self.pending and self.announcer is None:
            self.announcer = threading.Timer(self.ANNOUNCE_SECONDS, self._announce)
            self.announcer.daemon = True
            self.announcer.start()
        self.pending = True
        if not self.retrying:
            self.retrying = True
            self.timer = threading.Timer(self.RETRY_SECONDS, self._retry)
            self.timer.daemon = True
            self.timer.start()

    def _unraisable(self, unraisable):
        if self.active and isinstance(unraisable.exc_value, KeyboardInterrupt):
            self.compiling = False
            self._hold()  # dropped where Python prints and runs on: deliver it again
            return
        (self.previous_hook or sys.__unraisablehook__)(unraisable)

    def _retry(self):
        import signal

        self.retrying = False  # before the interrupt: its handler may need the next retry at once
        if self.active and self.pending:
            # a real SIGINT to the main thread, not _thread.interrupt_main(): that one does not wake a main
            # thread blocked in a wait (time.sleep, a lock, a future's result). One at a time: the next
            # retry is due only once _handle has run again.
            signal.pthread_kill(self.main_thread, signal.SIGINT)

    def _announce(self):
        if self.active and self.pending and self.compiling and not self.announced:
            self.announced = True
            try:
                sys.stderr.write(f"{self.name}: interrupt received; stopping when numba has compiled the current "
                                 "function (the first run after an install compiles them)\n")
                sys.stderr.flush()
            except (OSError, ValueError):
                pass

    def __exit__(self, kind, value, traceback):
        import signal

        was_active, self.active = self.active, False
        for timer in (self.timer, self.announcer):
            if timer is not None:
                timer.cancel()
        if self.timer is not None:
            self.timer.join()  # a retry under way has sent its SIGINT ...
        if was_active:
            _handle_pending_signals()  # ... and _handle, inactive now, takes it before Python's handler returns
            signal.signal(signal.SIGINT, self.previous)
            sys.unraisablehook = self.previous_hook
        if self.received and kind is None:
            raise KeyboardInterrupt  # held to the end, or lost where no hook saw it
        return False


def _handle_pending_signals() -> None:
    """Give Python a point at which it runs the handlers of signals that have arrived (a call does)."""


def _module_names(frame):
    while frame is not None:
        yield str(frame.f_globals.get("__name__", ""))
        frame = frame.f_back


def _numba_on_stack(frame) -> bool:
    """Whether ``frame`` or a frame that called it belongs to numba or llvmlite."""
    return any(name.partition(".")[0] in ("numba", "llvmlite") for name in _module_names(frame))


def _numba_compiling(frame) -> bool:
    """Whether ``frame`` or a frame that called it is numba's pass manager, which runs every step of a
    compilation, typing to machine code. Not numba.core.compiler alone: loading a function from numba's
    cache rebuilds it there too, under numba.core.compiler_lock."""
    return any(name == "numba.core.compiler_machinery" for name in _module_names(frame))


def exit_by_sigint(status: int) -> None:
    """Leave at once, the way an interrupted Unix tool does: killed by SIGINT (the shell says 130),
    so that a calling script sees the interrupt. The unwinding has already removed temporaries
    (and any left are named by PID, so the next run removes them)."""
    import os
    import signal

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, RuntimeError):  # RuntimeError: a flush re-entered from a signal handler
            pass
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGINT)
    sys.exit(status)  # pragma: no cover - only if the signal could not be delivered
