"""Settings every test module shares.

``jit_only``
    Marks a test whose inputs are too large to run as plain Python (a render
    of thousands of rays, a long cache stream). ``tests/run_tests.sh --nojit``
    sets ``NUMBA_DISABLE_JIT=1`` so coverage.py can see inside the kernels;
    these tests are skipped there and run in the ordinary, compiled pass.
    Prefer shrinking a test's input to marking it.

``--numba-times``
    Prints, at the end of the session, how long each numba kernel took to
    compile (or to load from numba's on-disk cache), slowest first. Run it
    once with ``NUMBA_CACHE_DIR`` pointing at an empty folder to see what a
    clean CI run pays.
"""
from __future__ import annotations

import os
import time
from collections import defaultdict

import pytest

NOJIT = os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")


def pytest_addoption(parser):
    parser.addoption("--numba-times", action="store_true",
                     help="report per-kernel numba compile and cache-load times at the end of the session")


def pytest_configure(config):
    config.addinivalue_line("markers", "jit_only: too slow as plain Python; skipped when NUMBA_DISABLE_JIT=1")
    if config.getoption("--numba-times") and not NOJIT:
        config.pluginmanager.register(_CompileTimes(), "numba-times")


def pytest_collection_modifyitems(config, items):
    if not NOJIT:
        return
    skip = pytest.mark.skip(reason="jit_only: too slow with NUMBA_DISABLE_JIT=1")
    for item in items:
        if "jit_only" in item.keywords:
            item.add_marker(skip)


class _CompileTimes:
    """Times ``Dispatcher.compile`` per kernel and signature, callees excluded.

    numba compiles a kernel's njit callees inside the kernel's own compile;
    a stack of running timers subtracts their time from the caller's so each
    row is what that function alone cost. Time spent in worker processes
    (the Dask tests) is not seen.
    """

    def __init__(self):
        from numba.core.dispatcher import Dispatcher

        self.rows = defaultdict(lambda: [0.0, 0, 0])  # name -> [seconds, compiles, cache loads]
        self.signatures = defaultdict(list)  # name -> argument types of each specialization
        self._stack = []
        self._dispatcher = Dispatcher
        self._original = Dispatcher.compile
        original, rows, stack, signatures = self._original, self.rows, self._stack, self.signatures

        def timed_compile(dispatcher, sig):
            py = dispatcher.py_func
            if py.__module__.startswith("numba."):
                # numba's own overloads (np.full, str(), ...) count as part
                # of the project kernel that made numba compile them
                return original(dispatcher, sig)
            known = len(dispatcher.overloads)
            hits = sum(dispatcher._cache_hits.values())
            stack.append(0.0)
            start = time.process_time()
            try:
                return original(dispatcher, sig)
            finally:
                elapsed = time.process_time() - start
                inner = stack.pop()
                if stack:
                    stack[-1] += elapsed
                if len(dispatcher.overloads) > known:
                    name = f"{py.__module__}.{py.__qualname__}"
                    row = rows[name]
                    signatures[name].append(str(sig))
                    row[0] += elapsed - inner
                    if sum(dispatcher._cache_hits.values()) > hits:
                        row[2] += 1
                    else:
                        row[1] += 1

        Dispatcher.compile = timed_compile

    def pytest_unconfigure(self, config):
        self._dispatcher.compile = self._original

    def pytest_terminal_summary(self, terminalreporter):
        write = terminalreporter.write_line
        terminalreporter.section("numba compile times, CPU seconds (callees excluded)")
        total = sum(row[0] for row in self.rows.values())
        write(f"{'seconds':>8} {'compiled':>8} {'loaded':>6}  kernel")
        for name, (seconds, compiled, loaded) in sorted(self.rows.items(), key=lambda kv: -kv[1][0]):
            if seconds >= 0.05:
                write(f"{seconds:8.2f} {compiled:8d} {loaded:6d}  {name}")
        compiled = sum(row[1] for row in self.rows.values())
        loaded = sum(row[2] for row in self.rows.values())
        write(f"{total:8.2f} {compiled:8d} {loaded:6d}  total over {len(self.rows)} functions")
        # several specializations of one kernel usually mean callers pass
        # different dtypes or layouts: each costs a full compile
        for name, signatures in sorted(self.signatures.items()):
            if len(signatures) > 1:
                write(f"{name}:")
                for signature in signatures:
                    write(f"    {signature}")
