"""Slow, obvious reference of cachesim.multicore_prefetch: threads, shared instances, coherence and
prefetchers, replayed access by access.

Written from the rules in cachesim.multicore's and cachesim.multicore_prefetch's
docstrings. Each instance is a reference_multicore.Instance (explicit ways
with ghosts); each instance of a level with a prefetcher has its own
reference_prefetch.StrideTable and its own set of unused prefetched lines,
and counts a prefetch useless when its line leaves the instance unused
(evicted, back-invalidated or invalidated by another thread's write). The
clock advances per access and per issued prefetch. Demand counts have the
11 columns of cachesim.multicore.
"""
import numpy as np

from reference_multicore import Instance
from reference_prefetch import StrideTable


class ReferenceThreads:
    def __init__(self, machine):
        self.machine = machine
        self.config = machine.hierarchy.levels
        n = len(self.config)
        self.widths = [machine.threads_per_instance(level) for level in range(n)]
        sizes = [machine.n_instances(level) for level in range(n)]
        self.caches = [[Instance(level, index) for _ in range(sizes[index])] for index, level in enumerate(self.config)]
        self.unused = [[set() for _ in range(size)] for size in sizes]
        self.tables = [[StrideTable(level.prefetcher.table_size) if level.prefetcher is not None
                        and level.prefetcher.kind == "stride" else None for _ in range(sizes[index])]
                       for index, level in enumerate(self.config)]
        most = max(sizes)
        self.counts = np.zeros((n, most, 16, 11), dtype=np.int64)
        self.prefetch = np.zeros((n, most, 3), dtype=np.int64)
        self.served = np.zeros((machine.n_threads, n + 1), dtype=np.int64)
        self.clock = 0

    def pending(self):
        out = np.zeros(self.prefetch.shape[:2], dtype=np.int64)
        for level, instances in enumerate(self.unused):
            for instance, lines in enumerate(instances):
                out[level, instance] = len(lines)
        return out

    def _left(self, level, instance, line):
        if line in self.unused[level][instance]:
            self.unused[level][instance].remove(line)
            self.prefetch[level, instance, 2] += 1

    def _fill(self, served, last, lines, thread, kind, is_write):
        mine = [thread // width for width in self.widths]
        for level in range(served - 1, last - 1, -1):
            if is_write and not self.config[level].write_allocate:
                continue
            evicted = self.caches[level][mine[level]].fill(lines[level], self.clock)
            if evicted is None:
                continue
            self.counts[level, mine[level], kind, 3] += 1
            self._left(level, mine[level], evicted)
            if self.machine.hierarchy.inclusion == "inclusive":
                for upper in range(level):
                    ratio = self.config[level].line_size // self.config[upper].line_size
                    for above in range(self.machine.n_instances(upper)):
                        if above * self.widths[upper] // self.widths[level] != mine[level]:
                            continue
                        for sub in range(evicted * ratio, (evicted + 1) * ratio):
                            if self.caches[upper][above].remove(sub) is not None:
                                self.counts[upper, above, kind, 4] += 1
                                self._left(upper, above, sub)

    def _candidates(self, level, instance, address, kind, missed, first_use):
        prefetcher = self.config[level].prefetcher
        line_size = self.config[level].line_size
        if prefetcher.trigger == "miss" and not missed:
            return []
        if prefetcher.kind == "next-line":
            if prefetcher.trigger == "tagged" and not (missed or first_use):
                return []
            return [address // line_size + prefetcher.distance + j for j in range(prefetcher.degree)]
        stride = self.tables[level][instance].update(kind, address)
        if not stride:
            return []
        targets = [address + (prefetcher.distance + j) * stride for j in range(prefetcher.degree)]
        return [target // line_size for target in targets if target >= 0]

    def _prefetch(self, level, line, thread, kind):
        mine = [thread // width for width in self.widths]
        if self.caches[level][mine[level]].holding(line) is not None:
            return
        self.clock += 1
        self.prefetch[level, mine[level], 0] += 1
        byte = line * self.config[level].line_size
        lines = [byte // config.line_size for config in self.config]
        served = len(self.config)
        for below in range(level + 1, len(self.config)):
            if self.caches[below][mine[below]].lookup(lines[below], self.clock):
                served = below
                break
        self._fill(served, level, lines, thread, kind, False)
        self.unused[level][mine[level]].add(line)

    def access(self, address, thread, is_write, kind, first, end):
        self.clock += 1
        n = len(self.config)
        lines = [address // level.line_size for level in self.config]
        mine = [thread // width for width in self.widths]
        # the first level, from the top, whose instance holds the line (lookups stop there)
        served = next((level for level in range(n) if self.caches[level][mine[level]].lookup(lines[level], self.clock)),
                      n)
        for level in range(min(served + 1, n)):
            row = self.counts[level, mine[level], kind]
            hit = level == served
            row[[0, 5]] += (1, is_write)
            row[[1, 6] if hit else [2, 7]] += (1, is_write)
            ghost = None if hit else self.caches[level][mine[level]].ghost_of(lines[level])
            if ghost is not None:
                _, written_first, written_end = ghost.ghost
                row[9] += 1
                row[10] += end <= written_first or written_end <= first
        self.served[thread, served] += 1
        first_use = False
        if served < n and lines[served] in self.unused[served][mine[served]]:
            self.unused[served][mine[served]].remove(lines[served])
            self.prefetch[served, mine[served], 1] += 1
            first_use = True
        self._fill(served, 0, lines, thread, kind, is_write)
        for level in range(min(served + 1, n)):
            if self.config[level].prefetcher is None:
                continue
            for line in self._candidates(level, mine[level], address, kind, level < served,
                                         first_use and level == served):
                self._prefetch(level, line, thread, kind)
        if is_write:
            for level in range(n):
                for other in range(self.machine.n_instances(level)):
                    way = None if other == mine[level] else self.caches[level][other].remove(lines[level])
                    if way is not None:
                        way.ghost = (lines[level], first, end)
                        self.counts[level, other, kind, 8] += 1
                        self._left(level, other, lines[level])


def reference_threads_prefetching(addresses, thread_ids, machine, writes=None, sizes=None, kinds=None):
    """Replay one interleaved stream through a fresh reference; return it."""
    reference = ReferenceThreads(machine)
    line_size = machine.hierarchy.levels[0].line_size
    for i, address in enumerate(int(a) for a in addresses):
        if sizes is None:
            first = address - address % line_size
            end = first + line_size
        else:
            first, end = address, address + int(sizes[i])
        reference.access(address, int(thread_ids[i]), bool(writes[i]) if writes is not None else False,
                         int(kinds[i]) if kinds is not None else 0, first, end)
    return reference
