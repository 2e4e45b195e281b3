"""The shared helpers: checks, atomic files, JSON fallback."""
import json
import os
import stat

import numpy as np
import pytest

from rtcommon.files import write_bytes_atomic, write_text_atomic
from rtcommon.jsonio import json_default
from rtcommon.validate import require_bool, require_int, require_number, require_power_of_two


def test_require_int_accepts_python_and_numpy_integers():
    assert require_int("n", 3, 1) == 3
    value = require_int("n", np.int32(5), 0, 5)
    assert value == 5 and type(value) is int


@pytest.mark.parametrize("value, message", [
    (True, "n must be an integer >= 1, got True"),
    (1.0, "n must be an integer >= 1, got 1.0"),
    ("2", "n must be an integer >= 1, got '2'"),
    (0, "n must be >= 1, got 0"),
])
def test_require_int_messages(value, message):
    with pytest.raises(ValueError) as error:
        require_int("n", value, 1)
    assert str(error.value) == message


def test_require_int_range():
    with pytest.raises(ValueError, match=r"^size must be in \[0, 6\], got 7$"):
        require_int("size", 7, 0, 6)
    with pytest.raises(ValueError, match=r"^size must be an integer in \[0, 6\], got None$"):
        require_int("size", None, 0, 6)


def test_require_number():
    assert require_number("latency", np.float32(2.5), 0, "cycles") == 2.5
    for bad in (-1, float("nan"), float("inf"), True, "3"):
        with pytest.raises(ValueError, match=r"^latency must be a finite number >= 0 \(cycles\), got"):
            require_number("latency", bad, 0, "cycles")


def test_require_bool():
    """True, False and numpy booleans pass as Python bools; 1, 0, "yes" and
    None are refused. Fails if ``require_bool`` also accepts ``int``."""
    assert require_bool("flag", True) is True and require_bool("flag", np.bool_(False)) is False
    for bad in (1, 0, "yes", None):
        with pytest.raises(ValueError, match=rf"^flag must be True or False, got {bad!r}$"):
            require_bool("flag", bad)


def test_require_power_of_two():
    """Every power of two up to 2**40 passes (numpy ones too); a value with two
    bits set, 0, a negative, a bool and a float are refused. Fails if
    ``require_power_of_two`` drops its ``value & (value - 1)`` clause."""
    for bit in range(41):
        assert require_power_of_two("line_size", 1 << bit) == 1 << bit
    value = require_power_of_two("line_size", np.int64(64))
    assert value == 64 and type(value) is int
    for bad in (3, 12, 96, 0, -4, True, 4.0):
        with pytest.raises(ValueError, match=rf"^line_size must be a power of two >= 1, got {bad!r}$"):
            require_power_of_two("line_size", bad)


def test_atomic_write_replaces_whole_file_with_plain_permissions(tmp_path):
    target = tmp_path / "out.txt"
    write_text_atomic(target, "old\n")
    write_bytes_atomic(target, b"new\n")
    assert target.read_bytes() == b"new\n"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_write_leaves_nothing_when_it_fails(tmp_path):
    with pytest.raises(TypeError):
        write_bytes_atomic(tmp_path / "out.bin", "not bytes")
    assert list(tmp_path.iterdir()) == []


def test_json_default():
    text = json.dumps({"a": np.int64(3), "b": np.arange(2.0), "c": np.bool_(True)}, default=json_default)
    assert json.loads(text) == {"a": 3, "b": [0.0, 1.0], "c": True}
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        json.dumps(object(), default=json_default)


def test_round_number_and_plain_by_hand():
    import math

    import numpy as np
    import pandas as pd

    from rtcommon.jsonio import plain, round_number

    assert round_number(np.float64(1.23456789), 3) == 1.23
    assert round_number(2.0, 6) == 2.0 and isinstance(round_number(2.0, 6), float)
    assert round_number(2.0, 6, integral_as_int=True) == 2 and isinstance(round_number(2.0, 6, integral_as_int=True), int)
    assert round_number(2.0 ** 60, 6, integral_as_int=True) == float(f"{2.0 ** 60:.6g}")  # beyond 2**53 stays a float
    assert round_number(math.nan, 6) is None and round_number(-math.inf, 6) is None
    assert round_number(np.True_, 6) == 1 and round_number(np.int32(7), 2) == 7
    frame = pd.DataFrame({"a": [1, 2], "b": [0.123456, math.nan]})
    assert plain({1: (np.bool_(True), frame, None, "x", np.float32(0.5))}, 2) == \
        {"1": [True, [{"a": 1, "b": 0.12}, {"a": 2, "b": None}], None, "x", 0.5]}
    assert plain(object.__new__(type("Odd", (), {"__str__": lambda self: "odd"})), 3) == "odd"


def test_read_text_file_skips_a_bom_and_names_the_line_of_bad_bytes(tmp_path):
    """Fails when the byte-order mark is kept (decoding as plain ``utf-8``) or the line is counted
    from 0."""
    from rtcommon.files import read_text_file
    from rtcommon.validate import InputError

    (tmp_path / "a.toml").write_bytes(b"\xef\xbb\xbfx = 1\n")
    assert read_text_file(tmp_path / "a.toml", "a TOML file") == "x = 1\n"
    (tmp_path / "b.toml").write_bytes(b"x = 1\ny = \xff\n")
    with pytest.raises(InputError, match=r"b.toml:2: not a text file \(byte 10 is not UTF-8\); expected a TOML file"):
        read_text_file(tmp_path / "b.toml", "a TOML file")
