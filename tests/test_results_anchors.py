"""The anchors page (docs/results/anchors.md): its table follows the data file, its measurements are replayed right.

``docs/results/anchors.toml`` holds the published findings and the rules that
decide them; ``docs/results/anchors.py`` measures them and writes the page,
storing what it measured in ``anchors.json`` beside it.
"""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def _generator():
    spec = importlib.util.spec_from_file_location("anchors_generator", RESULTS / "anchors.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


anchors = _generator()


def _verdict_table(text: str) -> list[dict]:
    """Rows of the first pipe table after '## Verdicts', as dicts by column name."""
    lines = text.split("## Verdicts", 1)[1].strip().split("\n")
    table = [line for line in lines[:next(i for i, line in enumerate(lines) if not line.startswith("|"))]]
    header = [cell.strip() for cell in table[0].strip("|").split("|")]
    return [dict(zip(header, (cell.strip() for cell in re.split(r"(?<!\\)\|", row.strip("|")))))
            for row in table[2:]]


def test_page_table_matches_the_data_file():
    """Each anchor of anchors.toml has one row, in order, with its published figure, citation, order and rule,
    and the verdict its stored measurement gives under that rule.

    Mutation: change one anchor's threshold in anchors.toml (or its citation) without regenerating the page:
    this test fails naming the anchor (checked).
    """
    run, data = anchors.load_anchors()
    record = json.loads((RESULTS / "anchors.json").read_text(encoding="utf-8"))[0]
    rows = _verdict_table((RESULTS / "anchors.md").read_text(encoding="utf-8"))
    assert [row["anchor"] for row in rows] == [anchor["id"] for anchor in data]
    for row, anchor in zip(rows, data):
        assert row["published"] == anchor["published"], anchor["id"]
        assert row["citation"] == anchor["citation"], anchor["id"]
        assert row["order"] == anchor["order"], anchor["id"]
        assert row["rule"] == f"{anchor['rule']} {anchor['threshold']:g}", anchor["id"]
        measured = record["anchors"].get(anchor["id"])
        expected = anchors.verdict(measured["values"], anchor["rule"], anchor["threshold"]) if measured \
            else anchors.NOT_MEASURED
        assert row["verdict"] == expected, anchor["id"]


def test_page_is_the_generators_output():
    """anchors.md is what page_text writes from the stored anchors.json (a list of runs) and the data file.

    Mutation: edit one measured digit in anchors.md: this test fails (checked).
    """
    record = json.loads((RESULTS / "anchors.json").read_text(encoding="utf-8"))
    assert (RESULTS / "anchors.md").read_text(encoding="utf-8") == anchors.page_text(record)


def test_every_anchor_cites_or_says_not_checked():
    """A citation names a part of the publication (abstract, section, page, table, figure) or says "not checked".

    Mutation: empty one citation in anchors.toml: fails (checked).
    """
    _, data = anchors.load_anchors()
    for anchor in data:
        assert re.search(r"abstract|section|p\. \d|table|figure|not checked", anchor["citation"]), anchor["id"]


@pytest.mark.parametrize("values, rule, threshold, expected", [
    ({"L1": 0.6, "L2": 0.5}, ">=", 0.5, anchors.CONFIRMED),
    ({"L1": 0.6, "L2": 0.49}, ">=", 0.5, anchors.NOT_CONFIRMED),
    ({"L2": 0.05}, "<=", 0.1, anchors.CONFIRMED),
    ({"L2": -0.2}, "<=", 0.1, anchors.CONFIRMED),
    ({"L2": 0.11}, "<=", 0.1, anchors.NOT_CONFIRMED),
    ({"L1": 0.9, "L2": None}, ">=", 0.5, anchors.NOT_MEASURED),
    ({}, ">=", 0.5, anchors.NOT_MEASURED),
])
def test_verdict_hand_cases(values, rule, threshold, expected):
    """Every listed level must pass; a missing value is not measured.

    Mutation: ``all`` -> ``any`` in verdict: the second case fails (checked).
    """
    assert anchors.verdict(values, rule, threshold) == expected


def test_load_anchors_names_the_bad_field(tmp_path):
    """A rule outside >=/<= is refused naming the file, the anchor and the field.

    Mutation: drop the rule check in load_anchors: fails (checked).
    """
    text = (RESULTS / "anchors.toml").read_text(encoding="utf-8").replace('rule = ">="', 'rule = ">"', 1)
    path = tmp_path / "anchors.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=r"anchors.toml: anchor 'bikker2012': rule must be"):
        anchors.load_anchors(path)


@pytest.fixture(scope="module")
def tiny():
    from cachesim.config import CacheLevel, Hierarchy
    from coherence.layout import get_layout
    from coherence.studies import place_layout
    from tracer.kd.tree import build_kdtree
    from tracer.rendering.pathtrace import path_trace
    from tracer.rendering.render import RenderOptions
    from tracer.scenes.catalog import load

    scene = load("balls")
    trace = path_trace(scene, build_kdtree(scene), RenderOptions(size=6, workload="pathtrace", spp=2, seed=3,
                                                                 max_depth=4)).trace
    hierarchy = Hierarchy((CacheLevel("L1", 1024, 32, 2), CacheLevel("L2", 4096, 64, 4)))
    return trace, place_layout(get_layout("malloc1997"), trace, scene), hierarchy


def test_misses_by_segment_against_a_segment_by_segment_replay(tiny):
    """Misses per segment equal replaying the segments one after another on one kept cache state and reading
    each call's misses (a small two-level machine, a layout whose records span lines).

    Mutation: ``served_by > level`` -> ``served_by >= level`` in misses_by_segment, or drop the ``+ 1`` in
    line_counts: fails (both checked).
    """
    from cachesim import CacheState, simulate

    trace, placed, hierarchy = tiny
    fast = anchors.misses_by_segment(trace, placed, hierarchy)
    state = CacheState(hierarchy)
    line_size = min(level.line_size for level in hierarchy.levels)
    slow = []
    for first, stop in trace.segments.ints[:, 4:6]:
        addresses = placed.addresses(np.asarray(trace.records[first:stop]), line_size)
        slow.append(np.asarray(simulate(addresses, state).misses, dtype=np.int64))
    assert fast.shape == (trace.segments.n_segments, 2)
    assert fast.sum() > 0
    np.testing.assert_array_equal(fast, np.array(slow))


def test_depth_first_order_replays_the_traced_order(tiny):
    """The registry's depth-first order, replayed through order_misses, misses exactly what misses_by_segment
    counts over all segments (one replay of the trace as traced): the two paths of the generator agree.

    Mutation: replay ``rows[::-1]`` in Workload.order_misses: fails (checked).
    """
    trace, placed, hierarchy = tiny
    work = anchors.Workload(None, trace, placed, hierarchy)
    rows = np.arange(trace.segments.n_segments, dtype=np.int64)
    np.testing.assert_array_equal(work.order_misses("depth-first", rows),
                                  anchors.misses_by_segment(trace, placed, hierarchy).sum(axis=0))


def test_pixel_rows_keep_each_pixels_rays_in_order(tiny):
    """Pixels in a shuffled order: every segment row once, pixels in the order asked, each pixel's rows as
    traced (what submission_change feeds the order). Compared with a slow per-pixel filter.

    Mutation: ``side="right"`` -> ``side="left"`` for ``stops`` in pixel_rows: fails (checked).
    """
    trace, placed, hierarchy = tiny
    work = anchors.Workload(None, trace, placed, hierarchy)
    order = np.random.default_rng(1).permutation(trace.n_pixels)
    pixels = trace.segments.ints[:, 0]
    expected = np.concatenate([np.flatnonzero(pixels == p) for p in order])
    np.testing.assert_array_equal(work.pixel_rows(order), expected)
