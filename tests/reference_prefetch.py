"""Slow, obvious reference of the prefetchers (rules in cachesim.prefetch's docstring).

Sets are the reference levels of reference_cache (OrderedDicts, oldest first;
random replacement by the documented hash of seed and clock). Unlike the
simulator, which finds unused prefetched lines from per-way marks and derives
the useless ones, this reference keeps a set of unused prefetched lines per
level and counts a line useless at the moment it is evicted or invalidated.
"""
import numpy as np

from reference_cache import ReferenceLevel

INITIAL, TRANSIENT, STEADY, NO_PREDICTION = "initial", "transient", "steady", "no-prediction"


def holds(level, line):
    """Whether a reference level holds ``line``, without touching its recency."""
    return line in level.sets[line % level.n_sets]


class StrideTable:
    """Chen & Baer's reference prediction table, one dict per entry."""

    def __init__(self, size):
        self.entries = [None] * size

    def update(self, pc, address):
        """Update the entry of ``pc`` with ``address``; return the stride when steady after it, else None."""
        index = pc % len(self.entries)
        entry = self.entries[index]
        if entry is None or entry["pc"] != pc:
            self.entries[index] = {"pc": pc, "previous": address, "stride": 0, "state": INITIAL}
            return None
        seen = address - entry["previous"]
        correct = seen == entry["stride"]
        state = entry["state"]
        if state == INITIAL:
            entry["state"] = STEADY if correct else TRANSIENT
        elif state == TRANSIENT:
            entry["state"] = STEADY if correct else NO_PREDICTION
        elif state == STEADY:
            entry["state"] = STEADY if correct else INITIAL
        else:
            entry["state"] = TRANSIENT if correct else NO_PREDICTION
        if not correct and state != STEADY:
            entry["stride"] = seen
        entry["previous"] = address
        return entry["stride"] if entry["state"] == STEADY else None


class ReferencePrefetching:
    """A hierarchy with prefetchers, fed one access at a time."""

    def __init__(self, hierarchy):
        self.hierarchy = hierarchy
        self.levels = [ReferenceLevel(level, index) for index, level in enumerate(hierarchy.levels)]
        self.prefetchers = [level.prefetcher for level in hierarchy.levels]
        self.tables = [StrideTable(p.table_size) if p is not None and p.kind == "stride" else None
                       for p in self.prefetchers]
        n = len(self.levels)
        self.counts = np.zeros((n, 8), dtype=np.int64)
        self.prefetch = np.zeros((n, 3), dtype=np.int64)  # issued, useful, useless
        self.unused = [set() for _ in range(n)]
        self.clock = 0
        self.served_by = []

    def pending(self):
        return np.array([len(lines) for lines in self.unused], dtype=np.int64)

    def _left(self, index, line):
        """``line`` left level ``index``: a useless prefetch if it was unused."""
        if line in self.unused[index]:
            self.unused[index].remove(line)
            self.prefetch[index, 2] += 1

    def _fill(self, served, last, lines, is_write):
        """Fill levels served - 1 down to ``last`` with ``lines[level]``, bottom-up, with inclusion."""
        for index in range(served - 1, last - 1, -1):
            if is_write and not self.hierarchy.levels[index].write_allocate:
                continue
            evicted = self.levels[index].insert(lines[index], self.clock)
            if evicted is None:
                continue
            self.counts[index, 3] += 1
            self._left(index, evicted)
            if self.hierarchy.inclusion == "inclusive":
                for upper in range(index):
                    ratio = self.levels[index].line_size // self.levels[upper].line_size
                    for sub in range(evicted * ratio, (evicted + 1) * ratio):
                        if self.levels[upper].remove(sub):
                            self.counts[upper, 4] += 1
                            self._left(upper, sub)

    def _candidates(self, index, address, pc, missed, first_use):
        prefetcher = self.prefetchers[index]
        line_size = self.levels[index].line_size
        if prefetcher.trigger == "miss" and not missed:
            return []
        if prefetcher.kind == "next-line":
            if prefetcher.trigger == "tagged" and not (missed or first_use):
                return []
            line = address // line_size
            return [line + prefetcher.distance + j for j in range(prefetcher.degree)]
        stride = self.tables[index].update(pc, address)
        if not stride:
            return []
        targets = [address + (prefetcher.distance + j) * stride for j in range(prefetcher.degree)]
        return [target // line_size for target in targets if target >= 0]

    def _prefetch(self, index, line):
        if holds(self.levels[index], line):
            return
        self.clock += 1
        self.prefetch[index, 0] += 1
        first_byte = line * self.levels[index].line_size
        lines = [first_byte // level.line_size for level in self.levels]
        served = len(self.levels)
        for below in range(index + 1, len(self.levels)):
            if self.levels[below].lookup(lines[below]):
                served = below
                break
        self._fill(served, index, lines, False)
        self.unused[index].add(line)

    def access(self, address, is_write=False, pc=0):
        self.clock += 1
        n = len(self.levels)
        lines = [address // level.line_size for level in self.levels]
        served = n
        for index, level in enumerate(self.levels):
            self.counts[index, 0] += 1
            self.counts[index, 5] += is_write
            if level.lookup(lines[index]):
                self.counts[index, 1] += 1
                self.counts[index, 6] += is_write
                served = index
                break
            self.counts[index, 2] += 1
            self.counts[index, 7] += is_write
        self.served_by.append(served)
        first_use = False
        if served < n and lines[served] in self.unused[served]:
            self.unused[served].remove(lines[served])
            self.prefetch[served, 1] += 1
            first_use = True
        self._fill(served, 0, lines, is_write)
        for index in range(min(served + 1, n)):
            if self.prefetchers[index] is None:
                continue
            for line in self._candidates(index, address, pc, index < served, first_use and index == served):
                self._prefetch(index, line)


def reference_prefetching(addresses, hierarchy, writes=None, pcs=None):
    """Run a stream through a fresh reference; return it (counts, prefetch, pending(), served_by, clock)."""
    reference = ReferencePrefetching(hierarchy)
    n = len(addresses)
    writes = [False] * n if writes is None else [bool(flag) for flag in writes]
    pcs = [0] * n if pcs is None else [int(pc) for pc in pcs]
    for address, is_write, pc in zip(addresses, writes, pcs):
        reference.access(int(address), is_write, pc)
    return reference
