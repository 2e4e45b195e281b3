"""Text address files: the chunked parser against a slow line-by-line reference, and its memory."""
import re
import tracemalloc

import numpy as np
import pytest

import cachesim.io
from cachesim import read_addresses

_DECIMAL = re.compile(r"[0-9]+")
_HEX = re.compile(r"0[xX][0-9a-fA-F]+")


def reference_read(path):
    """Whole file as text, ``str.splitlines``, ``#`` comments, ``int``: the obvious reading."""
    data = path.read_bytes()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    values = []
    for number, raw in enumerate(data.decode("ascii").splitlines(), start=1):
        token = raw.split("#", 1)[0].strip()
        if not token:
            continue
        if not (_DECIMAL.fullmatch(token) or _HEX.fullmatch(token)):
            raise ValueError(f"{path}:{number}: expected one decimal or 0x-hex address, got {token!r}")
        value = int(token, 16) if _HEX.fullmatch(token) else int(token)
        if value >= 2**64:
            raise ValueError(f"{path}:{number}: address {token} does not fit in 64 bits")
        values.append(value)
    return np.array(values, dtype=np.uint64)


def random_text(rng, n_lines):
    """Seeded lines of every accepted form, with mixed line ends (bytes)."""
    lines = []
    for _ in range(n_lines):
        value = int(rng.integers(0, 2**63)) * 2 + int(rng.integers(0, 2)) if rng.random() < 0.3 else int(
            rng.integers(0, 1 << 20))
        form = rng.integers(0, 7)
        if form == 0:
            text = str(value)
        elif form == 1:
            text = f"0{'xX'[int(rng.integers(0, 2))]}{'0' * int(rng.integers(0, 3))}{value:x}"
        elif form == 2:
            text = f"0x{value:X}"
        elif form == 3:
            text = ""
        elif form == 4:
            text = "# a comment 12"
        elif form == 5:
            text = f" \t{value}\t # comment"
        else:
            text = f"{'0' * int(rng.integers(0, 4))}{value}  "
        lines.append(text + ["\n", "\r\n", "\r"][int(rng.choice(3, p=[0.8, 0.15, 0.05]))])
    if rng.random() < 0.5:
        lines[-1] = lines[-1].rstrip("\r\n")  # no break after the last line
    return "".join(lines).encode("ascii")


@pytest.mark.parametrize("block", [7, 64, 1 << 20])
@pytest.mark.parametrize("seed", range(4))
def test_text_files_read_as_the_reference_reads_them(tmp_path, monkeypatch, seed, block):
    """Fails if ``_blocks`` in cachesim/io.py cuts a block anywhere but after a ``\\n``
    (``cut = len(data)``): blocks of 7 bytes then split lines in two."""
    monkeypatch.setattr(cachesim.io, "BLOCK_BYTES", block)
    rng = np.random.default_rng(seed)
    path = tmp_path / "a.txt"
    path.write_bytes((b"\xef\xbb\xbf" if seed == 1 else b"") + random_text(rng, 300))
    assert np.array_equal(read_addresses(path), reference_read(path))


@pytest.mark.parametrize("bad", ["12 3", "0x", "-5", "1.5", "18446744073709551616", "0x10000000000000000",
                                 "0x1g", "99999999999999999999x", "0x00000000000000000001z"])
@pytest.mark.parametrize("seed", range(3))
def test_bad_lines_are_named_as_the_reference_names_them(tmp_path, monkeypatch, seed, bad):
    """Fails if ``_parse_lines`` counts a ``\\r\\n`` as two line breaks (``end += 1`` always): the
    line numbers after the first CRLF would be too high."""
    monkeypatch.setattr(cachesim.io, "BLOCK_BYTES", 50)
    rng = np.random.default_rng(seed)
    lines = random_text(rng, 40).splitlines(keepends=True)
    at = int(rng.integers(0, len(lines)))
    lines.insert(at, f"  {bad} # here\r\n".encode())
    path = tmp_path / "bad.txt"
    path.write_bytes(b"".join(lines))
    with pytest.raises(ValueError) as expected:
        reference_read(path)
    with pytest.raises(ValueError) as got:
        read_addresses(path)
    assert str(got.value) == str(expected.value)


def test_a_utf8_byte_order_mark_is_skipped_and_utf16_is_named(tmp_path):
    """Fails if ``_blocks`` in cachesim/io.py keeps the UTF-8 mark: its bytes are not ASCII."""
    path = tmp_path / "bom.txt"
    path.write_bytes(b"\xef\xbb\xbf4096\n0x10\n")
    assert read_addresses(path).tolist() == [4096, 16]
    path.write_bytes("4096\n".encode("utf-16"))
    with pytest.raises(ValueError, match=r"bom.txt:1: not a text file of addresses \(byte 0 is not ASCII\) "
                                         r"\(a UTF-16 byte-order mark"):
        read_addresses(path)
    path.write_bytes(b"1\n2 # caf\xc3\xa9\n")
    with pytest.raises(ValueError, match=r"bom.txt:2: not a text file of addresses \(byte 9 is not ASCII\)"):
        read_addresses(path)


def _peak_bytes(path):
    tracemalloc.start()
    try:
        read_addresses(path)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.jit_only
def test_reading_a_text_file_takes_at_most_twice_its_npy_size(tmp_path):
    """Fails if ``_read_text`` in cachesim/io.py reads the whole text at once (``path.read_text()``
    and a list of its lines take about 160 bytes per address). A million lines here; the
    20-million-line figure is printed by benchmarks/bench_address_file.py."""
    n = 1_000_000
    addresses = np.random.default_rng(5).integers(0, 2**40, n)
    big = tmp_path / "big.txt"
    big.write_text("\n".join(map(str, addresses.tolist())) + "\n")
    one = tmp_path / "one.txt"
    one.write_text("4096\n")
    _peak_bytes(one)  # compile (or load) the kernels outside the measurement
    npy_bytes = 8 * n + 128
    extra = _peak_bytes(big) - _peak_bytes(one)
    assert extra <= 2 * npy_bytes, f"{extra / 2**20:.1f} MiB more than a 1-line file"
