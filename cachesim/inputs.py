"""Validation of simulator inputs: byte addresses, per-access write flags and PC-like ids."""
from __future__ import annotations

import numpy as np
from numba import njit

from rtcommon.validate import InputError


def as_addresses(addresses, name: str = "addresses") -> np.ndarray:
    """Validate and convert to a contiguous uint64 array of byte addresses.

    Accepts any integer array or sequence of non-negative integers below 2**64.
    Floats, booleans, negative values and non-numeric input raise ValueError.
    """
    if isinstance(addresses, np.ndarray):
        array = addresses
    else:
        try:
            array = np.asarray(addresses)
        except (OverflowError, ValueError, TypeError) as error:
            raise InputError(f"{name} must be non-negative integers below 2**64: {error}") from None
        if array.dtype == object:
            try:
                array = np.array([int(value) for value in array.ravel()], dtype=np.uint64)
            except (OverflowError, ValueError, TypeError) as error:
                raise InputError(f"{name} must be non-negative integers below 2**64: {error}") from None
    if array.ndim != 1:
        if array.size == 0:
            array = array.reshape(0)
        else:
            raise InputError(f"{name} must be one-dimensional, got shape {array.shape}")
    if array.size == 0:
        return np.zeros(0, dtype=np.uint64)
    if array.dtype.kind == "u":
        return np.ascontiguousarray(array, dtype=np.uint64)
    if array.dtype.kind == "i":
        lowest = array.min()
        if lowest < 0:
            raise InputError(f"{name} must be non-negative; found {lowest} at index {int(np.argmin(array))}")
        return np.ascontiguousarray(array, dtype=np.uint64)
    raise InputError(f"{name} must be integers (got dtype {array.dtype}); byte addresses are whole numbers")


def as_writes(writes, n_accesses: int, name: str = "writes") -> np.ndarray:
    """Validate per-access write flags: a bool array of shape (N,), or None (all reads).

    Returns a contiguous bool array; (0,) when there is no write at all, so
    that read-only streams take the read-only paths.
    """
    if writes is None:
        return np.zeros(0, dtype=np.bool_)
    array = np.asarray(writes)
    if array.dtype != np.bool_:
        if array.dtype.kind in "iu" and array.size and not np.isin(array, (0, 1)).all():
            raise InputError(f"{name} must be booleans (or 0/1), one per address; found other values")
        if array.dtype.kind not in "iub" and array.size:
            raise InputError(f"{name} must be booleans, one per address; got dtype {array.dtype}")
        array = array.astype(np.bool_)
    if array.ndim != 1 or array.size != n_accesses:
        raise InputError(f"{name} must have shape ({n_accesses},), one flag per address; got {array.shape}")
    if not array.any():
        return np.zeros(0, dtype=np.bool_)
    return np.ascontiguousarray(array)


def as_pcs(pcs, n_accesses: int, name: str = "pcs") -> np.ndarray:
    """Validate per-access PC-like ids: non-negative integers of shape (N,), or None (id 0 for all).

    Returns a contiguous int64 array; (0,) for None.
    """
    if pcs is None:
        return np.zeros(0, dtype=np.int64)
    array = np.asarray(pcs)
    if array.size and array.dtype.kind not in "iu":
        raise InputError(f"{name} must be integers, one per address; got dtype {array.dtype}")
    if array.ndim != 1 or array.size != n_accesses:
        raise InputError(f"{name} must have shape ({n_accesses},), one id per address; got {array.shape}")
    if array.size and (array.min() < 0 or (array.dtype.kind == "u" and array.max() >= 2**63)):
        raise InputError(f"{name} must be non-negative integers below 2**63")
    return np.ascontiguousarray(array, dtype=np.int64)


def small_integers(values, n: int, name: str, limit: int, what: str, lowest: int = 0,
                   dtype=np.int64) -> np.ndarray:
    """``values`` as ``dtype`` (N,), each in [lowest, limit), or a one-line error naming the first bad one.

    ``dtype`` must hold [lowest, limit). The range is checked on the values as given (one
    compiled pass for their least and greatest), so a stream already of ``dtype`` is not copied.
    """
    array = np.asarray(values)
    if array.ndim != 1 or array.size != n:
        raise InputError(f"{name} must have shape ({n},), one per address; got {array.shape}")
    if not n:
        return np.zeros(0, dtype=dtype)
    if array.dtype.kind not in "iu":
        raise InputError(f"{name} must be integers, got dtype {array.dtype}")
    array = np.ascontiguousarray(array)
    least, greatest = _bounds(array)
    if int(least) < lowest or int(greatest) >= limit:
        bad = int(np.flatnonzero((array < lowest) | (array >= limit))[0])
        raise InputError(f"{name}[{bad}] is {int(array[bad])}; expected an integer in "
                         f"[{lowest}, {limit}) ({what})")
    return array.astype(dtype, copy=False)


@njit(cache=True)
def _bounds(array):
    """The least and the greatest of a non-empty integer array, in one pass (indexed, which the compiler
    vectorises; a loop over the array's values it did not, for 8-byte integers)."""
    least = array[0]
    greatest = array[0]
    for i in range(array.shape[0]):
        least = min(least, array[i])
        greatest = max(greatest, array[i])
    return least, greatest
