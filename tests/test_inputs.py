"""cachesim.inputs.small_integers: range checks in the values' own dtype, against an obvious reference."""
import numpy as np
import pytest

from cachesim.inputs import small_integers


def first_out_of_range(values, lowest, limit):
    """The index of the first value outside [lowest, limit), by Python integers, or None."""
    for index, value in enumerate(values.tolist()):
        if not lowest <= int(value) < limit:
            return index
    return None


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.int64, np.uint64])
def test_small_integers_accepts_and_refuses_like_the_reference(dtype):
    """Seeded arrays of several dtypes, some with one value pushed out of range.
    Mutation: ``greatest = array[0]`` kept (drop the max update) in _bounds: an array whose
    first value is in range and a later one too large is accepted."""
    rng = np.random.default_rng(11)
    info = np.iinfo(dtype)
    for trial in range(40):
        n = int(rng.integers(1, 50))
        lowest, limit = int(rng.integers(0, 3)), int(rng.integers(5, 100))
        values = rng.integers(lowest, limit, n).astype(dtype)
        if trial % 2:
            values[rng.integers(0, n)] = dtype(info.max if trial % 4 == 1 else max(info.min, lowest - 1))
        bad = first_out_of_range(values, lowest, limit)
        if bad is None:
            converted = small_integers(values, n, "values", limit, "test", lowest=lowest)
            assert converted.dtype == np.int64 and converted.tolist() == values.tolist()
        else:
            with pytest.raises(ValueError, match=rf"values\[{bad}\] is {int(values[bad])}; expected"):
                small_integers(values, n, "values", limit, "test", lowest=lowest)


def test_small_integers_keeps_a_requested_dtype_without_copying():
    """Mutation: ``return np.ascontiguousarray(array, dtype=np.int64)`` at the end."""
    kinds = np.array([0, 3, 15], dtype=np.uint8)
    assert small_integers(kinds, 3, "kinds", 16, "kinds", dtype=np.uint8) is kinds
    assert small_integers(np.zeros(0, np.int32), 0, "kinds", 16, "kinds", dtype=np.uint8).dtype == np.uint8
    huge = np.array([1, 2**64 - 1], dtype=np.uint64)
    with pytest.raises(ValueError, match=r"sizes\[1\] is 18446744073709551615"):
        small_integers(huge, 2, "sizes", 1 << 20, "bytes", lowest=1)
