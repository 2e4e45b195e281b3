"""Physical page placement against a by-hand mapping of every line, and what each policy promises."""
from __future__ import annotations

import numpy as np
import pytest

from cachesim.config import alpha21164, alpha21164_with_dtb
from coherence.layout import get_layout
from coherence.page_placement import PAGE_PLACEMENTS, PagePlacement
from coherence.pixel_lines import pixel_lines
from coherence.simulation import simulate_run
from coherence.mappings import get_mapping

PAGE = 8192


SMALL_SCENE = {"kd_node": 3000, "index_entry": 5000, "sphere": 900, "triangle": 700, "material": 8, "light": 3}


def _placed(seed=1):
    return _spread_trace(12, 10, SMALL_SCENE, 40, seed), get_layout("alpha1997").place(SMALL_SCENE)


def _frames_by_hand(placed, placement, n_colours):
    """Each policy's frame of every page that holds a record, walked page by page in a dict."""
    first_page = placed.layout.base // PAGE
    used = set()
    for start, size in zip(placed.record_start.tolist(), placed.record_size.tolist()):
        if size:
            used.update(range(start // PAGE, (start + size - 1) // PAGE + 1))
    rng = np.random.default_rng(placement.seed)
    frames = {}
    if placement.policy == "random":
        colours = rng.integers(0, n_colours, -(-placed.end // PAGE) - first_page)
        frames = {page: page * n_colours + int(colours[page - first_page]) for page in used}
    elif placement.policy == "bin-hopping":
        hand = int(rng.integers(n_colours))
        for rank, page in enumerate(sorted(used)):
            frames[page] = page * n_colours + (hand + rank) % n_colours
    else:
        frames = {page: page * n_colours + page % n_colours for page in used}
    return frames


@pytest.mark.parametrize("policy", ["colouring", "bin-hopping", "random"])
@pytest.mark.parametrize("seed", [0, 5])
def test_every_line_maps_as_by_hand(policy, seed):
    """Fails when a line keeps its virtual page's number or loses its offset in the page
    (e.g. ``| (address & offset_mask)`` dropped from translate_addresses)."""
    trace, placed = _placed(seed)
    placement = PagePlacement(policy, PAGE, seed)
    hierarchy = alpha21164()
    n_colours = placement.colours(hierarchy)
    assert n_colours == 512  # 4 MB direct-mapped B-cache over 8 KB pages
    frames = _frames_by_hand(placed, placement, n_colours)
    virtual = placed.addresses(trace.records, 32)
    physical = placed.with_pages(placement, hierarchy).addresses(trace.records, 32)
    expected = np.array([frames[int(a) // PAGE] * PAGE + int(a) % PAGE for a in virtual], dtype=np.uint64)
    np.testing.assert_array_equal(physical, expected)


def test_the_shared_lines_of_a_study_are_translated_too():
    """pixel_lines reads the same page table: fails when it leaves its addresses virtual."""
    trace, placed = _placed(2)
    paged = placed.with_pages(PagePlacement("random", PAGE, 3), alpha21164())
    lines = pixel_lines(trace, paged, 32)
    np.testing.assert_array_equal(lines.addresses, paged.addresses(trace.records, 32))


def test_contiguous_translates_nothing():
    trace, placed = _placed(3)
    paged = placed.with_pages(PagePlacement(), alpha21164())
    assert paged.pages.frame.size == 0
    np.testing.assert_array_equal(paged.addresses(trace.records, 64), placed.addresses(trace.records, 64))


def test_distinct_pages_get_distinct_frames_and_random_spreads_colours():
    _, placed = _placed(4)
    for policy in PAGE_PLACEMENTS[1:]:
        table = placed.with_pages(PagePlacement(policy, PAGE, 9), alpha21164()).pages
        assert np.unique(table.frame).size == table.frame.size
    table = placed.with_pages(PagePlacement("random", PAGE, 9), alpha21164()).pages
    colours = table.frame % 512
    # random colours collide (birthday problem); colouring of consecutive pages never does
    assert np.unique(colours).size < colours.size


def _spread_trace(width, height, counts, records_per_pixel, seed):
    """A trace whose pixels read records of every kind in ``counts`` at random over the whole scene."""
    from tracer.trace.access import AccessTrace
    from tracer.trace.records import COUNTER_NAMES, RecordKind, pack

    rng = np.random.default_rng(seed)
    kinds = np.array([RecordKind[name.upper()] for name in counts])
    limits = np.array(list(counts.values()))
    chosen = rng.integers(0, kinds.size, width * height * records_per_pixel)
    records = pack(kinds[chosen], rng.integers(0, limits[chosen]))
    offsets = np.arange(0, records.size + 1, records_per_pixel, dtype=np.int64)
    counters = np.zeros((width * height, len(COUNTER_NAMES)), dtype=np.int64)
    return AccessTrace(offsets, records, counters, width, height, {})


def test_colouring_conflicts_exactly_as_contiguous_and_random_does_not():
    """Page colouring keeps every set index of the 21164's levels, so hits and misses equal
    contiguous placement's; random colours add B-cache conflicts. Fails when colouring gives a
    page another colour than its virtual page's (e.g. ``(virtual // 2) % n_colours``)."""
    from coherence.cost import alpha8400

    counts = {"kd_node": 60000, "index_entry": 90000, "sphere": 20000, "material": 8, "light": 3}
    trace = _spread_trace(24, 20, counts, 300, seed=7)
    hierarchy = alpha21164()
    placed = get_layout("alpha1997").place(counts)
    distribution = get_mapping("S").build(trace.width, trace.height, 2)

    def hits_and_misses(layout):
        run = simulate_run(trace, distribution, hierarchy, layout, alpha8400()).processes
        return run[[c for c in run.columns if c.endswith(("_hits", "_misses"))]]

    base = hits_and_misses(placed)
    coloured = hits_and_misses(placed.with_pages(PagePlacement("colouring", PAGE, 1), hierarchy))
    assert base.equals(coloured)
    random = hits_and_misses(placed.with_pages(PagePlacement("random", PAGE, 1), hierarchy))
    assert (random["L3_misses"] > base["L3_misses"]).all()


def test_a_tlb_of_another_page_size_is_refused():
    _, placed = _placed(5)
    with pytest.raises(ValueError, match="needs a TLB of the same page size"):
        placed.with_pages(PagePlacement("random", 16384, 0), alpha21164_with_dtb())


@pytest.mark.parametrize("bad", [{"policy": "buddy"}, {"page_size": 1000}, {"seed": -1}])
def test_bad_configuration_names_the_field(bad):
    with pytest.raises(ValueError, match="PagePlacement"):
        PagePlacement(**bad)


def test_a_report_places_pages_as_asked_and_records_it(tmp_path):
    """``report --page-placement random`` reaches the machine and its parameters; fails when
    Experiment.machine() leaves page_placement out (the report then records contiguous)."""
    import json

    from analyses.cli import main

    out = tmp_path / "out"
    assert main(["report", "tetra", "--size", "16", "--processes", "2", "--mappings", "S", "--layout", "alpha1997",
                 "--page-placement", "random", "--page-seed", "4", "--background-footprint", "65536",
                 "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    summary = json.loads((out / "summary.json").read_text())
    machine = summary["parameters"]["machine"]
    assert machine["page_placement"] == {"policy": "random", "page_size": PAGE, "seed": 4}
    assert machine["background_footprint"] == 65536


def _splitmix_output(value: int) -> int:
    """SplitMix64's output function in plain Python integers (Steele, Lea & Flood 2014)."""
    mask = (1 << 64) - 1
    value = ((value ^ (value >> 30)) * 0xBF58476D1CE4E5B9) & mask
    value = ((value ^ (value >> 27)) * 0x94D049BB133111EB) & mask
    return value ^ (value >> 31)


def test_a_background_stream_maps_as_by_hand_under_random_placement():
    """Page k of stream b gets frame ((b + 1) << 34 | k) << colour_bits | hashed colour. Fails when
    the hash ignores the process (``key`` without ``process << 34``: two users' streams would share
    their colour sequence)."""
    from coherence.page_placement import translate_stream

    pages = PagePlacement("random", PAGE, 6).background(512)
    first = (1 << 56) + (1 << 48) * 2 + 123 * 64
    for process in (0, 2):
        stream = np.arange(first, first + 3 * PAGE, 64, dtype=np.uint64)
        placed = stream.copy()
        translate_stream(placed, placed.size, process, first, pages)
        expected = []
        for address in stream.tolist():
            k = address // PAGE - first // PAGE
            colour = _splitmix_output(((6 << 40) + (process << 34) + k) & ((1 << 64) - 1)) & 511
            expected.append(((((process + 1) << 34 | k) << 9 | colour) << 13) | address % PAGE)
        np.testing.assert_array_equal(placed, np.array(expected, dtype=np.uint64))
    assert PagePlacement("colouring").background(512).colour_bits == -1


def test_other_users_pages_are_placed_only_by_random_placement():
    """With other users' slices in the run queue, colouring and bin hopping leave their streams
    contiguous, so our counts equal contiguous placement's wherever only the streams could differ;
    random placement scatters them. Fails when translate_stream is skipped in the schedule (the
    random run's counts then equal those with only the scene's pages placed)."""
    from dataclasses import replace

    from coherence.cost import alpha8400
    from coherence.simulation import Machine

    counts = {"kd_node": 4000, "index_entry": 6000, "sphere": 2000, "material": 8, "light": 3}
    trace = _spread_trace(16, 16, counts, 200, seed=11)
    hierarchy = alpha21164()
    placed = get_layout("alpha1997").place(counts)
    distribution = get_mapping("S").build(trace.width, trace.height, 2)
    busy = Machine(n_cpus=2, background_load=2, quantum_cycles=2e5, background_footprint=1 << 19)

    def l3_misses(machine, layout=placed):
        return simulate_run(trace, distribution, hierarchy, layout, alpha8400(), machine).processes["L3_misses"]

    contiguous = l3_misses(busy)
    colouring = l3_misses(replace(busy, page_placement=PagePlacement("colouring")))
    assert contiguous.equals(colouring)
    random = PagePlacement("random", PAGE, 2)
    both = l3_misses(replace(busy, page_placement=random))
    scene_only = l3_misses(busy, placed.with_pages(random, hierarchy))  # the machine leaves streams as they are
    assert not both.equals(scene_only)
