"""Timing helper shared by the benchmark scripts (run them as ``python benchmarks/NAME.py``)."""
import time


def best_of(repeats, function):
    """Call ``function()`` ``repeats`` times; return the fastest wall time in seconds and the last result."""
    best = float("inf")
    result = None
    for _ in range(max(1, repeats)):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result
