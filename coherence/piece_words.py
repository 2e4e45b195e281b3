"""Every pixel's accesses as the event loop on shared levels reads them: an address and one 16-bit word each.

A run on shared levels (:mod:`coherence.shared_schedule`) serves the
hardware threads in turns of about ``Q`` cycles, each turn a few dozen
accesses of one process's pixel. Kept as five arrays (address, bytes,
kind, write, private), every turn starts five separate streams of the
host's memory, one per array, for each of up to 64 processes at once;
an address and a word make it two streams and 10 bytes instead of 19.

A word holds, from the lowest bit:

- the bytes the access touches in its line less one, 10 bits
  (1 ... :data:`MAX_PIECE_BYTES`);
- its record kind, 4 bits from :data:`KIND_SHIFT`;
- :data:`WRITE_BIT`;
- :data:`PRIVATE_BIT`: an access to a process's own copy of per-ray data,
  moved by ``(p + 1) * private_span`` for process ``p``.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from rtcommon.validate import InputError

__all__ = ["KIND_MASK", "KIND_SHIFT", "MAX_PIECE_BYTES", "PRIVATE_BIT", "SIZE_MASK", "WRITE_BIT", "PixelPieces",
           "pack_pieces"]

SIZE_BITS = 10
SIZE_MASK = np.uint16((1 << SIZE_BITS) - 1)
#: Most bytes one access may touch.
MAX_PIECE_BYTES = 1 << SIZE_BITS
KIND_SHIFT = np.uint16(SIZE_BITS)
KIND_MASK = np.uint16(0xF)
WRITE_BIT = np.uint16(1 << (SIZE_BITS + 4))
PRIVATE_BIT = np.uint16(1 << (SIZE_BITS + 5))


class PixelPieces(NamedTuple):
    """Every pixel's accesses with their bytes and kinds, as the kernel reads them (made by :func:`pack_pieces`).

    Attributes
    ----------
    piece_offsets : ndarray of int64, shape (P + 1,)
        Pixel ``p`` makes accesses ``piece_offsets[p]:piece_offsets[p + 1]``.
    addresses : ndarray of uint64, shape (N,)
        First byte of each access, private kinds at their layout address.
    words : ndarray of uint16, shape (N,)
        Each access's bytes, kind and flags, as the module docstring says.
    private_span : int
        Bytes between two processes' copies (a multiple of the page size).
    """

    piece_offsets: np.ndarray
    addresses: np.ndarray
    words: np.ndarray
    private_span: int

    @property
    def sizes(self) -> np.ndarray:
        """Bytes each access touches in its line; int64 (N,)."""
        return (self.words & SIZE_MASK).astype(np.int64) + 1

    @property
    def kinds(self) -> np.ndarray:
        """Record kind of each access; uint8 (N,)."""
        return ((self.words >> KIND_SHIFT) & KIND_MASK).astype(np.uint8)

    @property
    def writes(self) -> np.ndarray:
        """True where the access is a write; bool (N,)."""
        return (self.words & WRITE_BIT) != 0

    @property
    def private(self) -> np.ndarray:
        """True where the access is to a process's own copy; bool (N,)."""
        return (self.words & PRIVATE_BIT) != 0


def pack_pieces(piece_offsets, addresses, sizes, kinds, writes, private, private_span: int) -> PixelPieces:
    """Pack every access's bytes, kind and flags into one word.

    Parameters
    ----------
    piece_offsets : array_like of int, shape (P + 1,)
        Rising from 0 to ``N``.
    addresses : array_like of uint64, shape (N,)
    sizes : array_like of int, shape (N,)
        1 ... :data:`MAX_PIECE_BYTES`.
    kinds : array_like of int, shape (N,)
        Below 16.
    writes, private : array_like of bool, shape (N,)
    private_span : int

    Returns
    -------
    PixelPieces

    Raises
    ------
    ValueError
        Naming the field out of its range.
    """
    piece_offsets = np.ascontiguousarray(piece_offsets, dtype=np.int64)
    addresses = np.ascontiguousarray(addresses, dtype=np.uint64)
    n = addresses.shape[0]
    sizes = np.ascontiguousarray(sizes, dtype=np.int64)
    kinds = np.ascontiguousarray(kinds, dtype=np.uint8)
    writes = np.ascontiguousarray(writes, dtype=np.bool_)
    private = np.ascontiguousarray(private, dtype=np.bool_)
    if any(array.shape != (n,) for array in (sizes, kinds, writes, private)):
        raise InputError(f"pack_pieces: addresses, sizes, kinds, writes and private must all have shape ({n},)")
    if piece_offsets.ndim != 1 or piece_offsets.size < 1 or piece_offsets[0] != 0 or piece_offsets[-1] != n \
            or np.any(np.diff(piece_offsets) < 0):
        raise InputError(f"pack_pieces: piece_offsets must rise from 0 to the {n} accesses")
    if n:
        if int(sizes.min()) < 1 or int(sizes.max()) > MAX_PIECE_BYTES:
            raise InputError(f"pack_pieces: an access touches {int(sizes.min())} ... {int(sizes.max())} bytes; runs "
                             f"on shared levels take 1 ... {MAX_PIECE_BYTES} (first-level lines up to "
                             f"{MAX_PIECE_BYTES} bytes)")
        if int(kinds.max()) > int(KIND_MASK):
            raise InputError(f"pack_pieces: record kind {int(kinds.max())} is not below 16")
    words = np.empty(n, dtype=np.uint16)
    _pack(sizes, kinds, writes, private, words)
    return PixelPieces(piece_offsets, addresses, words, int(private_span))


@njit(cache=True, nogil=True)
def _pack(sizes, kinds, writes, private, words):
    """Fill ``words`` (N,) from the fields, each already in its range."""
    for i in range(words.shape[0]):
        word = np.uint16(sizes[i] - 1) | (np.uint16(kinds[i]) << KIND_SHIFT)
        if writes[i]:
            word |= WRITE_BIT
        if private[i]:
            word |= PRIVATE_BIT
        words[i] = word
