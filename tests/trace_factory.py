"""Seeded random access traces and a small two-level hierarchy for coherence tests.

Shared by the simulation, simulate-CLI and study tests so that no test module
imports another one (pytest would collect the imported module's tests twice
when run by path, and a test module's fixtures are not an API).
"""
from __future__ import annotations

import numpy as np

from cachesim import CacheLevel, Hierarchy
from tracer.trace.access import COUNTER_NAMES, AccessTrace, RecordKind, pack

SMALL = Hierarchy((CacheLevel("L1", 512, 32, 1, latency=2), CacheLevel("L2", 3072, 64, 3, latency=9)),
                  memory_latency=50)


def random_trace(width=8, height=6, seed=0):
    """A ``width x height`` trace whose pixels read 0-39 random records of every kind."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(0, 40, width * height)
    kinds = rng.choice([RecordKind.KD_NODE, RecordKind.INDEX_ENTRY, RecordKind.SPHERE, RecordKind.TRIANGLE,
                        RecordKind.MATERIAL, RecordKind.LIGHT], lengths.sum())
    records = pack(kinds, rng.integers(0, 60, kinds.size))
    counters = rng.integers(0, 50, (width * height, len(COUNTER_NAMES)))
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    return AccessTrace(offsets, records, counters.astype(np.int64), width, height, {})
