"""``coherence cachesim`` and the address-file reader."""
import json

import numpy as np
import pandas as pd
import pytest

from cachesim import CacheLevel, Hierarchy, alpha21164, read_addresses, simulate
from analyses.cli import main


@pytest.fixture
def stream():
    rng = np.random.default_rng(7)
    return (np.cumsum(rng.integers(-64, 72, 5000)) + (1 << 36)).astype(np.uint64)


def test_table_shows_the_simulated_counts(tmp_path, stream, capsys):
    path = tmp_path / "stream.npy"
    np.save(path, stream)
    assert main(["cachesim", str(path)]) == 0
    out = capsys.readouterr().out
    expected = simulate(stream, alpha21164())
    assert f"{stream.size:,} addresses through alpha21164" in out
    for name, hits, misses in zip(("L1", "L2", "L3"), expected.hits, expected.misses):
        row = next(line.split() for line in out.splitlines() if line.split()[:1] == [name])
        assert int(row[5]) == hits and int(row[6]) == misses
    assert f"memory accesses: {expected.memory_accesses:,}" in out


def test_json_and_csv_carry_the_same_numbers(tmp_path, stream, capsys):
    path = tmp_path / "stream.npy"
    np.save(path, stream)
    csv = tmp_path / "levels.csv"
    assert main(["cachesim", str(path), "--json", "--csv", str(csv)]) == 0
    report = json.loads(capsys.readouterr().out)
    table = pd.read_csv(csv)
    meta = json.loads((tmp_path / "levels.csv.meta.json").read_text())
    expected = simulate(stream, alpha21164())
    assert [level["hits"] for level in report["levels"]] == expected.hits.tolist()
    assert table["misses"].tolist() == expected.misses.tolist()
    assert report["parameters"]["n_addresses"] == meta["parameters"]["n_addresses"] == stream.size
    assert "numba" in meta["versions"]
    assert not list(tmp_path.glob("*.tmp"))


def test_text_file_with_decimal_hex_and_comments(tmp_path, capsys):
    path = tmp_path / "a.txt"
    path.write_text("# a hand-made stream\n0x1000\n4096\n\n  0X2000  # far\n18446744073709551615\n")
    assert read_addresses(path).tolist() == [4096, 4096, 8192, 2**64 - 1]
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 1),))
    hierarchy_file = tmp_path / "tiny.toml"
    hierarchy.save(hierarchy_file)
    assert main(["cachesim", str(path), "--hierarchy", str(hierarchy_file), "--json"]) == 0
    levels = json.loads(capsys.readouterr().out)["levels"]
    assert [(level["hits"], level["misses"]) for level in levels] == [(1, 3)]


@pytest.mark.parametrize("content, message", [
    ("1\n2\nzz\n", ":3: expected one decimal or 0x-hex address, got 'zz'"),
    ("1\n-5\n", ":2: expected one decimal or 0x-hex address, got '-5'"),
    ("1.5\n", ":1: expected one decimal or 0x-hex address"),
    ("0x\n", ":1: expected one decimal or 0x-hex address"),
    ("7\n18446744073709551616\n", ":2: address 18446744073709551616 does not fit in 64 bits"),
    ("1 2\n", ":1: expected one decimal or 0x-hex address, got '1 2'"),
])
def test_bad_text_names_file_and_line(tmp_path, capsys, content, message):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    assert main(["cachesim", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}{message}" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("array, message", [
    (np.array([1.0, 2.0]), "must be integers"),
    (np.array([3, -1]), "must be non-negative"),
    (np.zeros((2, 2), dtype=np.int64), "one-dimensional"),
])
def test_bad_npy_is_rejected_with_the_file_name(tmp_path, capsys, array, message):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    assert main(["cachesim", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and message in err


def test_missing_corrupt_and_empty_files(tmp_path, capsys):
    assert main(["cachesim", str(tmp_path / "none.npy")]) == 2
    assert "no such file" in capsys.readouterr().err
    corrupt = tmp_path / "corrupt.npy"
    corrupt.write_bytes(b"not numpy")
    assert main(["cachesim", str(corrupt)]) == 2
    assert "not a readable .npy array" in capsys.readouterr().err
    empty = tmp_path / "empty.txt"
    empty.write_text("# nothing\n")
    assert main(["cachesim", str(empty), "--json"]) == 0
    assert all(level["accesses"] == 0 for level in json.loads(capsys.readouterr().out)["levels"])


def test_bad_hierarchy_and_output_folder_fail_before_reading(tmp_path, capsys):
    path = tmp_path / "a.txt"
    path.write_text("1\n")
    assert main(["cachesim", str(path), "--hierarchy", "nope"]) == 2
    assert "unknown hierarchy 'nope'" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('[[levels]]\nname = "L1"\nsize = 1000\nline_size = 32\nassoc = 1\n')
    assert main(["cachesim", str(path), "--hierarchy", str(bad)]) == 2
    assert str(bad) in capsys.readouterr().err
    assert main(["cachesim", str(path), "--csv", str(tmp_path / "no" / "x.csv")]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_hierarchy_file_with_a_byte_order_mark_loads(tmp_path, suffix):
    """Fails if Hierarchy.load decodes with "utf-8" instead of "utf-8-sig":
    the mark is then the first character of the TOML or JSON text, which both refuse."""
    path = alpha21164().save(tmp_path / f"h{suffix}")
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert Hierarchy.load(path) == alpha21164()


def test_help_teaches(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["cachesim", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "0x-hex" in out and "alpha21164" in out
