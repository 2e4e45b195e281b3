"""JSON: a numpy-aware fallback for ``json.dumps`` and plain, rounded values."""
from __future__ import annotations

import math

import numpy as np


def json_default(value):
    """``json.dumps`` fallback for numpy scalars and arrays."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def round_number(value, significant: int, *, integral_as_int: bool = False):
    """A number as a plain Python value: ints (and bools) as ints, floats to ``significant`` digits.

    Not-finite floats become None; with ``integral_as_int`` a float with no
    fractional part (below 2**53) becomes an int.
    """
    if isinstance(value, (bool, np.bool_, int, np.integer)):
        return int(value)
    value = float(value)
    if not math.isfinite(value):
        return None
    if integral_as_int and value == int(value) and abs(value) < 2**53:
        return int(value)
    return float(f"{value:.{significant}g}")


def plain(value, significant: int, *, integral_as_int: bool = False):
    """``value`` as plain JSON types, recursively: dict keys as strings, lists for tuples and for
    DataFrames (one dict per row), bools as bools, numbers by :func:`round_number`, anything else
    as its string."""
    import pandas as pd

    again = lambda item: plain(item, significant, integral_as_int=integral_as_int)  # noqa: E731
    if isinstance(value, dict):
        return {str(k): again(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [again(v) for v in value]
    if isinstance(value, pd.DataFrame):
        return [again(row) for row in value.to_dict(orient="records")]
    if isinstance(value, (str, type(None))):
        return value
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, float, np.number)):
        return round_number(value, significant, integral_as_int=integral_as_int)
    return str(value)
