"""Slow, obvious reference of cachesim.multicore: one interleaved stream replayed access by access.

Every instance of every level is a :class:`reference_cache.ReferenceLevel`
(OrderedDicts, or a list of ways for random replacement); lines lost to a
coherence invalidation are kept in one dict per instance, with the bytes of
the write that removed them. The clock counts accesses from 1, over all
threads. Counts have the 11 columns of cachesim.multicore (accesses, hits,
misses, evictions, back-invalidations, writes, write hits, write misses,
coherence invalidations, coherence misses, false-sharing misses), per level,
instance and record kind.

Rules (the same as the module's docstring says, written again from it):
the access goes through the instances serving its thread, first level down,
until one holds its line; the levels that missed are filled from the lowest
up, except those that do not allocate on writes for a write; a filled line
is no longer lost; an inclusive fill's victim is removed from the instances
above that the same instance serves; then a write removes its line from
every instance, at every level, that does not serve its thread, and marks it
lost there with the write's bytes. A miss on a lost line is a coherence
miss, and a false-sharing one when its bytes and the marked bytes are disjoint.
"""
import numpy as np

from reference_cache import ReferenceLevel

N_COLUMNS = 11
N_KINDS = 16


def reference_threads(addresses, thread_ids, machine, writes=None, sizes=None, kinds=None):
    """Return (counts (L, G, 16, 11) int64, served (T, L + 1) int64) for one interleaved stream."""
    config = machine.hierarchy.levels
    n_levels = len(config)
    widths = [machine.threads_per_instance(level) for level in range(n_levels)]
    caches = [[ReferenceLevel(level, index) for _ in range(machine.n_instances(index))]
              for index, level in enumerate(config)]
    lost = [[{} for _ in range(machine.n_instances(index))] for index in range(n_levels)]
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
            row = counts[level, mine[level], kind]
            row[0] += 1
            row[5] += is_write
            if caches[level][mine[level]].lookup(lines[level]):
                row[1] += 1
                row[6] += is_write
                served = level
                break
            row[2] += 1
            row[7] += is_write
            if lines[level] in lost[level][mine[level]]:
                row[9] += 1
                written_first, written_end = lost[level][mine[level]][lines[level]]
                if end <= written_first or written_end <= first:
                    row[10] += 1
        served_counts[thread, served] += 1
        for level in range(served - 1, -1, -1):
            if is_write and not config[level].write_allocate:
                continue
            evicted = caches[level][mine[level]].insert(lines[level], clock)
            lost[level][mine[level]].pop(lines[level], None)
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
                            if caches[upper][above].remove(sub):
                                counts[upper, above, kind, 4] += 1
        if is_write:
            for level in range(n_levels):
                for other in range(machine.n_instances(level)):
                    if other != mine[level] and caches[level][other].remove(lines[level]):
                        counts[level, other, kind, 8] += 1
                        lost[level][other][lines[level]] = (first, end)
    return counts, served_counts
