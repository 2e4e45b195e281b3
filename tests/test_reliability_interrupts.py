"""Reliability under Ctrl-C: an interrupt ends a run in one line, wherever it lands."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from reliability_files import ROOT


# ------------------------------------------------------------- Ctrl-C where Python drops exceptions
_DROPPED_INTERRUPT = textwrap.dedent('''
    import signal, sys, time, weakref
    from analyses.interrupts import InterruptsOutsideNumba

    def interrupt_here():
        signal.raise_signal(signal.SIGINT)
        for _ in range(1000):  # Python runs the handler here, inside the callback
            pass

    class Key:
        pass

    class Finalized:
        def __del__(self):
            interrupt_here()

    def in_weak_key_dictionary_callback():
        table = weakref.WeakKeyDictionary()
        key = Key()
        table[key] = 1
        watcher = weakref.ref(key, lambda ref: interrupt_here())  # runs beside the table's own clean-up
        del key
        return watcher

    def in_del():
        Finalized()

    def swallowed_by_a_library():
        try:
            interrupt_here()
        except KeyboardInterrupt:
            pass

    try:
        with InterruptsOutsideNumba():
            globals()[sys.argv[1]]()
            for _ in range(100):  # the run goes on for a second
                time.sleep(0.01)
            print("ran on")
        print("finished")
    except KeyboardInterrupt:
        print("interrupted")
''')


def _interruptible():
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)  # a test run in the background starts with SIGINT ignored


def _python(code: str, *argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, env=env,
                          timeout=120, preexec_fn=_interruptible)


@pytest.mark.parametrize("where, said", [("in_weak_key_dictionary_callback", "interrupted\n"),
                                         ("in_del", "interrupted\n"),
                                         ("swallowed_by_a_library", "ran on\ninterrupted\n")])
def test_an_interrupt_python_drops_still_ends_the_run(where, said):
    """Ctrl-C raised where Python prints "Exception ignored" and runs on (a weakref callback, ``__del__``)
    interrupts the command at once, without that message; one a library catches, at the latest when the
    command ends.

    Fails (prints "ran on", "finished" and "Exception ignored") if ``InterruptsOutsideNumba.__enter__`` no
    longer installs ``_unraisable`` as ``sys.unraisablehook`` (the callback cases) or if ``__exit__`` no
    longer raises for ``self.received`` (the library case).
    """
    done = _python(_DROPPED_INTERRUPT, where)
    assert (done.stdout, done.stderr) == (said, "")


_HELD_IN_NUMBA = textwrap.dedent('''
    import json, signal, sys, time
    from analyses.interrupts import InterruptsOutsideNumba

    class Clock:
        """stderr that notes when each line came."""
        def __init__(self):
            self.lines = []
        def write(self, text):
            self.lines.append((time.monotonic(), text))
        def flush(self):
            pass

    # A function of a numba module: sys.argv[1] is numba.core.compiler_machinery (compiling) or one that
    # loading a compiled function from numba's cache runs; Ctrl-C comes as it starts, and it runs on for 2 s.
    namespace = {"__name__": sys.argv[1]}
    exec("import signal, time\\n"
         "def work(seconds):\\n"
         "    sent = time.monotonic()\\n"
         "    signal.raise_signal(signal.SIGINT)\\n"
         "    while time.monotonic() < sent + seconds:\\n"
         "        time.sleep(0.01)\\n"
         "    return sent\\n", namespace)
    sys.stderr = clock = Clock()
    try:
        with InterruptsOutsideNumba("test"):
            sent = namespace["work"](2.0)
            returned = time.monotonic()
            time.sleep(1.0)
            print("ran on")
    except KeyboardInterrupt:
        stopped = time.monotonic()
    print(json.dumps({"said": [[at - sent, text] for at, text in clock.lines],
                      "returned": returned - sent, "stopped": stopped - sent}))
''')


def test_an_interrupt_held_by_a_compilation_is_announced_within_a_second():
    """Ctrl-C while numba compiles is held until the compilation ends, and one line says so within 1 s;
    while numba loads a compiled function it is held without a word.

    Fails if ``InterruptsOutsideNumba._hold`` no longer starts the announcer (no line), or if
    ``_announce`` no longer asks ``self.compiling``, or ``_numba_compiling`` takes any numba.core.compiler*
    module for a compilation again (a line while numba loads a function from its cache).
    """
    for module, lines in (("numba.core.compiler_machinery", 1), ("numba.core.caching", 0), ("numba.core.compiler", 0),
                          ("numba.core.compiler_lock", 0)):
        done = _python(_HELD_IN_NUMBA, module)
        result = json.loads(done.stdout)
        said = [text for _, text in result["said"] if text.strip()]
        assert len(said) == lines, result
        assert result["returned"] >= 2.0 and result["returned"] <= result["stopped"] <= result["returned"] + 0.5
        if lines:
            assert said[0].startswith("test: interrupt received; stopping when numba has compiled")
            assert result["said"][0][0] < 1.0


_LATE_INTERRUPT = textwrap.dedent('''
    import os, signal, sys
    from analyses import cli
    from analyses.commands import cachesim

    class InterruptAtTeardown:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)

    def run(args):
        cachesim.left_over = InterruptAtTeardown()  # lives until Python tears the modules down
        return 0

    cachesim.run = run
    sys.argv = ["coherence", "cachesim", "addresses.txt"]
    sys.exit(cli.main())
''')


def test_a_finished_command_line_leaves_before_pythons_teardown():
    """Once a command has finished, the process ends after the exit handlers, without Python's teardown:
    a Ctrl-C there found no handler and killed the process without a word (a second after a report).

    Fails (the object's SIGINT at teardown kills the process: rc -2) if ``main`` no longer registers
    ``_leave_after_exit_handlers``.
    """
    done = _python(_LATE_INTERRUPT)
    assert (done.returncode, done.stderr) == (0, "")


_LOADING_INTERRUPT = textwrap.dedent('''
    import runpy, signal, sys

    class InterruptWhileLoading:
        """Ctrl-C as the command line imports its interrupt handling."""
        def find_spec(self, name, path=None, target=None):
            if name == "analyses.interrupts" and not hasattr(self, "done"):
                self.done = signal.raise_signal(signal.SIGINT)
            return None

    sys.meta_path.insert(0, InterruptWhileLoading())
    sys.argv = ["coherence", "--version"]
    runpy.run_module("analyses", run_name="__main__", alter_sys=True)
''')


def test_ctrl_c_while_python_m_analyses_loads_prints_one_line():
    """``python -m analyses`` interrupted while it imports the command line prints one line and dies by SIGINT.

    Fails (a KeyboardInterrupt traceback) if ``analyses/__main__.py`` no longer catches KeyboardInterrupt
    around its import of ``analyses.cli``.
    """
    import signal

    done = _python(_LOADING_INTERRUPT)
    assert (done.returncode, done.stderr) == (-signal.SIGINT, "coherence: interrupted\n")


_LOADING_INTERRUPT_SIGINT_BLOCKED = textwrap.dedent('''
    import runpy, signal, sys

    class InterruptWhileLoading:
        """Ctrl-C as the command line imports its interrupt handling, in a process whose SIGINT is blocked."""
        def find_spec(self, name, path=None, target=None):
            if name == "analyses.interrupts" and not hasattr(self, "done"):
                self.done = True
                raise KeyboardInterrupt
            return None

    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    sys.meta_path.insert(0, InterruptWhileLoading())
    sys.argv = ["coherence", "--version"]
    runpy.run_module("analyses", run_name="__main__", alter_sys=True)
''')


def test_python_m_analyses_interrupted_while_loading_exits_130_when_sigint_cannot_kill_it():
    """``python -m analyses`` interrupted while it loads, in a process where SIGINT cannot end it, exits with
    status 130 after its one line, as the ``coherence`` script's ``exit_by_sigint`` does.

    Fails (a NameError traceback for ``main``, status 1) if ``analyses/__main__.py`` sends itself SIGINT
    without ``exit_by_sigint``'s fallback (its ``os.kill`` alone, as before).
    """
    done = _python(_LOADING_INTERRUPT_SIGINT_BLOCKED)
    assert (done.returncode, done.stderr) == (130, "coherence: interrupted\n")
