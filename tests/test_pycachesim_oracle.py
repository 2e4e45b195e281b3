"""Counts equal pycachesim's on identical LRU and FIFO configurations.

pycachesim 0.3.1 is a test-only oracle run in a subprocess (see
pycachesim_oracle.py). Its known faults are not taken as truth: only its bulk
load path is used (the single-address ``load`` truncates addresses to 32
bits), random replacement is not compared (wrong for non-power-of-two
associativity), and neither is inclusion (its "inclusive" does not
back-invalidate); those are checked against tests/reference_cache.py instead.
Evictions are not compared: pycachesim counts only dirty write-backs.
"""
import numpy as np
import pytest

import pycachesim_oracle
from cachesim import CacheLevel, Hierarchy, alpha21164_noninclusive, modern, simulate

pytestmark = pytest.mark.skipif(
    not pycachesim_oracle.available(),
    reason=f"pycachesim oracle not installed in {pycachesim_oracle.ORACLE_DIR} "
           "(tests/run_tests.sh installs it with pip install --target)")


def streams():
    rng = np.random.default_rng(11)
    n = 60000
    walk = np.cumsum(rng.integers(-300, 320, n)) + (1 << 34)  # above 2**32
    yield "local walk above 2**32", walk
    yield "uniform", rng.integers(0, 1 << 24, n)
    yield "strided to one set", (np.arange(n) % 40) * 8192 * 3
    hot = rng.integers(0, 1 << 14, n)
    yield "hot and cold", np.where(rng.random(n) < 0.9, hot, rng.integers(0, 1 << 30, n))


def hierarchies():
    yield alpha21164_noninclusive()  # pycachesim has no back-invalidation
    yield modern()
    for policy in ("lru", "fifo"):
        yield Hierarchy((
            CacheLevel("L1", 4096, 32, 4, policy),
            CacheLevel("L2", 3 * 64 * 128, 64, 3, policy),       # 128 sets, 3 ways
            CacheLevel("L3", 64 * 1024, 64, "full", policy),
        ), name=f"small-{policy}")


@pytest.mark.parametrize("hierarchy", list(hierarchies()), ids=lambda h: h.name)
def test_counts_equal_pycachesim(hierarchy):
    for name, stream in streams():
        stream = np.asarray(stream, dtype=np.uint64)
        ours = simulate(stream, hierarchy)
        theirs = pycachesim_oracle.run(stream, hierarchy)
        assert ours.accesses.tolist() == theirs["accesses"], name
        assert ours.hits.tolist() == theirs["hits"], name
        assert ours.misses.tolist() == theirs["misses"], name
