"""JSON: a numpy-aware fallback for ``json.dumps`` and plain, rounded values."""
from __future__ import annotations

import numpy as np


def json_default(value):
    """``json.dumps`` fallback for numpy scalars and arrays."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
