"""The per-access path for a direct-mapped first level over at least one more.

The 21164's D-cache is direct-mapped, and on the study-era traces only a
third of its accesses hit, in no pattern a branch predictor learns. The
general walk (:mod:`cachesim.by_access`) branches on that hit and then on the
second level's, and spent most of its time recovering from the mispredicted
branches. Here every access looks both levels up at once, and a read
either serves is finished with selects instead of branches: a first-level
hit changes nothing, a second-level hit stamps its way (LRU) and fills the
first level's one way. Writes (a few in a thousand on the study-era traces)
take branches. A second level's miss looks a direct-mapped third level (the
21164's B-cache) up with one tag compare and fills it without a stamp, in
scalars too; the levels below it, or a third level that is not
direct-mapped, are walked as in the general walk. The kernel stays a
function of its own in its callers (:data:`rtcommon.jit.NOT_INLINED`).

The semantics (inclusion, writes, counters, ``served_by``, the clock and the
stamps it leaves) are exactly those of :mod:`cachesim.by_access`, which tests
check state for state on seeded random hierarchies and streams. Exclusive
hierarchies move lines on every hit and keep the general walk.
"""
import numpy as np
from numba import njit

from cachesim.full import _fill_levels, _serving_level
from cachesim.sets import EVICTIONS, EXCLUSIVE, INCLUSIVE, LRU, _add_counts, _insert, _zeroed_counts
from rtcommon.jit import NO_REFCOUNTS, NOT_INLINED


@njit(cache=True, inline="always")
def serves_direct_first(geometry):
    """Whether :func:`_simulate_direct_first` applies to a hierarchy: at
    least two levels, not exclusive, a direct-mapped first level and an LRU
    second, both with a power-of-two number of sets (the 21164's)."""
    return (geometry.rel_shift.shape[0] >= 2 and geometry.inclusion != EXCLUSIVE and geometry.ways[0] == 1
            and geometry.policy[1] == LRU and geometry.set_mask[0] >= 0 and geometry.set_mask[1] >= 0)


@njit(cache=True, inline="always")
def _simulate_direct_first(addresses, writes, geometry, state, clock, served_by, record, work):
    """:func:`cachesim.by_access._simulate_by_access` for a hierarchy that
    :func:`serves_direct_first`: same parameters, same results."""
    if record:
        if writes.shape[0] > 0:
            return _direct_first_kernel(addresses, writes, geometry, state, clock, served_by, work, 0)
        return _direct_first_kernel(addresses, None, geometry, state, clock, served_by, work, 0)
    if writes.shape[0] > 0:
        return _direct_first_kernel(addresses, writes, geometry, state, clock, None, work, 0)
    return _direct_first_kernel(addresses, None, geometry, state, clock, None, work, 0)


@njit(cache=True, inline="always")
def _simulate_direct_first_skips(addresses, writes, skip_mask, geometry, state, clock, work):
    """:func:`_simulate_direct_first` of a stream whose certain first-level read hits were taken out,
    each access's low ``skip_mask`` bits counting those that followed it (:func:`_direct_first_kernel`)."""
    if writes.shape[0] > 0:
        return _direct_first_kernel(addresses, writes, geometry, state, clock, None, work, skip_mask)
    return _direct_first_kernel(addresses, None, geometry, state, clock, None, work, skip_mask)


@njit(cache=True, inline="always")
def _ways_holding(tags, base, n_ways, line):
    """The way of the set of ``n_ways`` ways from ``base`` that holds ``line``, or -1, with a select
    per way and no early exit (a line is in a set once)."""
    slot = np.int64(-1)
    for way in range(base, base + n_ways):
        slot = way if tags[np.uint64(way)] == line else slot
    return slot


@njit(cache=True, inline="always")
def _find_way(tags, base, n_ways, line):
    """:func:`_ways_holding`, with a loop of fixed length for three ways (the 21164's S-cache), which
    the compiler unrolls."""
    if n_ways == 3:
        return _ways_holding(tags, base, 3, line)
    return _ways_holding(tags, base, n_ways, line)


@njit(cache=True, **NOT_INLINED, **NO_REFCOUNTS)
def _direct_first_kernel(addresses, writes, geometry, state, clock, served_by, work, skip_mask):
    """The kernel of :func:`_simulate_direct_first`, compiled apart for a
    stream of reads (``writes`` None) and for one that does not record
    ``served_by`` (None): numba drops the checks of a None argument, at the
    price of compiling more specialisations.

    ``skip_mask`` (0, or ``2**b - 1`` with ``b`` at most the line shift):
    the low bits of each address count the reads that followed it in the
    original stream and that the first level was certain to serve (a line
    a read put there with no access to any of the line's sets in any level
    since: :func:`coherence.pixel_lines.pixel_lines` takes them out). Such
    a read changes no state in a direct-mapped first level, so each counts
    as an access and a read hit there and advances the clock, as walked it
    would; ``served_by`` must then be None.

    Every index is cast to unsigned: numba fixes up a negative signed index
    (a shift, a mask and an add at every array access), which took a quarter
    of this loop's time.
    """
    rel_shift = geometry.rel_shift
    set_mask = geometry.set_mask
    ways = geometry.ways
    offset = geometry.offset
    seeds = geometry.seeds
    write_allocate = geometry.write_allocate
    inclusive = geometry.inclusion == INCLUSIVE
    tags = state.tags
    stamps = state.stamps
    counts = state.counts
    n_levels = rel_shift.shape[0]
    shift = np.uint64(geometry.line_shift)
    # The first two levels' geometry in scalars: every access reads both.
    mask0 = set_mask[0]
    allocate0 = write_allocate[0]
    rel1 = rel_shift[1]
    mask1 = set_mask[1]
    ways1 = ways[1]
    offset1 = offset[1]
    seed1 = seeds[1]
    allocate1 = write_allocate[1]
    # The first level's read hits and evictions; writes and the second
    # level's misses are counted apart, and its hits are what is left.
    first_read_hits = np.int64(0)
    first_evictions = np.int64(0)
    first_write_hits = np.int64(0)
    second_write_hits = np.int64(0)
    second_misses = np.int64(0)
    second_evictions = np.int64(0)
    first_invalidations = np.int64(0)
    n_writes = np.int64(0)
    level_hits, level_write_hits, invalidations = _zeroed_counts(work, n_levels)
    # A direct-mapped third level (the 21164's B-cache) is looked up and
    # filled here too, with its geometry in scalars.
    third_direct = n_levels >= 3 and ways[2] == 1 and set_mask[2] >= 0
    third = 2 if third_direct else 0  # any level: read only when third_direct
    rel2 = rel_shift[third]
    mask2 = set_mask[third]
    offset2 = offset[third]
    allocate2 = write_allocate[third]
    stamp2 = geometry.policy[third] == LRU  # a hit is a use
    spread21 = rel2 - rel1  # second-level lines per third-level line, log2
    third_hits = np.int64(0)
    third_write_hits = np.int64(0)
    third_evictions = np.int64(0)
    second_invalidations = np.int64(0)
    unused = np.int64(0)
    n = addresses.shape[0]
    low = np.uint64(skip_mask)
    pending = np.int64(0)  # certain hits after the last access, counted as the next one comes
    skipped = np.int64(0)
    i = 0
    while i < n:
        # Reads that the first level or the second serves run in a loop of
        # their own, left at the first access it cannot serve with what that
        # access looked up: the values only the rest needs wait outside it,
        # and the loop keeps its own in registers.
        while True:
            at = np.uint64(i)
            address = addresses[at]
            line0 = np.int64(address >> shift)
            base0 = np.uint64(line0 & mask0)
            resident = tags[base0]
            hit0 = resident == line0
            line1 = line0 >> rel1
            base1 = offset1 + (line1 & mask1) * ways1
            slot1 = _find_way(tags, base1, ways1, line1)
            is_write = False if writes is None else writes[at]
            clock += 1 + pending
            pending = np.int64(address & low)
            skipped += pending
            i += 1
            # Neither level holds it: slot1 < 0 and resident != line0, in
            # arithmetic, as a test of hit0 would be compiled to a branch.
            differs = resident ^ line0
            if is_write or (slot1 & (differs | -differs)) < 0:
                break
            # Served: nothing changes on a first-level hit; a second-level
            # hit stamps its way (LRU) and fills the first level, with selects.
            miss0 = not hit0
            touched = np.uint64(slot1 if slot1 >= 0 else base1)
            kept = stamps[touched]
            # The stamp read is used again (summed into `unused`): a select of
            # a value read for it alone is compiled to a branch around the read.
            unused ^= kept
            stamps[touched] = clock if miss0 else kept
            tags[base0] = line0
            first_evictions += np.int64(miss0 & (resident >= 0))
            first_read_hits += np.int64(hit0)
            if served_by is not None:
                served_by[at] = np.uint8(miss0)
            if i == n:
                break
        if not is_write and (hit0 | (slot1 >= 0)):
            break  # the last access was served above
        # A write, or a read that neither level holds.
        if is_write:
            n_writes += 1
            if hit0:  # changes nothing in a direct-mapped level
                first_write_hits += 1
                if served_by is not None:
                    served_by[at] = 0
                continue
            if slot1 >= 0:
                second_write_hits += 1
                stamps[slot1] = clock  # a write is a use
                if allocate0:
                    first_evictions += np.int64(resident >= 0)
                    tags[base0] = line0
                if served_by is not None:
                    served_by[at] = 1
                continue
        # Neither level holds it: walk the levels below the second, as the general walk does.
        second_misses += 1
        if third_direct:
            line2 = line0 >> rel2
            base2 = np.uint64(offset2 + (line2 & mask2))
            if tags[base2] == line2:
                served = np.int64(2)
                third_hits += 1
                if is_write:
                    third_write_hits += 1
                if stamp2:
                    stamps[base2] = clock
            else:
                served = np.int64(3)
                if n_levels > 3:  # the levels below, as the general walk does
                    served = _serving_level(line0, 3, geometry, state, None, clock, is_write, work)
                    _fill_levels(served, 3, geometry, state, None, clock, is_write, work)
                if allocate2 or not is_write:  # no stamp, as the walk's direct-mapped fill
                    evicted = tags[base2]
                    tags[base2] = line2
                    if evicted >= 0:
                        third_evictions += 1
                        if inclusive:  # the lines of the levels above inside the evicted one leave them
                            first = evicted << spread21
                            for sub in range(first, first + (np.int64(1) << spread21)):
                                sub_base = offset1 + (sub & mask1) * ways1
                                for way in range(sub_base, sub_base + ways1):
                                    if tags[way] == sub:
                                        tags[way] = -1
                                        second_invalidations += 1
                            first = evicted << rel2
                            for sub in range(first, first + (np.int64(1) << rel2)):
                                if tags[sub & mask0] == sub:
                                    tags[sub & mask0] = -1
                                    first_invalidations += 1
        else:
            served = _serving_level(line0, 2, geometry, state, None, clock, is_write, work)
            _fill_levels(served, 2, geometry, state, None, clock, is_write, work)
        if served_by is not None:
            served_by[at] = served
        if not (is_write and not allocate1):
            if ways1 == 1:  # no stamp, as the walk's direct-mapped fill
                evicted = tags[base1]
                tags[base1] = line1
            else:
                evicted = _insert(tags, stamps, seed1, base1, ways1, LRU, line1, clock)
            if evicted >= 0:
                second_evictions += 1
                if inclusive:  # the first level's lines inside the evicted one leave it
                    first = evicted << rel1
                    for sub in range(first, first + (np.int64(1) << rel1)):
                        if tags[sub & mask0] == sub:
                            tags[sub & mask0] = -1
                            first_invalidations += 1
        if allocate0 or not is_write:
            first_evictions += np.int64(tags[base0] >= 0)
            tags[base0] = line0
    clock += pending
    n_accesses = addresses.shape[0] + skipped
    level_hits[0] = first_read_hits + skipped + first_write_hits
    level_write_hits[0] = first_write_hits
    level_hits[1] = n_accesses - second_misses - level_hits[0]
    level_write_hits[1] = second_write_hits
    invalidations[0] += first_invalidations
    counts[0, EVICTIONS] += first_evictions
    counts[1, EVICTIONS] += second_evictions
    if third_direct:
        level_hits[2] += third_hits
        level_write_hits[2] += third_write_hits
        invalidations[1] += second_invalidations
        counts[2, EVICTIONS] += third_evictions
    work.level_lines[0] = unused  # scratch: keeps the stamps' second use
    _add_counts(counts, n_accesses, n_writes, level_hits, level_write_hits, invalidations)
    return clock
