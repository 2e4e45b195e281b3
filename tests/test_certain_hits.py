"""Certain first-level read hits taken out of the shared line addresses (coherence.pixel_lines), the cache walk
that counts them (cachesim.kernels.simulate_skips_into) and the data TLB on page runs (cachesim.tlb.tlb_lookup
with a skip mask), against the whole streams walked access by access: the general compiled walk
(cachesim.by_access, itself checked against the dict-based reference caches in test_cachesim) and the
reference TLB of tests/reference_tlb.py."""
import numpy as np
import pytest

from cachesim import CacheLevel, CacheState, Hierarchy, Tlb, alpha21164, alpha21164_with_dtb
from cachesim import kernels as K
from cachesim.by_access import _simulate_by_access
from cachesim.tlb import TlbGeometry, empty_tlb, tlb_lookup, NLU, TLB_FIFO, TLB_LRU
from coherence.pixel_lines import PixelLines, held_bytes, pixel_lines, skips_certain_hits, take_out_certain_hits
from coherence.record_lines import FILL_AHEAD
from rtcommon.validate import InputError
from tracer.trace.access import AccessTrace
from tracer.trace.records import WRITE_FLAG

from reference_tlb import ReferenceTlb


def random_hierarchy(rng):
    """A direct-mapped first level of 16-64 byte lines over an LRU second of 1-4 ways and 0-1 direct-mapped or
    LRU levels below, inclusive or not, with random write allocation."""
    while True:
        line = 1 << int(rng.integers(4, 7))
        levels = [CacheLevel("L1", line * (1 << int(rng.integers(1, 5))), line, 1,
                             write_allocate=bool(rng.integers(2)))]
        line2 = line << int(rng.integers(0, 2))
        ways2 = int(rng.integers(1, 5))
        levels.append(CacheLevel("L2", line2 * ways2 * (1 << int(rng.integers(1, 5))), line2, ways2, "lru",
                                 write_allocate=bool(rng.integers(2))))
        if rng.integers(2):
            ways3 = int(rng.integers(1, 3))
            levels.append(CacheLevel("L3", line2 * ways3 * (1 << int(rng.integers(2, 6))), line2, ways3, "lru",
                                     write_allocate=bool(rng.integers(2))))
        try:
            return Hierarchy(tuple(levels), inclusion=str(rng.choice(["inclusive", "non-inclusive"])))
        except ValueError:  # an inclusive level above one that does not allocate writes, say
            continue


def random_pixels(rng, line_shift, n_pixels):
    """Line addresses of ``n_pixels`` pixels (a few hot lines revisited, as tree nodes are), their write flags
    (3%) and offsets."""
    lengths = rng.integers(0, 120, n_pixels)
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    hot = rng.integers(0, 1 << 10, 24)
    lines = np.where(rng.random(offsets[-1]) < 0.6, rng.choice(hot, offsets[-1]), rng.integers(0, 1 << 12, offsets[-1]))
    return (lines.astype(np.uint64) << np.uint64(line_shift)), rng.random(offsets[-1]) < 0.03, offsets


def held(addresses, writes, offsets, line_shift):
    """A PixelLines holding every access, with room after its arrays as pixel_lines leaves."""
    room_addresses = np.zeros(addresses.size + 4, dtype=np.uint64)
    room_writes = np.zeros(addresses.size + 4, dtype=np.bool_)
    room_addresses[:addresses.size] = addresses
    room_writes[:addresses.size] = writes
    written = np.concatenate([[0], np.cumsum(writes, dtype=np.int64)])
    pixel_writes = written[offsets[1:]] - written[offsets[:-1]]  # empty pixels (the last too) count 0
    return PixelLines(offsets.copy(), room_addresses[:addresses.size], room_writes[:addresses.size], pixel_writes,
                      line_shift)


def replay_both(rng, hierarchy, addresses, writes, offsets, taken):
    """Every pixel in a random order, with a random foreign stream (another process's slice) now and then, on
    one state whole and on another from ``taken``: the states, clocks and TLBs after each pixel must agree."""
    whole, short = CacheState(hierarchy), CacheState(hierarchy)
    work = K.chunk_buffers()
    no_writes = np.zeros(0, dtype=np.bool_)
    served = np.zeros(0, dtype=np.uint8)
    clock_whole = clock_short = 0
    page_shift = taken.page_shift
    tlb_geometry = TlbGeometry(page_shift, 4, NLU)
    tlb_whole, tlb_short = empty_tlb(4), empty_tlb(4)
    for pixel in rng.permutation(offsets.size - 1):
        if rng.random() < 0.3:
            foreign = (rng.integers(0, 1 << 12, int(rng.integers(1, 60))).astype(np.uint64)
                       << np.uint64(taken.line_shift))
            clock_whole = _simulate_by_access(foreign, no_writes, whole.geometry, whole.arrays, clock_whole, served,
                                              False, work)
            clock_short = _simulate_by_access(foreign, no_writes, short.geometry, short.arrays, clock_short, served,
                                              False, work)
            tlb_lookup(foreign, tlb_geometry, tlb_whole)
            tlb_lookup(foreign, tlb_geometry, tlb_short)
        start, stop = offsets[pixel], offsets[pixel + 1]
        clock_whole = _simulate_by_access(addresses[start:stop], writes[start:stop], whole.geometry, whole.arrays,
                                          clock_whole, served, False, work)
        first, last = taken.line_offsets[pixel], taken.line_offsets[pixel + 1]
        flags = taken.writes[first:last] if taken.pixel_writes[pixel] else no_writes
        clock_short = K.simulate_skips_into(taken.addresses[first:last], flags, taken.skip_mask, short.geometry,
                                            short.arrays, clock_short, work)
        tlb_lookup(addresses[start:stop], tlb_geometry, tlb_whole)
        runs = taken.page_runs[taken.page_offsets[pixel]:taken.page_offsets[pixel + 1]]
        tlb_lookup(runs, tlb_geometry, tlb_short, (1 << page_shift) - 1)
        assert clock_short == clock_whole
        for a, b in zip(whole.arrays, short.arrays):
            np.testing.assert_array_equal(a, b)
        for a, b in zip(tlb_whole, tlb_short):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(30))
def test_taken_out_hits_leave_the_state_of_the_whole_stream(seed):
    """On seeded random hierarchies and pixels, pixels replayed from the taken-out lines (and the TLB from the
    page runs) leave every tag, stamp, counter and clock as the general walk of every access does. Fails when
    the take-out forgets a lower level's conflict (``elif since[s] > read_at: certain = False`` dropped,
    checked: an inclusive eviction then leaves a line out of the first level that it counts as a hit), or when
    the walk forgets the clock of the hits (``clock += 1 + pending`` made ``clock += 1``: checked)."""
    rng = np.random.default_rng(seed)
    hierarchy = random_hierarchy(rng)
    line_shift = hierarchy.levels[0].line_size.bit_length() - 1
    addresses, writes, offsets = random_pixels(rng, line_shift, 60)
    taken = take_out_certain_hits(held(addresses, writes, offsets, line_shift), hierarchy)
    assert taken.skip_mask == (1 << line_shift) - 1
    assert taken.addresses.size < addresses.size  # the hot lines give certain hits
    replay_both(rng, hierarchy, addresses, writes, offsets, taken)


@pytest.mark.parametrize("policy", [NLU, TLB_LRU, TLB_FIFO])
def test_page_runs_look_up_as_every_access(policy):
    """The TLB on a pixel's page runs with their counts equals the reference TLB looking every access up, for
    every policy, runs longer than a page's count field split. Fails when a run's repeats are not counted as
    lookups (``skipped += repeats`` dropped: checked)."""
    rng = np.random.default_rng(40 + policy)
    page_shift = 9
    pages = np.repeat(rng.integers(0, 12, 400), rng.integers(1, 30, 400))
    pages = np.concatenate([pages, np.full(1500, 5)])  # longer than 511 repeats: split
    addresses = (pages.astype(np.uint64) << np.uint64(page_shift)) + rng.integers(0, 16, pages.size).astype(np.uint64) * np.uint64(32)
    offsets = np.array([0, 100, 100, addresses.size], dtype=np.int64)
    taken = take_out_certain_hits(held(addresses, np.zeros(addresses.size, bool), offsets, 5),
                                  Hierarchy((CacheLevel("L1", 512, 32, 1), CacheLevel("L2", 3072, 64, 3)),
                                            tlb=Tlb(entries=4, page_size=512, miss_cycles=1.0)))
    reference = ReferenceTlb(4, 512, {NLU: "nlu", TLB_LRU: "lru", TLB_FIFO: "fifo"}[policy])
    tlb = empty_tlb(4)
    geometry = TlbGeometry(page_shift, 4, policy)
    misses = 0
    for pixel in range(3):
        runs = taken.page_runs[taken.page_offsets[pixel]:taken.page_offsets[pixel + 1]]
        assert ((runs & np.uint64(511)) < 511).all() or pixel == 2
        misses += tlb_lookup(runs, geometry, tlb, 511)
    for address in addresses:
        reference.lookup(address)
    assert tlb.counts.tolist() == [addresses.size, reference.hits, reference.misses] and misses == reference.misses


def test_certain_hits_by_hand():
    """Lines A (set 0), B (set 1), C (set 0 of the 2-set first level, set 0 of the second), 32-byte lines: in
    A B A the second A is certain; in A C A it is not (C took A's set); in A(write) A it is not (a write does
    not allocate); the count field fills at 31 and the next hit is kept. Fails when a write counts as putting its
    line in the first level (``if not write:`` before ``last_read[...] = i`` dropped: checked)."""
    hierarchy = Hierarchy((CacheLevel("L1", 64, 32, 1, write_allocate=False), CacheLevel("L2", 256, 64, 2)),
                          inclusion="inclusive")
    a, b, c = np.uint64(0), np.uint64(32), np.uint64(64 * 2)
    pixels = [[a, b, a], [a, c, a], [a, a], [a] + [a] * 33]
    write_of = [[0, 0, 0], [0, 0, 0], [1, 0], [0] * 34]
    addresses = np.array([x for pixel in pixels for x in pixel], dtype=np.uint64)
    writes = np.array([w for pixel in write_of for w in pixel], dtype=np.bool_)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in pixels])]).astype(np.int64)
    taken = take_out_certain_hits(held(addresses, writes, offsets, 5), hierarchy)
    kept = [taken.addresses[taken.line_offsets[p]:taken.line_offsets[p + 1]].tolist() for p in range(4)]
    assert kept == [[a, b + 1], [a, c, a], [a, a], [a + 31, a + 1]]


def test_which_hierarchies_take_hits_out_and_lines_of_another_are_refused():
    """The alpha presets take hits out (with or without the DTB, alike: same key); a set-associative first level
    or another line size does not; a run refuses lines taken out for another hierarchy, one whose second
    level differs only in its replacement policy included. Fails when the run does not check the key (the
    ``elif lines.skip_mask and ...`` check dropped: checked), or the key leaves the policy out and the run
    does not ask :func:`skips_certain_hits` of its own hierarchy (both dropped: checked)."""
    from coherence.pixel_lines import pixel_lines, skip_key
    from coherence.simulation import simulate_run
    from coherence.mappings import Strip
    from test_scheduler import COST, placed_for
    from trace_factory import random_trace

    assert skips_certain_hits(alpha21164(), 32) and skips_certain_hits(alpha21164_with_dtb(), 32)
    assert skip_key(alpha21164()) == skip_key(alpha21164_with_dtb())
    assert not skips_certain_hits(alpha21164(), 64)
    two_way = Hierarchy((CacheLevel("L1", 512, 32, 2), CacheLevel("L2", 3072, 64, 3)))
    assert not skips_certain_hits(two_way, 32)
    trace = random_trace(width=8, height=6, seed=4)
    placed = placed_for()
    other = Hierarchy((CacheLevel("L1", 512, 32, 1), CacheLevel("L2", 6144, 64, 3)))
    lines = pixel_lines(trace, placed, 32, hierarchy=other)
    assert lines.skip_mask
    with pytest.raises(InputError, match="taken out for the hierarchy"):
        simulate_run(trace, Strip().build(8, 6, 2), Hierarchy(other.levels[:1] + (CacheLevel("L2", 3072, 64, 3),)),
                     placed, COST, lines=lines)
    fifo = Hierarchy(other.levels[:1] + (CacheLevel("L2", 6144, 64, 3, policy="fifo"),))
    with pytest.raises(InputError, match="taken out for the hierarchy"):  # same sizes, another replacement
        simulate_run(trace, Strip().build(8, 6, 2), fifo, placed, COST, lines=lines)
    with pytest.raises(InputError, match="take_out_certain_hits"):
        take_out_certain_hits(lines, other)


@pytest.mark.parametrize("seed", range(6))
def test_lines_taken_out_from_the_records_equal_those_of_every_access_held(seed):
    """pixel_lines given a hierarchy works out one pixel's accesses at a time from the records and never holds
    every access; on random traces, hierarchies (a TLB of 512 B or 8 KB pages) and page placements its lines
    equal take_out_certain_hits of every access held (checked against the whole walk above), with a third of
    the records writes. Fails when the records' pass leaves its addresses virtual (``translate_addresses`` in
    _take_out_records dropped: checked)."""
    from dataclasses import replace

    from coherence.page_placement import PagePlacement
    from test_scheduler import placed_for
    from trace_factory import random_trace

    rng = np.random.default_rng(200 + seed)
    hierarchy = replace(random_hierarchy(rng), tlb=Tlb(entries=4, page_size=int(rng.choice([512, 8192])),
                                                       miss_cycles=1.0))
    line_size = hierarchy.levels[0].line_size
    trace = random_trace(width=12, height=9, seed=seed)
    records = np.array(trace.records)  # a third of them writes: writes end a line's certain hits
    records[rng.random(records.size) < 1 / 3] |= np.uint32(WRITE_FLAG)
    trace = AccessTrace(trace.pixel_offsets, records, trace.counters, trace.width, trace.height, {})
    placed = placed_for().with_pages(PagePlacement(str(rng.choice(["random", "bin-hopping"])), 8192, seed),
                                     alpha21164())
    every = pixel_lines(trace, placed, line_size)
    expected = take_out_certain_hits(every, hierarchy)
    taken = pixel_lines(trace, placed, line_size, hierarchy=hierarchy)
    assert taken.addresses.size < every.addresses.size and taken.skips_for == expected.skips_for
    assert taken.writes.any() and taken.pixel_writes.sum() == every.writes.sum()
    for name, a, b in zip(PixelLines._fields, taken, expected):
        np.testing.assert_array_equal(a, b, err_msg=name)


def test_the_budget_counts_the_bytes_held_at_the_peak():
    """held_bytes of lines taken out is the bytes of the result's arrays, the offsets of every access and the
    one pixel's accesses being worked out; pixel_lines returns the lines within that budget and None one byte
    below it; the room reserved for every access is given back (the arrays own exactly what they show).
    Fails when the records' pass ignores its budget (its ``bytes_left`` check dropped: checked) or when the
    result's arrays are views of the reserved ones (``resize`` replaced by slicing: checked)."""
    from test_scheduler import placed_for
    from trace_factory import random_trace

    trace, placed, hierarchy = random_trace(width=12, height=9, seed=3), placed_for(), alpha21164_with_dtb()
    every = pixel_lines(trace, placed, 32)
    lines = pixel_lines(trace, placed, 32, hierarchy=hierarchy)
    longest = int(np.diff(every.line_offsets).max())
    held = held_bytes(lines.addresses.size, lines.pixel_writes.size, lines.page_runs.size, longest)
    arrays = sum(array.nbytes for array in (lines.line_offsets, lines.addresses, lines.writes, lines.pixel_writes,
                                            lines.page_offsets, lines.page_runs))
    assert held == arrays + every.line_offsets.nbytes + (longest + FILL_AHEAD) * (8 + 1)
    for array in (lines.addresses, lines.writes, lines.page_runs):
        assert array.base is None and array.flags.owndata
    within = pixel_lines(trace, placed, 32, budget_bytes=held, hierarchy=hierarchy)
    for name, a, b in zip(PixelLines._fields, within, lines):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert pixel_lines(trace, placed, 32, budget_bytes=held - 1, hierarchy=hierarchy) is None
    # smaller budgets reserve less room than every access (the pass stops in the pixel that passes them)
    fixed = held_bytes(0, lines.pixel_writes.size, 0, longest)
    for budget in np.linspace(fixed - 100, held - 1, 9).astype(np.int64):
        assert pixel_lines(trace, placed, 32, budget_bytes=int(budget), hierarchy=hierarchy) is None
    assert held_bytes(every.addresses.size, every.pixel_writes.size) == (
        every.line_offsets.nbytes + every.pixel_writes.nbytes + (every.addresses.size + FILL_AHEAD) * (8 + 1))
