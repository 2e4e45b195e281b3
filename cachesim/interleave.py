"""Round-robin interleaving of per-thread streams into the one stream :func:`cachesim.multicore.simulate_threads` replays.

>>> from cachesim.interleave import interleave
>>> addresses, threads = interleave([[0, 64, 128], [4096, 4160]], quantum=2)
>>> threads.tolist()
[0, 0, 1, 1, 0]
"""
from __future__ import annotations

import numpy as np

from cachesim.inputs import as_addresses, small_integers
from rtcommon.validate import InputError

__all__ = ["interleave", "interleave_order"]


def interleave_order(lengths, quantum: int = 1, times=None) -> tuple[np.ndarray, np.ndarray]:
    """The round-robin order of per-thread streams laid one after another.

    Parameters
    ----------
    lengths : sequence of int, length T
        Accesses of hardware thread ``t``'s stream, at position ``t``.
    quantum : int
        Length of a turn (>= 1): ``quantum`` accesses, or with ``times``
        ``quantum`` units of time (cycles, say).
    times : sequence of array_like of int, length T, optional
        When each thread issues each of its accesses, non-decreasing per
        thread. A turn then holds a thread's accesses issued in one window
        of ``quantum`` units: window ``w`` is times ``[w * quantum, (w + 1) * quantum)``,
        every thread's accesses of window ``w`` come before any of ``w + 1``,
        and within a window thread 0's come first, then thread 1's, and so
        on. With ``quantum=1`` and one access per unit of time per thread,
        the threads alternate access by access.

    Returns
    -------
    order : ndarray of int64, shape (N,)
        Positions in the concatenated streams, in interleaved order.
    thread_ids : ndarray of int64, shape (N,)
        The thread of each access of the interleaved stream.
    """
    if isinstance(quantum, bool) or not isinstance(quantum, (int, np.integer)) or quantum < 1:
        raise InputError(f"interleave: quantum must be an integer >= 1, got {quantum!r}")
    lengths = [int(length) for length in lengths]
    if times is None:
        # Access j of thread t runs in round j // quantum, after the earlier threads' turns of that round.
        rounds = [np.arange(length, dtype=np.int64) // quantum for length in lengths]
    else:
        times = list(times)
        if len(times) != len(lengths):
            raise InputError(f"interleave: {len(lengths)} streams but {len(times)} arrays of times")
        rounds = []
        for thread, (stamps, length) in enumerate(zip(times, lengths)):
            stamps = small_integers(stamps, length, f"times[{thread}]", 1 << 62, "a time")
            if stamps.size > 1 and (np.diff(stamps) < 0).any():
                at = int(np.flatnonzero(np.diff(stamps) < 0)[0]) + 1
                raise InputError(f"interleave: times[{thread}] must not decrease; it does at access {at}")
            rounds.append(stamps // quantum)
    if not lengths:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    threads = np.concatenate([np.full(length, thread, dtype=np.int64) for thread, length in enumerate(lengths)])
    order = np.lexsort((threads, np.concatenate(rounds)))
    return order.astype(np.int64), threads[order]


def interleave(streams, quantum: int = 1, times=None) -> tuple[np.ndarray, np.ndarray]:
    """Interleave per-thread address streams round-robin (turns as in :func:`interleave_order`).

    Parameters
    ----------
    streams : sequence of array_like of int, length T
        Stream of hardware thread ``t`` at position ``t``; an exhausted
        stream drops out of the rotation.
    quantum : int
        Accesses per turn (>= 1), or units of time per turn with ``times``.
    times : sequence of array_like of int, optional
        Issue time of each access of each stream (see :func:`interleave_order`).

    Returns
    -------
    addresses : ndarray of uint64, shape (N,)
    thread_ids : ndarray of int64, shape (N,)
        Which thread made each access; ``addresses[thread_ids == t]`` is
        stream ``t`` in its order.
    """
    arrays = [as_addresses(stream, name=f"streams[{index}]") for index, stream in enumerate(streams)]
    order, threads = interleave_order([array.size for array in arrays], quantum, times)
    if not arrays:
        return np.zeros(0, dtype=np.uint64), threads
    return np.concatenate(arrays)[order], threads
