"""Coherence: mappings, memory layout, cost model, scheduling and metrics."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("raytrace-coherence")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
