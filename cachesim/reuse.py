"""Exact LRU stack (reuse) distances and miss-ratio curves.

The reuse distance of an access is the number of distinct lines touched since
the previous access to the same line (-1, "infinite", for a first touch). A
fully associative LRU cache of ``C`` lines misses exactly the accesses whose
distance is ``>= C`` or infinite, so one pass gives the miss ratio of every
capacity at once.

The kernel keeps, for every line, the time of its last access in a hash table
and marks that time in a Fenwick tree; the distance is the number of marks
after the previous access. Consecutive accesses to one line (distance 0) do
not advance time. When time reaches the tree's capacity, the live times
(one per distinct line) are renumbered 1..D in order and the tree is rebuilt,
with room for at least 4·D times: so the tree holds O(D) entries, not O(N),
and stays in cache for scenes of any trace length. O(N log D) time
(amortised), O(D) memory besides the optional per-access output.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd
from numba import njit

from cachesim.simulate import as_addresses
from rtcommon.jit import NO_REFCOUNTS
from rtcommon.validate import InputError, require_power_of_two

#: First size of the reuse kernel's Fenwick tree (it grows with the distinct lines): large
#: enough that renumbering, which sorts the live times, runs rarely (every 60,000 or more
#: accesses for up to 16,000 distinct lines).
TREE_CAPACITY = 1 << 16


@njit(cache=True, inline="always")
def _slot_of(keys, line, mask):
    slot = (line * np.int64(-7046029254386353131)) >> np.int64(17)
    slot &= mask
    while keys[slot] != line and keys[slot] != -1:
        slot = (slot + 1) & mask
    return slot


@njit(cache=True)
def _grow(keys, values):
    capacity = keys.shape[0] * 2
    new_keys = np.full(capacity, -1, dtype=np.int64)
    new_values = np.empty(capacity, dtype=np.int64)
    mask = capacity - 1
    for i in range(keys.shape[0]):
        if keys[i] != -1:
            slot = _slot_of(new_keys, keys[i], mask)
            new_keys[slot] = keys[i]
            new_values[slot] = values[i]
    return new_keys, new_values


@njit(cache=True)
def _renumber(keys, values, distinct, tree):
    """Give the live times (``values`` of used slots) the ranks 1..distinct, in
    order, and make ``tree`` the Fenwick tree with exactly those marked."""
    slots = np.flatnonzero(keys != -1)
    order = np.argsort(values[slots])
    for rank in range(distinct):
        values[slots[order[rank]]] = rank + 1
    tree[:] = 0
    size = tree.shape[0] - 1
    for position in range(1, distinct + 1):
        tree[position] += 1
        parent = position + (position & -position)
        if parent <= size:
            tree[parent] += tree[position]
    for position in range(distinct + 1, size + 1):
        parent = position + (position & -position)
        if parent <= size:
            tree[parent] += tree[position]


class ReuseState(NamedTuple):
    """The reuse kernel's state between pieces of one stream (see :class:`ReuseCounter`).

    Attributes
    ----------
    keys, values : ndarray of int64, shape (H,)
        Hash table (H a power of two): line number (-1: empty slot) and the
        time of its last access.
    tree : ndarray of int64, shape (C + 1,)
        Fenwick tree over the times 1..C, in which each line's last time is marked.
    histogram : ndarray of int64, shape (D,)
        Accesses per finite distance (grown as needed).
    scalars : ndarray of int64, shape (N_SCALARS,)
        :data:`DISTINCT` lines, the current :data:`TIME`, the
        :data:`PREVIOUS` line (-1 at the start), :data:`COLD` first touches
        and the :data:`LARGEST` distance seen (-1: none).
    """

    keys: np.ndarray
    values: np.ndarray
    tree: np.ndarray
    histogram: np.ndarray
    scalars: np.ndarray


# Columns of ReuseState.scalars.
DISTINCT, TIME, PREVIOUS, COLD, LARGEST = 0, 1, 2, 3, 4
N_SCALARS = 5


def _fresh_state(tree_capacity: int = TREE_CAPACITY) -> ReuseState:
    """An empty stream's state; ``tree_capacity`` (>= 1) is the tree's first size."""
    scalars = np.zeros(N_SCALARS, dtype=np.int64)
    scalars[PREVIOUS] = -1
    scalars[LARGEST] = -1
    return ReuseState(np.full(1 << 12, -1, dtype=np.int64), np.empty(1 << 12, dtype=np.int64),
                      np.zeros(tree_capacity + 1, dtype=np.int64), np.zeros(1024, dtype=np.int64), scalars)


@njit(cache=True, nogil=True)
def _reuse_pass(addresses, shift, distances, state):
    """Continue a stream with ``addresses`` (uint64, (N,)) at lines of ``1 << shift`` bytes.

    Writes each access's distance into ``distances`` (int64, (N,)) unless
    that is empty (0,), and counts the finite distances into the state's
    histogram. Returns the new :class:`ReuseState`: its arrays may have been
    replaced by larger ones (its scalars are updated in place).

    :func:`_reuse_run` does the work without reference counting
    (:data:`rtcommon.jit.NO_REFCOUNTS`) and stops where the state
    needs room; here the room is made: the live times renumbered (and the
    tree grown), the hash table or the histogram grown.
    """
    keys, values, tree, histogram, scalars = state
    start = 0
    while True:
        start = _reuse_run(addresses, start, shift, distances, ReuseState(keys, values, tree, histogram, scalars))
        if start == addresses.shape[0]:
            break
        distinct = scalars[DISTINCT]
        if scalars[TIME] == tree.shape[0] - 1:
            # out of times: renumber the live ones, keeping room for at least three
            # times as many new ones, so the sort is paid once per 3 * distinct accesses
            if 4 * distinct + 2 > tree.shape[0] - 1:
                tree = np.zeros(8 * distinct + 3, dtype=np.int64)
            _renumber(keys, values, distinct, tree)
            scalars[TIME] = distinct
        if 2 * (distinct + 1) > keys.shape[0]:
            keys, values = _grow(keys, values)
        if distinct >= histogram.shape[0]:  # a distance is below the number of distinct lines
            grown = np.zeros(max(2 * histogram.shape[0], distinct + 1), dtype=np.int64)
            grown[:histogram.shape[0]] = histogram
            histogram = grown
    return ReuseState(keys, values, tree, histogram, scalars)


@njit(cache=True, nogil=True, **NO_REFCOUNTS)
def _reuse_run(addresses, start, shift, distances, state):
    """:func:`_reuse_pass`'s loop from access ``start``; returns where it stopped.

    It stops at the end, or before an access to a new line when the tree is
    out of times, the hash table would be more than half full, or the
    histogram might be too short for the next distance.
    """
    keys, values, tree, histogram, scalars = state
    record = distances.shape[0] > 0
    distinct = scalars[DISTINCT]
    time = scalars[TIME]
    previous = scalars[PREVIOUS]
    cold = scalars[COLD]
    largest = scalars[LARGEST]
    size = tree.shape[0] - 1
    mask = keys.shape[0] - 1
    stop = addresses.shape[0]
    for i in range(start, addresses.shape[0]):
        line = np.int64(addresses[i] >> np.uint64(shift))
        if line == previous:
            distance = 0
        else:
            if time == size or 2 * (distinct + 1) > keys.shape[0] or distinct >= histogram.shape[0]:
                stop = i
                break
            previous = line
            time += 1
            slot = _slot_of(keys, line, mask)
            if keys[slot] == -1:
                keys[slot] = line
                distinct += 1
                distance = -1
            else:
                last = values[slot]
                marked_up_to_last = 0
                position = last
                while position > 0:
                    marked_up_to_last += tree[position]
                    position -= position & -position
                distance = distinct - marked_up_to_last
                position = last
                while position <= size:
                    tree[position] -= 1
                    position += position & -position
            values[slot] = time
            position = time
            while position <= size:
                tree[position] += 1
                position += position & -position
        if record:
            distances[i] = distance
        if distance < 0:
            cold += 1
        else:
            histogram[distance] += 1
            if distance > largest:
                largest = distance
    scalars[DISTINCT] = distinct
    scalars[TIME] = time
    scalars[PREVIOUS] = previous
    scalars[COLD] = cold
    scalars[LARGEST] = largest
    return stop


def _check_line_size(line_size) -> int:
    return require_power_of_two("line_size", line_size).bit_length() - 1


class ReuseCounter:
    """Reuse distances of a stream fed in pieces, exactly as if it came in one.

    Its memory is O(distinct lines) however long the stream, so a caller can
    feed a long trace piece by piece instead of materialising its addresses.

    >>> counter = ReuseCounter(64)
    >>> for piece in ([0, 64, 128], [0, 64]):
    ...     _ = counter.update(piece)
    >>> counter.profile().histogram.tolist(), counter.profile().cold
    ([0, 0, 2], 3)

    Parameters
    ----------
    line_size : int
        Line size in bytes (a power of two).
    """

    def __init__(self, line_size: int = 64):
        self._shift = _check_line_size(line_size)
        self.line_size = int(line_size)
        self._state = _fresh_state()

    def update(self, addresses, distances=None) -> "ReuseCounter":
        """Continue the stream with ``addresses`` (array_like of int, shape (N,)).

        ``distances`` (ndarray of int64, shape (N,)), if given, receives each
        access's distance (-1 for a first touch). Returns the counter itself.
        """
        addresses = as_addresses(addresses)
        if self._shift == 0 and addresses.size and addresses.max() >= 2**63:
            raise InputError("with 1-byte lines, addresses must be below 2**63")
        if distances is None:
            distances = np.empty(0, dtype=np.int64)
        elif distances.shape != addresses.shape or distances.dtype != np.int64:
            raise InputError(f"distances must be int64 of shape {addresses.shape}")
        self._state = _reuse_pass(addresses, self._shift, distances, self._state)
        return self

    def profile(self) -> "ReuseProfile":
        """The reuse profile of the stream so far (a copy)."""
        histogram = self._state.histogram[:self._state.scalars[LARGEST] + 1]
        return ReuseProfile(self.line_size, histogram.copy(), int(self._state.scalars[COLD]))


def reuse_distances(addresses, line_size: int = 64) -> np.ndarray:
    """Exact LRU stack distance of every access at line granularity.

    Parameters
    ----------
    addresses : array_like of int, shape (N,)
        Byte addresses in access order.
    line_size : int
        Line size in bytes (a power of two).

    Returns
    -------
    ndarray of int64, shape (N,)
        Distinct lines touched since the previous access to the same line;
        -1 for the first access to a line.
    """
    counter = ReuseCounter(line_size)
    addresses = as_addresses(addresses)
    distances = np.empty(addresses.size, dtype=np.int64)
    counter.update(addresses, distances)
    return distances


@dataclass(frozen=True)
class ReuseProfile:
    """Histogram of reuse distances of one stream.

    Attributes
    ----------
    line_size : int
    histogram : ndarray of int64, shape (D,)
        ``histogram[d]`` accesses had reuse distance ``d``.
    cold : int
        First touches (infinite distance).
    """

    line_size: int
    histogram: np.ndarray
    cold: int

    @classmethod
    def from_distances(cls, distances: np.ndarray, line_size: int) -> "ReuseProfile":
        finite = distances[distances >= 0]
        histogram = np.bincount(finite).astype(np.int64) if finite.size else np.zeros(0, np.int64)
        return cls(int(line_size), histogram, int(distances.size - finite.size))

    @property
    def accesses(self) -> int:
        return int(self.histogram.sum()) + self.cold

    def misses(self, capacity_lines) -> np.ndarray:
        """Misses of a fully associative LRU cache of each capacity (in lines).

        Parameters
        ----------
        capacity_lines : int or array_like of int, shape (K,)

        Returns
        -------
        ndarray of int64, shape (K,) (or a scalar for a scalar input)
        """
        capacity = np.asarray(capacity_lines, dtype=np.int64)
        if np.any(capacity < 0):
            raise InputError("capacity_lines must be >= 0")
        # tail[c] = accesses with distance >= c
        tail = np.concatenate((np.cumsum(self.histogram[::-1])[::-1], [0])).astype(np.int64)
        index = np.minimum(capacity, tail.size - 1)
        return tail[index] + self.cold

    def miss_ratio_curve(self, sizes=None) -> pd.DataFrame:
        """Miss ratio of a fully associative LRU cache for each size in bytes.

        Parameters
        ----------
        sizes : array_like of int, optional
            Cache sizes in bytes; default powers of two from one line up to
            the size that holds every line.

        Returns
        -------
        DataFrame with columns size (bytes), capacity_lines, misses, miss_ratio.
        """
        if sizes is None:
            top = max(1, self.histogram.size + 1)
            sizes = self.line_size * 2 ** np.arange(int(np.ceil(np.log2(top))) + 1)
        sizes = np.asarray(sizes, dtype=np.int64)
        capacity = sizes // self.line_size
        misses = self.misses(capacity)
        total = self.accesses
        return pd.DataFrame({
            "size": sizes,
            "capacity_lines": capacity,
            "misses": misses.astype(np.int64),
            "miss_ratio": misses / total if total else np.full(sizes.size, np.nan),
        })


def reuse_profile(addresses, line_size: int = 64) -> ReuseProfile:
    """Reuse-distance histogram of a stream (see :class:`ReuseProfile`)."""
    return ReuseCounter(line_size).update(addresses).profile()
