"""Checks of user-given numbers that raise :class:`InputError` (a ``ValueError``) naming field and range.

One approach for the whole toolkit: frozen dataclasses call these in
``__post_init__`` and public functions call them before any work. A small
module rather than a validation library (pydantic, attrs validators): the
checks are few, numpy integers must pass as integers and ``bool`` must not,
and the messages stay the toolkit's own (``CacheLevel.size must be >= 1``).
Never ``assert``: ``python -O`` strips it. The checks import numpy
themselves: the command line imports :class:`InputError` as it starts, and
``coherence --help`` should not wait for numpy.
"""
from __future__ import annotations

import math
import numbers


class InputError(ValueError):
    """The caller's input is wrong: a value, an option, a file's contents. Said in one line that names it
    (field, option, file and line) and what was expected.

    The toolkit's own checks raise it, never a bare ``ValueError``, so that
    the command line can tell input it refuses from a bug: it prints an
    InputError as ``coherence CMD: error: ...`` and exits with 2, and any
    other exception as an internal error, with its traceback, exiting
    with 1. It is a ``ValueError``, so code that catches those still
    catches it.
    """


def _range_text(minimum, maximum) -> str:
    if minimum is not None and maximum is not None:
        return f" in [{minimum}, {maximum}]"
    if minimum is not None:
        return f" >= {minimum}"
    if maximum is not None:
        return f" <= {maximum}"
    return ""


def require_int(name: str, value, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as a Python int, checked against ``minimum <= value <= maximum``.

    Parameters
    ----------
    name : str
        What the message calls the value, e.g. ``"CacheLevel.size"``.
    value : int or numpy integer
        ``bool`` is refused although it is an ``int``.
    minimum, maximum : int, optional
        Inclusive bounds.

    Raises
    ------
    InputError
        ``"<name> must be an integer >= 1, got 'x'"`` for a non-integer,
        ``"<name> must be >= 1, got 0"`` (or ``in [lo, hi]``) out of range.
    """
    import numpy as np

    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name} must be an integer{_range_text(minimum, maximum)}, got {value!r}")
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        raise InputError(f"{name} must be{_range_text(minimum, maximum)}, got {value}")
    return int(value)


def require_number(name: str, value, minimum: float | None = None, unit: str = "") -> float:
    """``value`` as a finite float, checked against ``minimum``.

    Raises
    ------
    InputError
        ``"<name> must be a finite number >= 0 (cycles), got ..."`` for a
        non-number, NaN, an infinity or a value below ``minimum``.
    """
    import numpy as np

    ok = (not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real)
          and math.isfinite(value) and (minimum is None or value >= minimum))
    if not ok:
        suffix = f" ({unit})" if unit else ""
        raise InputError(f"{name} must be a finite number{_range_text(minimum, None)}{suffix}, got {value!r}")
    return float(value)


def require_bool(name: str, value) -> bool:
    """``value`` as a Python bool; ``True``, ``False`` and numpy booleans only.

    Raises
    ------
    InputError
        ``"<name> must be True or False, got 1"`` for anything else (an
        integer or a string is refused, not taken for its truth value).
    """
    import numpy as np

    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def require_power_of_two(name: str, value) -> int:
    """``value`` as a Python int that is a power of two (1, 2, 4, ...).

    Raises
    ------
    InputError
        ``"<name> must be a power of two >= 1, got 12"`` for a non-integer
        (``bool`` included), a value below 1 or one with more than one bit set.
    """
    import numpy as np

    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1 \
            or value & (value - 1):
        raise InputError(f"{name} must be a power of two >= 1, got {value!r}")
    return int(value)
