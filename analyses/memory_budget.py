"""How a report or the paper spends its memory budget, so that a trace of any length streams from disk.

The budget is the whole process's: :func:`memory_shares` sets aside what the
process takes whatever the trace (:data:`PROCESS_BYTES`) and what its runs
take per pixel (:data:`RUN_BYTES_PER_PIXEL` for each run at once, one per
CPU as far as the budget allows: :func:`runs_at_once`), and splits the rest
among the trace's uses; :func:`trace_pages_limited` keeps the
trace's resident pages under their share while runs read it
(:class:`rtcommon.resident.ResidentLimit`). Results do not depend on the
budget: only where the trace's bytes wait differs.
"""
from __future__ import annotations

from rtcommon.resident import ResidentLimit, resident_file_bytes
from rtcommon.validate import InputError, require_int

#: Default memory budget of a report or the paper, in bytes (2 GiB).
DEFAULT_MEMORY_BUDGET = 2 << 30
#: What the process takes whatever the trace: the interpreter, numpy,
#: pandas, matplotlib, numba and the compiled kernels (a 512x512 render
#: alone peaks at 0.46 GB; a 2048x2048 report idles at 0.47-0.53 GB between
#: its steps), with room for the figures.
PROCESS_BYTES = 640 << 20
#: What one run of a study takes per pixel of the image at its height: the
#: distribution's tasks, the pixels' line offsets and compute cycles, the
#: run's outputs. tests/test_resident.py measures it as the growth of a
#: run's peak with the image (63 bytes a pixel on every default mapping).
RUN_BYTES_PER_PIXEL = 96
#: The least the trace's uses may get (64 MiB).
MIN_TRACE_BYTES = 64 << 20
#: The smallest budget accepted, whatever the image.
MIN_MEMORY_BUDGET = PROCESS_BYTES + MIN_TRACE_BYTES


def memory_shares(memory_budget: int, n_pixels: int = 0, n_jobs: int = 1) -> dict:
    """How a process of ``memory_budget`` bytes spends what its image and runs leave on the trace.

    Parameters
    ----------
    memory_budget : int
        Bytes the whole process may take.
    n_pixels : int
        Pixels of the image.
    n_jobs : int
        Runs simulated at once in this process.

    Returns
    -------
    dict
        Of what is left after :data:`PROCESS_BYTES` and ``n_jobs *
        n_pixels * RUN_BYTES_PER_PIXEL``: ``render_records``, records a
        render holds in RAM before writing them out in chunks (half);
        ``shared_lines``, line addresses a study's runs share (three
        quarters, at most :data:`coherence.pixel_lines.SHARED_LINES_BUDGET`);
        ``trace_pages``, the trace's pages resident while runs read them (a
        quarter). A render comes before the runs, and the runs use the
        last two together.

    Raises
    ------
    InputError
        If less than :data:`MIN_TRACE_BYTES` would be left, naming the
        budget that would do.
    """
    from coherence.pixel_lines import SHARED_LINES_BUDGET

    budget = require_int("memory_budget", memory_budget, 0)
    least = least_memory_budget(n_pixels, n_jobs)
    if budget < least:
        raise InputError(
            f"memory_budget (--memory-budget) of {budget / 2**20:.0f} MB is too small: the process takes about "
            f"{PROCESS_BYTES >> 20} MB and {n_jobs} run{'s' if n_jobs != 1 else ''} at once over {n_pixels:,} "
            f"pixels about {n_jobs * n_pixels * RUN_BYTES_PER_PIXEL / 2**20:.0f} MB, and the trace needs at least "
            f"{MIN_TRACE_BYTES >> 20} MB; give at least {-(-least >> 20)} MB")
    available = budget - least + MIN_TRACE_BYTES
    return {"render_records": available // 2, "shared_lines": min(SHARED_LINES_BUDGET, available - available // 4),
            "trace_pages": available // 4}


def least_memory_budget(n_pixels: int, n_jobs: int = 1) -> int:
    """The smallest budget, in bytes, that :func:`memory_shares` accepts for ``n_jobs`` runs at once over
    ``n_pixels`` pixels: :data:`PROCESS_BYTES`, the runs' :data:`RUN_BYTES_PER_PIXEL` and
    :data:`MIN_TRACE_BYTES`."""
    n_pixels = require_int("n_pixels", n_pixels, 0)
    n_jobs = require_int("n_jobs", n_jobs, 1)
    return PROCESS_BYTES + n_jobs * n_pixels * RUN_BYTES_PER_PIXEL + MIN_TRACE_BYTES


def runs_at_once(memory_budget: int, n_pixels: int, n_cpus: int) -> int:
    """How many runs a process of ``memory_budget`` bytes simulates at once: one per CPU (``n_cpus``), fewer if
    their :data:`RUN_BYTES_PER_PIXEL` would leave the trace less than :data:`MIN_TRACE_BYTES`; at least one
    (:func:`memory_shares` then says whether even one fits)."""
    n_pixels = require_int("n_pixels", n_pixels, 0)
    n_cpus = require_int("n_cpus", n_cpus, 1)
    spare = require_int("memory_budget", memory_budget, 0) - PROCESS_BYTES - MIN_TRACE_BYTES
    fit = spare // (n_pixels * RUN_BYTES_PER_PIXEL) if n_pixels else n_cpus
    return int(max(1, min(n_cpus, fit)))


def trace_pages_limited(trace, shares: dict) -> ResidentLimit:
    """A context that keeps ``trace``'s resident pages (records and counters) under ``shares["trace_pages"]``
    bytes, on top of what the process's other files (its libraries) hold when it is made."""
    return ResidentLimit([trace.records, trace.counters], (resident_file_bytes() or 0) + shares["trace_pages"])
