"""How a report or the paper spends its memory budget on a trace, so that a trace of any length streams from disk.

:func:`memory_shares` splits the budget; :func:`trace_pages_limited` keeps
the trace's resident pages under their share while runs read it
(:class:`rtcommon.resident.ResidentLimit`). Results do not depend on the
budget: only where the trace's bytes wait differs.
"""
from __future__ import annotations

from rtcommon.resident import ResidentLimit, resident_file_bytes
from rtcommon.validate import require_int

#: Default memory budget for a trace, in bytes (2 GiB).
DEFAULT_MEMORY_BUDGET = 2 << 30
#: The smallest budget accepted (64 MiB).
MIN_MEMORY_BUDGET = 64 << 20


def memory_shares(memory_budget: int) -> dict:
    """How ``memory_budget`` bytes (an int of at least :data:`MIN_MEMORY_BUDGET`) are spent on a trace.

    Returns
    -------
    dict
        ``render_records``: records a render holds in RAM before writing
        them out in chunks (half); ``shared_lines``: line addresses a
        study's runs share (half, at most
        :data:`coherence.pixel_lines.SHARED_LINES_BUDGET`); ``trace_pages``:
        the trace's pages resident while runs read it (a quarter). A render
        comes before the runs, so at most three quarters are in use at once.
    """
    from coherence.pixel_lines import SHARED_LINES_BUDGET

    budget = require_int("memory_budget", memory_budget, MIN_MEMORY_BUDGET)
    return {"render_records": budget // 2, "shared_lines": min(SHARED_LINES_BUDGET, budget // 2),
            "trace_pages": budget // 4}


def trace_pages_limited(trace, shares: dict) -> ResidentLimit:
    """A context that keeps ``trace``'s resident pages (records and counters) under ``shares["trace_pages"]``
    bytes, on top of what the process's other files (its libraries) hold when it is made."""
    return ResidentLimit([trace.records, trace.counters], (resident_file_bytes() or 0) + shares["trace_pages"])
