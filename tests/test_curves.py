"""Space-filling-curve pixel orders against slow, obvious references."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coherence.curves import (
    CURVES,
    curve_order,
    hilbert_order,
    morton_keys,
    morton_order,
    scan_order,
    serpentine_order,
)

sizes = st.integers(min_value=1, max_value=70)


def _non_adjacent_steps(order: np.ndarray, width: int) -> int:
    y, x = np.divmod(order, width)
    return int(np.count_nonzero(np.abs(np.diff(x)) + np.abs(np.diff(y)) != 1))


# ---------------------------------------------------------------- references


def _d2xy(n: int, d: int) -> tuple[int, int]:
    """Classic Hilbert index -> (x, y) on an n x n grid, n a power of two."""
    x = y = 0
    s = 1
    t = d
    while s < n:
        rx = 1 & (t // 2)
        ry = 1 & (t ^ rx)
        if ry == 0:
            if rx == 1:
                x, y = s - 1 - x, s - 1 - y
            x, y = y, x
        x += s * rx
        y += s * ry
        t //= 4
        s *= 2
    return x, y


def _gilbert_reference(width: int, height: int, major_x: bool) -> list[int]:
    """Plain recursive generalised Hilbert, as in the published description."""
    out = []

    def sign(v):
        return (v > 0) - (v < 0)

    def walk(x, y, ax, ay, bx, by):
        w, h = abs(ax + ay), abs(bx + by)
        dax, day, dbx, dby = sign(ax), sign(ay), sign(bx), sign(by)
        if h == 1 or w == 1:
            dx, dy, m = (dax, day, w) if h == 1 else (dbx, dby, h)
            for _ in range(m):
                out.append(y * width + x)
                x, y = x + dx, y + dy
            return
        ax2, ay2, bx2, by2 = ax // 2, ay // 2, bx // 2, by // 2
        if 2 * w > 3 * h:
            if abs(ax2 + ay2) % 2 and w > 2:
                ax2, ay2 = ax2 + dax, ay2 + day
            walk(x, y, ax2, ay2, bx, by)
            walk(x + ax2, y + ay2, ax - ax2, ay - ay2, bx, by)
        else:
            if abs(bx2 + by2) % 2 and h > 2:
                bx2, by2 = bx2 + dbx, by2 + dby
            walk(x, y, bx2, by2, ax2, ay2)
            walk(x + bx2, y + by2, ax, ay, bx - bx2, by - by2)
            walk(x + (ax - dax) + (bx2 - dbx), y + (ay - day) + (by2 - dby),
                 -bx2, -by2, -(ax - ax2), -(ay - ay2))

    if major_x:
        walk(0, 0, width, 0, 0, height)
    else:
        walk(0, 0, 0, height, width, 0)
    return out


def _interleave(x: int, y: int) -> int:
    key = 0
    for bit in range(32):
        key |= ((x >> bit) & 1) << (2 * bit)
        key |= ((y >> bit) & 1) << (2 * bit + 1)
    return key


# ---------------------------------------------------------------- all curves


@settings(max_examples=60, deadline=None)
@given(width=sizes, height=sizes)
def test_every_curve_is_a_permutation(width, height):
    for name in CURVES:
        order = curve_order(name, width, height)
        assert order.dtype == np.int64
        assert order.shape == (width * height,)
        np.testing.assert_array_equal(np.sort(order), np.arange(width * height))


def test_unknown_curve_and_bad_sizes():
    with pytest.raises(ValueError, match="unknown curve 'peano'"):
        curve_order("peano", 4, 4)
    for fn in (hilbert_order, morton_order, serpentine_order, scan_order):
        with pytest.raises(ValueError, match="width must be >= 1"):
            fn(0, 4)
        with pytest.raises(ValueError, match="height must be an integer"):
            fn(4, 2.0)
        with pytest.raises(ValueError, match="width must be an integer"):
            fn(True, 4)


# ---------------------------------------------------------------- Hilbert


@pytest.mark.parametrize("k", range(7))
def test_hilbert_on_power_of_two_squares_is_the_classic_curve(k):
    n = 1 << k
    reference = [y * n + x for x, y in (_d2xy(n, d) for d in range(n * n))]
    np.testing.assert_array_equal(hilbert_order(n, n), reference)


def test_hilbert_matches_plain_recursive_reference():
    from coherence.curves import _hilbert_major_x

    for width in range(1, 23):
        for height in range(1, 23):
            expected = _gilbert_reference(width, height, _hilbert_major_x(width, height))
            np.testing.assert_array_equal(hilbert_order(width, height), expected, err_msg=f"{width}x{height}")


def test_hilbert_steps_are_four_neighbours_for_all_small_sizes():
    # 0 for every size, odd ones included: the orientation rule avoids the
    # one case (odd major axis, even minor) where parity forces a diagonal.
    bad = {
        (w, h): _non_adjacent_steps(hilbert_order(w, h), w)
        for w in range(1, 49)
        for h in range(1, 49)
    }
    assert {k: v for k, v in bad.items() if v} == {}


@pytest.mark.jit_only  # the small sizes above cover the same code
@pytest.mark.parametrize("width,height", [(512, 512), (511, 512), (512, 511), (513, 257), (1000, 3), (3, 1000), (640, 480), (97, 89)])
def test_hilbert_steps_are_four_neighbours_for_large_sizes(width, height):
    order = hilbert_order(width, height)
    assert order[0] == 0
    assert _non_adjacent_steps(order, width) == 0


def test_hilbert_parity_rule_matters():
    # Forcing the long odd side as the major axis of 5x4 makes a diagonal
    # step; the chosen orientation does not.
    forced = np.array(_gilbert_reference(5, 4, major_x=True))
    assert _non_adjacent_steps(forced, 5) >= 1
    assert _non_adjacent_steps(hilbert_order(5, 4), 5) == 0


def test_hilbert_is_local():
    # contiguous quarters of the curve on 64x64 are the four 32x32 quadrants
    order = hilbert_order(64, 64)
    y, x = np.divmod(order, 64)
    for q in range(4):
        part = slice(q * 1024, (q + 1) * 1024)
        assert np.ptp(x[part]) == 31 and np.ptp(y[part]) == 31


# ---------------------------------------------------------------- Morton


@settings(max_examples=40, deadline=None)
@given(width=st.integers(1, 40), height=st.integers(1, 40))
def test_morton_equals_bit_interleaving_reference(width, height):
    pixels = [(x, y) for y in range(height) for x in range(width)]
    expected = [y * width + x for x, y in sorted(pixels, key=lambda p: _interleave(*p))]
    np.testing.assert_array_equal(morton_order(width, height), expected)


def test_morton_keys_hand_checked():
    np.testing.assert_array_equal(morton_keys([0, 1, 0, 1, 2, 3], [0, 0, 1, 1, 0, 3]), [0, 1, 2, 3, 4, 15])
    assert morton_keys(2**31 - 1, 2**31 - 1) == 2**62 - 1
    np.testing.assert_array_equal(morton_order(4, 2), [0, 1, 4, 5, 2, 3, 6, 7])


# ---------------------------------------------------------------- serpentine, scan


def test_serpentine_hand_checked():
    np.testing.assert_array_equal(serpentine_order(3, 2), [0, 1, 2, 5, 4, 3])
    np.testing.assert_array_equal(serpentine_order(2, 3), [0, 1, 3, 2, 4, 5])
    np.testing.assert_array_equal(serpentine_order(1, 3), [0, 1, 2])
    order = serpentine_order(37, 23)
    assert _non_adjacent_steps(order, 37) == 0


def test_scan_order():
    np.testing.assert_array_equal(scan_order(3, 2), np.arange(6))
