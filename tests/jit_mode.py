"""Whether numba compiles, for tests that size their inputs by it.

``tests/run_tests.sh --nojit`` runs the suite with ``NUMBA_DISABLE_JIT=1`` so
coverage.py sees the kernels' lines; the kernels then run as plain Python,
about a hundred times slower. A test whose cost grows with its input (rays
cast, pixels rendered) takes ``shrink(n)`` instead of ``n``: the compiled run
keeps the full input, the plain run keeps every code path on a smaller one.
Tests that cannot shrink are marked ``@pytest.mark.jit_only`` (see conftest.py).
"""
from __future__ import annotations

from numba.core import config

NOJIT = bool(config.DISABLE_JIT)


def shrink(n: int, factor: int = 10) -> int:
    """``n`` when numba compiles, ``n // factor`` (at least 1) when it does not."""
    return max(1, n // factor) if NOJIT else n
