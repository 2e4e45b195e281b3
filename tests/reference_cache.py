"""Slow, obvious reference models used to check the compiled simulator.

LRU and FIFO sets are OrderedDicts (oldest first); random replacement keeps a
list of ways and draws victims with the same documented hash of (level seed,
access clock) as the simulator, so the victim sequences can be compared
exactly. The clock counts accesses from 1.

Writes (``writes[i]`` true): a write hit is served like a read (LRU recency
updated); a write miss goes on down like a read miss; on the way back the
levels that missed are filled, except those with ``write_allocate=False``.
Counts have 8 columns: accesses, hits, misses, evictions, invalidations,
writes, write hits, write misses.
"""
from collections import OrderedDict

import numpy as np

from cachesim.simulate import _seed_state

MASK64 = (1 << 64) - 1


def random_way(seed, clock, ways):
    """splitmix64's finaliser of clock XOR seed; top 32 bits scaled to [0, ways)."""
    x = (clock ^ seed) & MASK64
    x ^= x >> 30
    x = (x * 0xBF58476D1CE4E5B9) & MASK64
    x ^= x >> 27
    x = (x * 0x94D049BB133111EB) & MASK64
    x ^= x >> 31
    return ((x >> 32) * ways) >> 32


class ReferenceLevel:
    def __init__(self, level, index):
        self.line_size = level.line_size
        self.n_sets = level.n_sets
        self.ways = level.ways
        self.policy = level.policy
        if self.policy == "random":
            self.sets = [[None] * self.ways for _ in range(self.n_sets)]
            self.seed = _seed_state(level.seed, index)
        else:
            self.sets = [OrderedDict() for _ in range(self.n_sets)]

    def _set(self, line):
        return self.sets[line % self.n_sets]

    def lookup(self, line):
        entries = self._set(line)
        if line not in entries:
            return False
        if self.policy == "lru":
            entries.move_to_end(line)
        return True

    def remove(self, line):
        entries = self._set(line)
        if self.policy == "random":
            if line in entries:
                entries[entries.index(line)] = None
                return True
            return False
        return entries.pop(line, None) is not None

    def insert(self, line, clock):
        """Place line at access ``clock``; return the evicted line or None."""
        entries = self._set(line)
        if self.policy == "random":
            if None in entries:
                entries[entries.index(None)] = line
                return None
            way = random_way(self.seed, clock, self.ways)
            evicted, entries[way] = entries[way], line
            return evicted
        evicted = None
        if len(entries) == self.ways:
            evicted, _ = entries.popitem(last=False)
        entries[line] = True
        return evicted


def reference_simulate(addresses, hierarchy, writes=None):
    """Return (counts (L, 8) int64, served_by list) like cachesim.simulate."""
    levels = [ReferenceLevel(level, index) for index, level in enumerate(hierarchy.levels)]
    allocate = [level.write_allocate for level in hierarchy.levels]
    n_levels = len(levels)
    counts = np.zeros((n_levels, 8), dtype=np.int64)
    served_by = []
    addresses = [int(a) for a in addresses]
    flags = [False] * len(addresses) if writes is None else [bool(w) for w in writes]
    for clock, (address, is_write) in enumerate(zip(addresses, flags), start=1):
        lines = [address // level.line_size for level in levels]
        served = n_levels
        for index, level in enumerate(levels):
            counts[index, 0] += 1
            counts[index, 5] += is_write
            if level.lookup(lines[index]):
                counts[index, 1] += 1
                counts[index, 6] += is_write
                served = index
                break
            counts[index, 2] += 1
            counts[index, 7] += is_write
        served_by.append(served)
        if served == 0:
            continue
        if hierarchy.inclusion == "exclusive":
            if served < n_levels:
                levels[served].remove(lines[served])
            line = lines[0]
            for index, level in enumerate(levels):
                line = level.insert(line, clock)
                if line is None:
                    break
                counts[index, 3] += 1
            continue
        for index in range(served - 1, -1, -1):
            if is_write and not allocate[index]:
                continue
            evicted = levels[index].insert(lines[index], clock)
            if evicted is None:
                continue
            counts[index, 3] += 1
            if hierarchy.inclusion == "inclusive":
                for upper in range(index):
                    ratio = levels[index].line_size // levels[upper].line_size
                    for sub in range(evicted * ratio, (evicted + 1) * ratio):
                        if levels[upper].remove(sub):
                            counts[upper, 4] += 1
    return counts, served_by


def reference_reuse_distances(addresses, line_size):
    """O(N^2) reuse distances: distinct lines since the previous same-line access."""
    lines = [int(a) // line_size for a in addresses]
    last_seen = {}
    distances = []
    for i, line in enumerate(lines):
        if line in last_seen:
            distances.append(len(set(lines[last_seen[line] + 1:i])))
        else:
            distances.append(-1)
        last_seen[line] = i
    return np.array(distances, dtype=np.int64)


def stack_reuse_distances(addresses, line_size):
    """Reuse distances from an explicit LRU stack (most recent first): the
    distance is the line's depth in the stack. O(N * D), fast enough for long
    streams over few lines; shares nothing with the kernel's Fenwick tree."""
    stack = []
    distances = []
    for address in addresses:
        line = int(address) // line_size
        if line in stack:
            depth = stack.index(line)
            del stack[depth]
            distances.append(depth)
        else:
            distances.append(-1)
        stack.insert(0, line)
    return np.array(distances, dtype=np.int64)
