"""Cache hierarchy simulation of address streams (no ray tracing inside).

Configuration: :class:`CacheLevel`, :class:`Hierarchy`, :class:`Tlb` (a data
TLB, an option of a hierarchy), presets :func:`alpha21164` (inclusive, as the
manuals describe it), :func:`alpha21164_noninclusive`,
:func:`alpha21164_with_dtb` (with the 21164's data TLB,
:func:`alpha21164_dtb`) and :func:`modern`; :class:`Prefetcher` (a level's
hardware prefetcher, :mod:`cachesim.prefetch`); :class:`SharedHierarchy` (levels shared by
the hardware threads of a multicore machine), simulated by
:func:`simulate_threads` (with write-invalidate coherence). Simulation: :func:`simulate`,
:func:`simulate_many` (accesses may be writes), :class:`CacheState`. Reuse
distances: :func:`reuse_distances`, :func:`reuse_profile`, :class:`ReuseCounter` (a stream in pieces). Files:
:func:`read_addresses`.

Compiled code of other packages calls the kernels of :mod:`cachesim.kernels`
(and :mod:`cachesim.tlb`) directly, with a state's
:attr:`CacheState.geometry` (a :class:`CacheGeometry`) and
:attr:`CacheState.arrays` (a :class:`CacheArrays`).
"""
from cachesim.config import (PRESETS, CacheLevel, Hierarchy, alpha21164, alpha21164_noninclusive,
                             alpha21164_with_dtb, get_hierarchy, modern)
from cachesim.io import read_addresses
from cachesim.prefetch_config import Prefetcher
from cachesim.kernels import CacheArrays, CacheGeometry
from cachesim.reuse import ReuseCounter, ReuseProfile, reuse_distances, reuse_profile
from cachesim.multicore import simulate_threads
from cachesim.multicore_state import SharedState
from cachesim.sharing import SharedHierarchy
from cachesim.simulate import CacheState, SimulationResult, as_addresses, simulate, simulate_many
from cachesim.tlb_config import Tlb, alpha21164_dtb

__all__ = [
    "PRESETS", "CacheArrays", "CacheGeometry", "CacheLevel", "CacheState", "Hierarchy", "Prefetcher", "ReuseCounter", "ReuseProfile",
    "SharedHierarchy", "SharedState", "SimulationResult", "Tlb", "alpha21164", "alpha21164_dtb", "alpha21164_noninclusive", "alpha21164_with_dtb",
    "as_addresses", "get_hierarchy", "modern", "read_addresses", "reuse_distances", "reuse_profile",
    "simulate", "simulate_many", "simulate_threads",
]
