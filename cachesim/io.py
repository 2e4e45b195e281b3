"""Reading address streams from files.

Two formats:

- ``.npy``: a one-dimensional array of non-negative integers (any integer
  dtype; uint64 is kept as is).
- text (any other suffix): one address per line, decimal (``4096``) or
  hexadecimal with a ``0x`` prefix (``0x1000``). Blank lines and lines
  starting with ``#`` are skipped; a ``#`` after an address starts a comment.

Errors name the file and, for text, the line and what was expected.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from cachesim.simulate import as_addresses

_DECIMAL = re.compile(r"[0-9]+")
_HEX = re.compile(r"0[xX][0-9a-fA-F]+")
_LIMIT = 1 << 64


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
        raise ValueError(f"{path}: is a folder; expected a .npy or text file of addresses")
    if path.suffix.lower() == ".npy":
        return _read_npy(path)
    return _read_text(path)


def _read_npy(path: Path) -> np.ndarray:
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise ValueError(f"{path}: not a readable .npy array ({error})") from None
    if not isinstance(array, np.ndarray):
        raise ValueError(f"{path}: holds several arrays; expected one array of addresses")
    try:
        return as_addresses(array, name=str(path))
    except ValueError as error:
        raise ValueError(str(error)) from None


def _read_text(path: Path) -> np.ndarray:
    try:
        text = path.read_text(encoding="ascii")
    except UnicodeDecodeError as error:
        line = path.read_bytes()[: error.start].count(b"\n") + 1
        raise ValueError(f"{path}:{line}: not a text file of addresses (byte {error.start} is not ASCII)") from None
    tokens = []
    numbers = []
    for number, raw in enumerate(text.splitlines(), start=1):
        token = raw.split("#", 1)[0].strip()
        if token:
            tokens.append(token)
            numbers.append(number)
    if all(_DECIMAL.fullmatch(token) for token in tokens):
        # The common case: hand the whole column to numpy's parser.
        values = np.array(tokens, dtype=np.str_)
        try:
            return values.astype(np.uint64) if tokens else np.zeros(0, dtype=np.uint64)
        except OverflowError:
            pass  # find the line below
    addresses = np.empty(len(tokens), dtype=np.uint64)
    for index, (token, number) in enumerate(zip(tokens, numbers)):
        if _DECIMAL.fullmatch(token):
            value = int(token)
        elif _HEX.fullmatch(token):
            value = int(token, 16)
        else:
            raise ValueError(f"{path}:{number}: expected one decimal or 0x-hex address, got {token!r}")
        if value >= _LIMIT:
            raise ValueError(f"{path}:{number}: address {token} does not fit in 64 bits")
        addresses[index] = value
    return addresses
