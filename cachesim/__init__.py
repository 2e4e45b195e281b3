"""Cache hierarchy simulation of address streams (no ray tracing inside).

Configuration: :class:`CacheLevel`, :class:`Hierarchy`, presets
:func:`alpha21164` and :func:`modern`. Simulation: :func:`simulate`,
:func:`simulate_many`, :class:`CacheState`. Reuse distances:
:func:`reuse_distances`, :func:`reuse_profile`. Files: :func:`read_addresses`.

Compiled code of other packages calls the kernels of :mod:`cachesim.kernels`
directly, with a state's :attr:`CacheState.geometry` (a :class:`CacheGeometry`)
and :attr:`CacheState.arrays` (a :class:`CacheArrays`).
"""
from cachesim.config import PRESETS, CacheLevel, Hierarchy, alpha21164, get_hierarchy, modern
from cachesim.io import read_addresses
from cachesim.kernels import CacheArrays, CacheGeometry
from cachesim.reuse import ReuseProfile, reuse_distances, reuse_profile
from cachesim.simulate import CacheState, SimulationResult, as_addresses, simulate, simulate_many

__all__ = [
    "PRESETS", "CacheArrays", "CacheGeometry", "CacheLevel", "CacheState", "Hierarchy", "ReuseProfile",
    "SimulationResult", "alpha21164", "as_addresses", "get_hierarchy", "modern", "read_addresses", "reuse_distances", "reuse_profile",
    "simulate", "simulate_many",
]
