"""The set-level steps of the shared-cache simulator (:mod:`cachesim.multicore`).

Finding a line in a set of one cache instance, placing a line in it (the
victim rule of :mod:`cachesim.sets`), the ghosts that coherence
invalidations leave and their filter, inclusion's back-invalidations, and a
write's invalidation of the other instances' copies with the owners table
that narrows its search. Every function is a compiled helper inlined into
the access path of :mod:`cachesim.multicore` and
:mod:`cachesim.multicore_prefetch`; the rules they follow are in the
docstring of :mod:`cachesim.multicore`.
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from cachesim.multicore_state import BACK_INVALIDATIONS, COHERENCE_INVALIDATIONS
from cachesim.sets import RANDOM, _find, _random_way


@njit(cache=True, inline="always")
def _filter_slot(line, instance_number, ghost_filter):
    """The entry of ``ghost_filter`` that counts a ghost of ``line`` in the instance numbered
    ``instance_number`` among all instances (bits 40 up of a Fibonacci hash of the two)."""
    key = (np.uint64(line) << np.uint64(16)) ^ np.uint64(instance_number)
    mixed = (key * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return np.int64(mixed & np.uint64(ghost_filter.shape[0] - 1))


# The helpers take arrays, not bundles: a bundle's field read in the
# per-access loop costs a reference-count update each time.
@njit(cache=True, inline="always")
def _byte_range(address, size, line0, line_shift):
    """Bytes ``first .. end - 1`` an access touches: ``size`` bytes from ``address``, or its whole line
    ``line0`` when ``size`` is 0."""
    if size > 0:
        first = np.int64(address)
        return first, first + size
    first = line0 << line_shift
    return first, first + (np.int64(1) << line_shift)


@njit(cache=True, inline="always")
def set_index(line, set_mask, n_sets):
    """The set of ``line`` in a level of ``n_sets`` sets: ``line & set_mask`` when ``set_mask`` >= 0 (a power
    of two of sets), else ``line % n_sets``."""
    return line & set_mask if set_mask >= 0 else line % n_sets


@njit(cache=True, inline="always")
def _set_of(line, level, instance, n_sets, set_mask, ways, offset, level_ways):
    """First way of ``line``'s set in instance ``instance`` of ``level``."""
    return (offset[level] + instance * level_ways[level]
            + set_index(line, set_mask[level], n_sets[level]) * ways[level])


def _trailing_zeros(value):
    """The number of trailing zero bits of a nonzero unsigned integer. Compiled, it is LLVM's ``cttz``
    (one instruction, :func:`_cttz`); this plain-Python body runs when numba is switched off."""
    value = int(value)
    return np.uint64((value & -value).bit_length() - 1)


@intrinsic
def _cttz(typingctx, value):
    """LLVM's ``cttz`` of an unsigned integer (any answer for 0, which callers rule out)."""
    if not isinstance(value, types.Integer) or value.signed:
        return None

    def codegen(context, builder, signature, args):
        width = args[0].type
        function = cgutils.get_or_insert_function(builder.module, ir.FunctionType(width, [width, ir.IntType(1)]),
                                                  f"llvm.cttz.i{width.width}")
        return builder.call(function, [args[0], ir.IntType(1)(1)])

    return value(value), codegen


@overload(_trailing_zeros)
def _trailing_zeros_compiled(value):
    return lambda value: _cttz(value)


@njit(cache=True, inline="always")
def _probe_ways(tags, base, n_ways, line):
    """:func:`cachesim.sets._find` without an early exit or a branch per way: a bit per way that holds
    ``line`` (a line is in a set once), every way compared, and the way of the lowest bit set. The index
    is unsigned: numba tests a signed index for a negative value (counted from the end), which costs a
    select per way. At most 64 ways take this path (:func:`_probe`)."""
    matches = np.uint64(0)
    first = np.uint64(base)
    for way in range(n_ways):
        matches |= np.uint64(tags[first + np.uint64(way)] == line) << np.uint64(way)
    return base + np.int64(_trailing_zeros(matches)) if matches else np.int64(-1)


@njit(cache=True, inline="always")
def _probe_any(tags, base, n_ways, line):
    """:func:`_probe_ways` for sets of any number of ways."""
    first = np.uint64(base)
    for way in range(n_ways):
        if tags[first + np.uint64(way)] == line:
            return base + way
    return np.int64(-1)


@njit(cache=True, inline="always")
def _probe(tags, base, n_ways, line):
    """:func:`_probe_ways`, with a loop of fixed length for the common associativities (8, 12 and 16
    ways), which the compiler unrolls."""
    if n_ways == 8:
        return _probe_ways(tags, base, 8, line)
    if n_ways == 16:
        return _probe_ways(tags, base, 16, line)
    if n_ways == 12:
        return _probe_ways(tags, base, 12, line)
    if n_ways <= 64:
        return _probe_ways(tags, base, n_ways, line)
    return _probe_any(tags, base, n_ways, line)


#: :func:`_probe` for callers outside cachesim: the way of ``line`` in the set whose first way is ``base``
#: (-1: not there).
probe_set = _probe


@njit(cache=True, inline="always")
def _victim_ways(tags, stamps, base, n_ways):
    """The first empty way of the set, else the first of its least stamps, with one comparison per
    way: an empty way ranks below every stamp (stamps are clocks, >= 0), the earlier of two empty
    ways first. Returns the way and its rank (< 0: empty). Unsigned indices, as in :func:`_probe_ways`."""
    victim = np.int64(0)
    lowest = np.int64(9223372036854775807)
    first = np.uint64(base)
    for way in range(n_ways):
        slot = first + np.uint64(way)
        rank = way - np.int64(9223372036854775807) if tags[slot] < 0 else stamps[slot]
        if rank < lowest:
            lowest = rank
            victim = way
    return base + victim, lowest


@njit(cache=True, inline="always")
def _place(tags, stamps, seed, base, n_ways, policy, line, clock):
    """:func:`cachesim.sets._insert` (the same victim: the first empty way, else the first
    of the least stamps, else a random draw), the victim found by :func:`_victim_ways` with a
    loop of fixed length for the common associativities (as :func:`_probe`)."""
    if n_ways == 8:
        victim, lowest = _victim_ways(tags, stamps, base, 8)
    elif n_ways == 16:
        victim, lowest = _victim_ways(tags, stamps, base, 16)
    elif n_ways == 12:
        victim, lowest = _victim_ways(tags, stamps, base, 12)
    else:
        victim, lowest = _victim_ways(tags, stamps, base, n_ways)
    if lowest >= 0 and policy == RANDOM:
        victim = base + _random_way(seed, clock, n_ways)
    evicted = tags[victim]
    tags[victim] = line
    stamps[victim] = clock
    return evicted


@njit(cache=True, inline="always")
def _drop_ghost(slot, filter_entry, ghosts, ghost_filter):
    ghosts[slot] = -1
    ghost_filter[filter_entry] -= 1


@njit(cache=True, inline="always")
def _back_invalidate(evicted, level, instance, kind, geometry, machine, state):
    """Inclusion: remove the evicted line from the instances above that ``instance`` serves."""
    width = machine.threads_per_instance[level]
    for upper in range(level):
        spread = geometry.rel_shift[level] - geometry.rel_shift[upper]
        per_upper = machine.threads_per_instance[upper]
        first_line = evicted << spread
        for above in range(instance * width // per_upper, (instance + 1) * width // per_upper):
            for sub in range(first_line, first_line + (np.int64(1) << spread)):
                base = _set_of(sub, upper, above, geometry.n_sets, geometry.set_mask, geometry.ways,
                               geometry.offset, machine.level_ways)
                slot = _find(state.tags, base, geometry.ways[upper], sub)
                if slot >= 0:
                    state.tags[slot] = -1
                    state.counts[upper, above, kind, BACK_INVALIDATIONS] += 1


@njit(cache=True, inline="always")
def _thread_bit(thread):
    """The bit of hardware thread ``thread`` in a sharers mask: bit ``thread mod 64`` (threads 64 apart share one)."""
    return np.int64(1) << np.int64(thread & 63)


@njit(cache=True, inline="always")
def _instance_bits(instance, width):
    """The sharers-mask bits of the threads that instance ``instance`` of a level ``width`` threads wide
    serves (threads ``instance * width`` ... ``(instance + 1) * width - 1``): ``width`` bits from bit
    ``instance * width mod 64``, wrapping around; all 64 when ``width >= 64``."""
    if width >= 64:
        return np.int64(-1)
    ones = (np.uint64(1) << np.uint64(width)) - np.uint64(1)
    start = np.uint64((instance * width) & 63)
    return np.int64((ones << start) | (ones >> ((np.uint64(64) - start) & np.uint64(63))))


@njit(cache=True, inline="always")
def _invalidate_others(line0, thread, kind, first, end, sharers, geometry, machine, state):
    """A write by ``thread``: remove its line from every instance that does not serve the thread,
    leaving a ghost with the write's bytes. Only instances serving a thread whose bit is in the mask
    ``sharers`` (:func:`_thread_bit`; -1: every thread) are searched: no other holds the line."""
    for level in range(geometry.rel_shift.shape[0]):
        line = line0 >> geometry.rel_shift[level]
        own = machine.instance_of[level, thread]
        width = machine.threads_per_instance[level]
        for other in range(machine.n_instances[level]):
            if other == own or (sharers != -1 and _instance_bits(other, width) & sharers == 0):
                continue
            base = _set_of(line, level, other, geometry.n_sets, geometry.set_mask, geometry.ways, geometry.offset,
                           machine.level_ways)
            slot = _probe(state.tags, base, geometry.ways[level], line)
            if slot >= 0:
                state.tags[slot] = -1
                state.ghosts[slot] = line
                state.ghost_bytes[slot, 0] = first
                state.ghost_bytes[slot, 1] = end
                state.ghost_filter[_filter_slot(line, machine.instance_base[level] + other,
                                                state.ghost_filter)] += 1
                state.counts[level, other, kind, COHERENCE_INVALIDATIONS] += 1


@njit(cache=True, inline="always")
def _owner_slot(line, owners):
    """The entry of ``owners`` (rows a power of two) for first-level line ``line``: the top bits of a
    Fibonacci hash of it."""
    mixed = (np.uint64(line) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    return np.int64(mixed & np.uint64(owners.shape[0] - 1))


@njit(cache=True, inline="always")
def _note_fill(line0, thread, owners):
    """A fill of first-level line ``line0`` by ``thread``: the line's owners entry, if it has one,
    gains the thread's bit."""
    if owners.shape[0] > 0:
        entry = _owner_slot(line0, owners)
        if owners[entry, 0] == line0:
            owners[entry, 1] |= _thread_bit(thread)


@njit(cache=True, inline="always")
def _write_invalidate(line0, thread, kind, first, end, geometry, machine, state):
    """:func:`_invalidate_others` for a write by ``thread``, searching only the instances of the threads
    the owners table names for the line (all without an entry), and skipped when those threads share
    the thread's first-level instance, hence every instance that serves it (no copy to remove); after a
    search, the entry names the thread alone."""
    owners = state.owners
    if owners.shape[0] == 0:
        _invalidate_others(line0, thread, kind, first, end, np.int64(-1), geometry, machine, state)
        return
    entry = _owner_slot(line0, owners)
    sharers = np.int64(-1)
    if owners[entry, 0] == line0:
        sharers = owners[entry, 1]
        width = machine.threads_per_instance[0]
        own_bits = _instance_bits(machine.instance_of[0, thread], width)
        if machine.instance_of.shape[1] <= 64 and sharers & ~own_bits == 0:
            return
    _invalidate_others(line0, thread, kind, first, end, sharers, geometry, machine, state)
    owners[entry, 0] = line0
    owners[entry, 1] = _thread_bit(thread)
