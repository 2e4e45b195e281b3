"""Coherence: mappings, memory layout, cost model, scheduling and metrics.

The public API, importable from here (loaded on first use, so the command
line starts fast)::

    from coherence import study, Machine, get_mapping, get_layout, get_cost_model
"""
from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("raytrace-coherence")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

_EXPORTS = {
    "study": "coherence.studies", "StudyResult": "coherence.studies", "place_layout": "coherence.studies",
    "Execution": "coherence.studies",
    "Machine": "coherence.simulation", "simulate_run": "coherence.simulation", "Run": "coherence.simulation",
    "CostModel": "coherence.cost", "get_cost_model": "coherence.cost",
    "MemoryLayout": "coherence.layout", "RecordLayout": "coherence.layout", "get_layout": "coherence.layout",
    "Distribution": "coherence.distribution", "Mapping": "coherence.mappings", "Strip": "coherence.mappings",
    "Pixel": "coherence.mappings", "Row": "coherence.mappings", "Block": "coherence.mappings",
    "DynamicBlock": "coherence.mappings", "CurveSegments": "coherence.mappings",
    "CurveTiles": "coherence.mappings", "CustomMapping": "coherence.mappings",
    "from_owner_image": "coherence.mappings", "MAPPINGS": "coherence.mappings", "get_mapping": "coherence.mappings",
    "DEFAULT_MAPPINGS": "coherence.mappings",
    "miss_map": "coherence.missmap", "MissMap": "coherence.missmap",
    "TextureLayout": "coherence.texture_layout", "misses_by_kind": "coherence.kind_misses",
    "misses_by_kind_per_layout": "coherence.kind_misses",
    "hilbert_order": "coherence.curves", "morton_order": "coherence.curves", "serpentine_order": "coherence.curves",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'coherence' has no attribute {name!r}")
