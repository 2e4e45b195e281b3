"""The size check of the robustness study: may a quantity be computed on a smaller image?

The 8-process losses and the verdict are computed at the study's size, at
least :data:`VERDICT_MIN_SIZE` pixels square. A smaller image may serve only
a quantity that it reproduces: one whose value at half the study's size is
within :data:`SIZE_CHECK_TOLERANCE` of its value at twice the study's size
(at the default 256 x 256, 128 x 128 against 512 x 512) on every one of
:data:`SIZE_CHECK_POINTS` sample points. The quantities checked are the
one-process ones (:data:`SIZE_CHECK_QUANTITIES`): only they could come from
a smaller image, as the losses need the one-process runs at the verdict's
size. Each point is a sample of the Morris design, spread evenly over it
(:func:`size_check_rows`), with its trajectory's seed, simulated at both
sizes on the tree of the study's base (one trace per size).

A quantity that passes could be taken at the smaller size; this study
takes every quantity at its own size all the same (``size_used``), because
its one-process runs at that size are simulated for the losses anyway. The
check tells the reader how far the one-process differences depend on the
image's resolution, and whether a study of them alone may run smaller.
"""
from __future__ import annotations

import numpy as np

__all__ = ["VERDICT_MIN_SIZE", "SIZE_CHECK_POINTS", "SIZE_CHECK_TOLERANCE", "SIZE_CHECK_QUANTITIES",
           "SIZE_CHECK_MAPPINGS", "check_sizes", "size_check_rows", "compare_sizes"]

#: Smallest image side the 8-process losses and the verdict are computed at
#: (the robustness study's default size; the faithfulness section calls a
#: smaller study a first look).
VERDICT_MIN_SIZE = 256

#: Sample points of the check.
SIZE_CHECK_POINTS = 5

#: Largest relative difference ``|small - reference| / |reference|`` a quantity may show at a point.
SIZE_CHECK_TOLERANCE = 0.10

#: The quantities checked: one-process user time of B and DB relative to S's.
SIZE_CHECK_QUANTITIES = ("b_minus_s", "db_minus_s")

#: The mappings whose one-process runs give those quantities.
SIZE_CHECK_MAPPINGS = ("S", "B", "DB")


def check_sizes(size: int) -> tuple[int, int]:
    """The smaller and the reference image side of the check for a study at ``size``: half and twice it."""
    return max(int(size) // 2, 1), 2 * int(size)


def size_check_rows(n_samples: int, points: int = SIZE_CHECK_POINTS) -> np.ndarray:
    """Indices of ``points`` samples spread evenly over a design of ``n_samples``, first and last included.

    Returns
    -------
    ndarray of int64, shape (min(points, n_samples),)
    """
    return np.unique(np.round(np.linspace(0, n_samples - 1, min(points, n_samples))).astype(np.int64))


def compare_sizes(small: dict, reference: dict, size_used: int, tolerance: float = SIZE_CHECK_TOLERANCE) -> dict:
    """Per quantity: its values at both sizes, their relative differences and whether it passes.

    Parameters
    ----------
    small, reference : dict of str to list of float
        Quantity -> its value at each point, at the smaller and the reference size.
    size_used : int
        The size the study takes the quantity at.
    tolerance : float

    Returns
    -------
    dict
        Quantity -> ``small``, ``reference``, ``relative_difference`` (lists
        per point; NaN where the reference value is 0 or a value is
        missing), ``passed`` (every point within ``tolerance``, at least
        :data:`SIZE_CHECK_POINTS` of them) and ``size_used``.
    """
    out = {}
    for name in reference:
        at_small = np.asarray(small[name], dtype=np.float64)
        at_reference = np.asarray(reference[name], dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            relative = np.abs(at_small - at_reference) / np.abs(at_reference)
        relative[~np.isfinite(relative)] = np.nan
        passed = bool(relative.size >= SIZE_CHECK_POINTS and np.all(relative <= tolerance))
        out[name] = {"small": at_small.tolist(), "reference": at_reference.tolist(),
                     "relative_difference": relative.tolist(), "passed": passed, "size_used": int(size_used)}
    return out
