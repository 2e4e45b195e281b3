"""The study's unknowns: docs/unknowns.md and coherence.unknowns agree, and every default lies in its range."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from coherence.layout import LAYOUTS
from coherence.page_placement import PAGE_PLACEMENTS
from coherence.unknowns import SOURCES, STUDY_TREE_RULE, TREE_VARIANTS, UNKNOWNS, Unknown, unknown

DOCS = Path(__file__).resolve().parents[1] / "docs"
HEADER = "| unknown | option | default | range | unit | distribution | source |"


def _cell(text: str) -> str:
    return text.strip().strip("`")


def _number(text: str) -> float:
    return float(text.replace(",", ""))


def _docs_rows() -> list:
    """The first table of docs/unknowns.md as dicts, parsed the slow obvious way."""
    lines = (DOCS / "unknowns.md").read_text(encoding="utf-8").splitlines()
    start = lines.index(HEADER)
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        name, option, default, span, unit, distribution, source = cells
        row = {"name": _cell(name), "option": _cell(option), "unit": unit, "distribution": distribution,
               "source": _cell(source)}
        row["default"] = None if default == "fitted" else (
            _cell(default) if default.startswith("`") else _number(default))
        if distribution == "categorical":
            row["choices"] = tuple(_cell(c) for c in span.split(","))
            row["low"] = row["high"] = None
        else:
            low, high = span.split(" to ")
            row["choices"] = ()
            row["low"], row["high"] = _number(low), _number(high)
        rows.append(row)
    return rows


def _module_row(entry: Unknown) -> dict:
    return {"name": entry.name, "option": entry.option, "unit": entry.unit, "distribution": entry.distribution,
            "source": entry.source, "default": entry.default, "choices": entry.choices, "low": entry.low,
            "high": entry.high}


def test_docs_table_matches_module_row_by_row():
    """Each row of the docs table equals the module's entry of the same position.

    Fails when a range is edited in one place only: checked by changing
    memory_latency's high in coherence/unknowns.py from 150.0 to 160.0.
    """
    docs = _docs_rows()
    assert [row["name"] for row in docs] == [u.name for u in UNKNOWNS]
    for row, entry in zip(docs, UNKNOWNS):
        assert row == _module_row(entry), entry.name


def test_every_default_lies_in_its_range():
    """Every default read from the model lies inside its documented range or choices.

    Fails when a default moves outside: checked by raising memory_latency's
    low to 81.0 in both coherence/unknowns.py and the docs table (the model's
    default stays 80).
    """
    outside = [u.name for u in UNKNOWNS if u.default is not None and not u.contains(u.default)]
    assert outside == []


def test_fitted_costs_have_no_default_and_span_at_most_four_times():
    """Only the fitted costs lack a default, and each cost prior spans at most 4x.

    Fails when a prior is widened: checked by setting cost_ray's high to
    301.0 (in both the module and the docs).
    """
    fitted = [u for u in UNKNOWNS if u.default is None]
    assert [u.name for u in fitted] == [u.name for u in UNKNOWNS if u.name.startswith("cost_")]
    assert len(fitted) == 5
    for entry in fitted:
        assert entry.high / entry.low <= 4.0, entry.name


def test_every_source_has_a_heading_in_the_docs():
    """Each source key used, and each key of SOURCES, has its own heading under "Sources".

    Fails when a citation is missing: checked by deleting the
    "### unix-quanta" heading.
    """
    text = (DOCS / "unknowns.md").read_text(encoding="utf-8")
    sources = text[text.index("\n## Sources\n"):]
    headings = {line[4:].strip() for line in sources.splitlines() if line.startswith("### ")}
    assert headings == set(SOURCES)
    assert {u.source for u in UNKNOWNS} <= headings


def test_choices_name_real_options():
    """Categorical choices are exactly the values the toolkit accepts.

    Fails when a choice is misspelt: checked by renaming "bin-hopping" to
    "binhopping" in the module and the docs.
    """
    assert set(unknown("page_placement").choices) == set(PAGE_PLACEMENTS)
    assert set(unknown("memory_image").choices) == set(LAYOUTS)


def test_tree_variants_come_from_the_tree_search_and_the_default_is_the_study_tree():
    """The default tree variant spells today's study-era rule; every variant is a row of the search table.

    Fails when the study tree changes without this entry: checked by
    changing ``STUDY_TREE``'s ``tree_depth`` from 16 to 17 in
    tracer/rendering/workload.py (the default then reads d17-..., and the
    first check fails).
    """
    assert unknown("tree_variant").default == STUDY_TREE_RULE == TREE_VARIANTS[0]
    with open(DOCS / "study_tree_search.csv", newline="", encoding="utf-8") as handle:
        ratios = {}
        for row in csv.DictReader(handle):
            if row["size"] == "32":
                ratios[(row["rule"], row["scene"])] = float(row["ratio"])
    chosen_tetra = ratios[(STUDY_TREE_RULE, "tetra")]
    for rule in TREE_VARIANTS:
        assert 0.75 <= ratios[(rule, "balls")] <= 1.25, rule
        assert 0.75 <= ratios[(rule, "shell")] <= 1.25, rule
        assert chosen_tetra <= ratios[(rule, "tetra")] <= 1.25, rule


@pytest.mark.parametrize("fields, word", [
    ({"distribution": "normal", "low": 1.0, "high": 2.0}, "distribution"),
    ({"distribution": "uniform", "low": 2.0, "high": 1.0}, "low"),
    ({"distribution": "log-uniform", "low": 0.0, "high": 1.0}, "low"),
    ({"distribution": "integer", "low": 0.5, "high": 2.0}, "whole"),
    ({"distribution": "categorical", "choices": ("a",)}, "choices"),
    ({"distribution": "categorical", "choices": ("a", "b"), "low": 1.0}, "choices"),
    ({"distribution": "uniform", "low": 1.0, "high": float("nan")}, "high"),
])
def test_bad_entries_are_refused_naming_the_field(fields, word):
    """A malformed entry raises ValueError naming the field.

    Fails when a check is dropped: checked by deleting the ``low < high``
    check in ``Unknown.__post_init__`` (the second case then passes silently).
    """
    with pytest.raises(ValueError, match=word):
        Unknown("x", "option", None, source=SOURCES[0], **fields)


def test_contains_on_hand_checked_cases():
    """``contains`` on bounds, outside values and integer ranges, checked by hand.

    Fails when the integer rule is dropped: checked by deleting the
    whole-number test in ``Unknown.contains`` (2.5 processes is then inside).
    """
    load = unknown("background_load")
    assert load.contains(0) and load.contains(8) and load.contains(3.0)
    assert not load.contains(2.5) and not load.contains(9) and not load.contains(-1)
    latency = unknown("memory_latency")
    assert latency.contains(51.0) and latency.contains(150.0) and not latency.contains(50.9)
    assert not latency.contains("80") and not latency.contains(True)
    placement = unknown("page_placement")
    assert placement.contains("random") and not placement.contains("first-fit")
