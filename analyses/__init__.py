"""Analyses: per-scene report, paper reproduction, what-if studies.

The public API, importable from here (loaded on first use)::

    from analyses import Experiment, make_report, build_report, write_report, cached_trace
    from analyses.verdict import verdict   # the function (``analyses.verdict`` is the module)
"""
from importlib import import_module

_EXPORTS = {
    "make_report": "analyses.report", "build_report": "analyses.report", "write_report": "analyses.report",
    "Report": "analyses.report", "check_output_folder": "analyses.output",
    "cached_trace": "analyses.traces", "default_cache_dir": "analyses.traces", "trace_key": "analyses.traces",
    "Verdict": "analyses.verdict", "Experiment": "analyses.experiment",
}

__all__ = list(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'analyses' has no attribute {name!r}")
