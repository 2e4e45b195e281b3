"""Slow, obvious reference of cachesim.multicore: one interleaved stream replayed access by access.

Every instance of every level is a list of sets, each a list of ways; a way
holds a line or None, the clock of its last use (LRU) or fill (FIFO), and a
ghost: the line a coherence invalidation removed from it, with the bytes of
that write, or None. The clock counts accesses from 1, over all threads.
Counts have the 11 columns of cachesim.multicore (accesses, hits, misses,
evictions, back-invalidations, writes, write hits, write misses, coherence
invalidations, coherence misses, false-sharing misses), per level, instance
and record kind.

Rules (the same as the module's docstring says, written again from it):
the access goes through the instances serving its thread, first level down,
until one holds its line; a miss on a line that has a ghost in its set is a
coherence miss, and a false-sharing one when its bytes and the ghost's are
disjoint. The levels that missed are filled from the lowest up, except
those that do not allocate on writes for a write: the line's own ghost in
the set goes, the line takes the first empty way (else the least recently
used, first filled or randomly drawn one), and a ghost in that way goes.
An inclusive fill's victim is removed from the instances above that the
same instance serves. Then a write removes its line from every instance, at
every level, that does not serve its thread, leaving a ghost in its way.
"""
import numpy as np

from cachesim.simulate import _seed_state
from reference_cache import random_way

N_COLUMNS = 11
N_KINDS = 16


class Way:
    def __init__(self):
        self.line = None
        self.stamp = 0
        self.ghost = None  # (line, first byte, end)


class Instance:
    """One cache instance with explicit ways."""

    def __init__(self, level, index):
        self.n_sets = level.n_sets
        self.policy = level.policy
        self.seed = _seed_state(level.seed, index)
        self.sets = [[Way() for _ in range(level.ways)] for _ in range(level.n_sets)]

    def ways(self, line):
        return self.sets[line % self.n_sets]

    def holding(self, line):
        return next((way for way in self.ways(line) if way.line == line), None)

    def ghost_of(self, line):
        return next((way for way in self.ways(line) if way.ghost is not None and way.ghost[0] == line), None)

    def lookup(self, line, clock):
        way = self.holding(line)
        if way is not None and self.policy == "lru":
            way.stamp = clock
        return way is not None

    def fill(self, line, clock):
        """Place ``line``; return the evicted line or None."""
        own = self.ghost_of(line)
        if own is not None:
            own.ghost = None
        ways = self.ways(line)
        empty = [way for way in ways if way.line is None]
        if empty:
            victim = empty[0]
        elif self.policy == "random":
            victim = ways[random_way(self.seed, clock, len(ways))]
        else:
            victim = min(ways, key=lambda way: way.stamp)  # min keeps the first of equal stamps
        evicted = victim.line
        victim.line, victim.stamp, victim.ghost = line, clock, None
        return evicted

    def remove(self, line):
        way = self.holding(line)
        if way is not None:
            way.line = None
        return way


def reference_threads(addresses, thread_ids, machine, writes=None, sizes=None, kinds=None):
    """Return (counts (L, G, 16, 11) int64, served (T, L + 1) int64) for one interleaved stream."""
    config = machine.hierarchy.levels
    n_levels = len(config)
    widths = [machine.threads_per_instance(level) for level in range(n_levels)]
    caches = [[Instance(level, index) for _ in range(machine.n_instances(index))]
              for index, level in enumerate(config)]
    most = max(machine.n_instances(index) for index in range(n_levels))
    counts = np.zeros((n_levels, most, N_KINDS, N_COLUMNS), dtype=np.int64)
    served_counts = np.zeros((machine.n_threads, n_levels + 1), dtype=np.int64)
    n = len(addresses)
    writes = [False] * n if writes is None else [bool(w) for w in writes]
    kinds = [0] * n if kinds is None else [int(k) for k in kinds]
    for i in range(n):
        clock = i + 1
        address, thread, is_write, kind = int(addresses[i]), int(thread_ids[i]), writes[i], kinds[i]
        if sizes is None:
            first = address - address % config[0].line_size
            end = first + config[0].line_size
        else:
            first, end = address, address + int(sizes[i])
        lines = [address // level.line_size for level in config]
        mine = [thread // width for width in widths]
        served = n_levels
        for level in range(n_levels):
            cache = caches[level][mine[level]]
            row = counts[level, mine[level], kind]
            row[0] += 1
            row[5] += is_write
            if cache.lookup(lines[level], clock):
                row[1] += 1
                row[6] += is_write
                served = level
                break
            row[2] += 1
            row[7] += is_write
            ghost = cache.ghost_of(lines[level])
            if ghost is not None:
                row[9] += 1
                _, written_first, written_end = ghost.ghost
                if end <= written_first or written_end <= first:
                    row[10] += 1
        served_counts[thread, served] += 1
        for level in range(served - 1, -1, -1):
            if is_write and not config[level].write_allocate:
                continue
            evicted = caches[level][mine[level]].fill(lines[level], clock)
            if evicted is None:
                continue
            counts[level, mine[level], kind, 3] += 1
            if machine.hierarchy.inclusion == "inclusive":
                for upper in range(level):
                    ratio = config[level].line_size // config[upper].line_size
                    for above in range(machine.n_instances(upper)):
                        # the instances above that this one serves: their threads are among its threads
                        if above * widths[upper] // widths[level] != mine[level]:
                            continue
                        for sub in range(evicted * ratio, (evicted + 1) * ratio):
                            if caches[upper][above].remove(sub) is not None:
                                counts[upper, above, kind, 4] += 1
        if is_write:
            for level in range(n_levels):
                for other in range(machine.n_instances(level)):
                    if other == mine[level]:
                        continue
                    way = caches[level][other].remove(lines[level])
                    if way is not None:
                        way.ghost = (lines[level], first, end)
                        counts[level, other, kind, 8] += 1
    return counts, served_counts


def assert_equals_reference(machine, addresses, thread_ids, writes, sizes, kinds):
    """Run cachesim.multicore.simulate_threads on the stream, assert that every count and each thread's served
    counts equal :func:`reference_threads`'s, and return its result."""
    from cachesim.multicore import simulate_threads

    expected, served = reference_threads(addresses, thread_ids, machine, writes, sizes, kinds)
    result = simulate_threads(addresses, thread_ids, machine, writes=writes, sizes=sizes, kinds=kinds)
    np.testing.assert_array_equal(result.counts, expected)
    np.testing.assert_array_equal(result.served, served)
    return result
