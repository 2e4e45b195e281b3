"""Reading address streams from files.

Two formats:

- ``.npy``: a one-dimensional array of non-negative integers (any integer
  dtype; uint64 is kept as is).
- text (any other suffix): one address per line, decimal (``4096``) or
  hexadecimal with a ``0x`` prefix (``0x1000``). Blank lines and lines
  starting with ``#`` are skipped; a ``#`` after an address starts a comment.
  ASCII (a UTF-8 byte-order mark at the start is skipped); lines end in
  ``\\n``, ``\\r\\n`` or ``\\r``.

Errors name the file and, for text, the line and what was expected.

A text file is read in blocks of whole lines, twice: a first pass checks
every line and counts the addresses, a second fills an array of exactly that
length. Beyond the result (8 bytes per address) a read holds one block, so a
20-million-line file needs about 160 MB, not the gigabytes that a list of
its lines would.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numba import njit

from cachesim.simulate import as_addresses
from rtcommon.validate import InputError

#: Bytes of text parsed per call of the kernel (whole lines: a block ends after its last ``\n``).
BLOCK_BYTES = 1 << 20
_BOM = b"\xef\xbb\xbf"
# Outcomes of _parse_lines.
_PARSED, _BAD_TOKEN, _TOO_BIG, _NOT_ASCII, _FULL = 0, 1, 2, 3, 4


def read_addresses(path: str | os.PathLike) -> np.ndarray:
    """Read byte addresses from a ``.npy`` or text file.

    Parameters
    ----------
    path : str or path-like
        The file (see the module docstring for the formats).

    Returns
    -------
    ndarray of uint64, shape (N,)

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the content is not a stream of addresses; the message names the
        file (and line, for text) and what was expected.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such address file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; expected a .npy or text file of addresses")
    if path.suffix.lower() == ".npy":
        return _read_npy(path)
    return _read_text(path)


def _read_npy(path: Path) -> np.ndarray:
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise InputError(f"{path}: not a readable .npy array ({error})") from None
    if not isinstance(array, np.ndarray):
        raise InputError(f"{path}: holds several arrays; expected one array of addresses")
    try:
        return as_addresses(array, name=str(path))
    except ValueError as error:
        raise InputError(str(error)) from None


def _blocks(stream):
    """Yield (offset in the file, uint8 array) of whole lines, about :data:`BLOCK_BYTES` each;
    the last block may end without a line break. A leading UTF-8 byte-order mark is skipped."""
    offset = 0
    carry = b""
    while True:
        data = stream.read(BLOCK_BYTES)
        if offset == 0 and not carry and data.startswith(_BOM):
            data = data[len(_BOM):]
            offset = len(_BOM)
        if not data:
            if carry:
                yield offset, np.frombuffer(carry, dtype=np.uint8)
            return
        data = carry + data
        cut = data.rfind(b"\n") + 1
        if cut == 0:
            carry = data  # a line longer than a block: read on
            continue
        yield offset, np.frombuffer(data, dtype=np.uint8, count=cut)
        offset += cut
        carry = data[cut:]


def _read_text(path: Path) -> np.ndarray:
    out = np.zeros(0, dtype=np.uint64)
    for store in (False, True):  # count and check, then fill
        n_out = 0
        line = 1
        with open(path, "rb") as stream:
            for offset, block in _blocks(stream):
                n_out, lines, outcome, start, stop = _parse_lines(block, out, n_out, store)
                if outcome != _PARSED:
                    _raise_parse_error(path, block, offset, line + lines, outcome, start, stop)
                line += lines
        if not store:
            out = np.empty(n_out, dtype=np.uint64)
    if n_out != out.shape[0]:
        raise InputError(f"{path}: changed while being read ({out.shape[0]} addresses, then {n_out})")
    return out


def _raise_parse_error(path, block, offset, line, outcome, start, stop):
    token = bytes(block[start:stop]).decode("ascii", errors="replace")
    if outcome == _BAD_TOKEN:
        raise InputError(f"{path}:{line}: expected one decimal or 0x-hex address, got {token!r}")
    if outcome == _TOO_BIG:
        raise InputError(f"{path}:{line}: address {token} does not fit in 64 bits")
    if outcome == _NOT_ASCII:
        position = offset + start
        utf16 = " (a UTF-16 byte-order mark: save the file as ASCII or UTF-8)" if (
            position == 0 and bytes(block[:2]) in (b"\xff\xfe", b"\xfe\xff")) else ""
        raise InputError(f"{path}:{line}: not a text file of addresses (byte {position} is not ASCII){utf16}")
    raise InputError(f"{path}: changed while being read (more addresses than at first)")


@njit(cache=True)
def _is_line_break(byte):
    # The ASCII line breaks of Python's str.splitlines.
    return byte == 10 or byte == 13 or byte == 11 or byte == 12 or (28 <= byte <= 30)


@njit(cache=True)
def _is_blank(byte):
    # What str.strip removes within a line.
    return byte == 32 or byte == 9 or byte == 31


@njit(cache=True)
def _parse_token(text, start, stop):
    """The address in ``text[start:stop]`` (stripped, non-empty): (value, outcome)."""
    value = np.uint64(0)
    too_big = False  # kept going: a later bad character makes it a bad token instead
    if stop - start > 2 and text[start] == 48 and (text[start + 1] == 120 or text[start + 1] == 88):
        for k in range(start + 2, stop):
            byte = text[k]
            if 48 <= byte <= 57:
                digit = byte - 48
            elif 97 <= byte <= 102:
                digit = byte - 87
            elif 65 <= byte <= 70:
                digit = byte - 55
            else:
                return value, _BAD_TOKEN
            too_big |= (value >> np.uint64(60)) != np.uint64(0)
            value = (value << np.uint64(4)) | np.uint64(digit)
        return value, (_TOO_BIG if too_big else _PARSED)
    for k in range(start, stop):
        byte = text[k]
        if not 48 <= byte <= 57:
            return value, _BAD_TOKEN
        digit = np.uint64(byte - 48)
        # 2**64 - 1 = 18446744073709551615
        if value > np.uint64(1844674407370955161) or (value == np.uint64(1844674407370955161)
                                                       and digit > np.uint64(5)):
            too_big = True
        value = value * np.uint64(10) + digit
    return value, (_TOO_BIG if too_big else _PARSED)


@njit(cache=True)
def _parse_lines(text, out, n_out, store):
    """Parse the addresses of ``text`` (uint8, (B,)), one per line, after ``n_out`` of them.

    Stores them in ``out[n_out:]`` when ``store`` (else only counts them).
    Returns (addresses so far, line breaks passed, outcome, start, stop):
    on a bad line the outcome says why, the line breaks passed number the
    line, and ``text[start:stop]`` is the token (or the non-ASCII byte).
    """
    n = text.shape[0]
    lines = 0
    i = 0
    while i < n:
        end = i
        comment = -1
        while end < n and not _is_line_break(text[end]):
            byte = text[end]
            if byte >= 128:
                return n_out, lines, _NOT_ASCII, end, end + 1
            if byte == 35 and comment < 0:
                comment = end
            end += 1
        start = i
        stop = end if comment < 0 else comment
        while start < stop and _is_blank(text[start]):
            start += 1
        while stop > start and _is_blank(text[stop - 1]):
            stop -= 1
        if stop > start:
            value, outcome = _parse_token(text, start, stop)
            if outcome != _PARSED:
                return n_out, lines, outcome, start, stop
            if store:
                if n_out >= out.shape[0]:
                    return n_out, lines, _FULL, start, stop
                out[n_out] = value
            n_out += 1
        if end < n:
            lines += 1
            end += 2 if (text[end] == 13 and end + 1 < n and text[end + 1] == 10) else 1
        i = end
    return n_out, lines, _PARSED, 0, 0
