"""Every table and figure of the generated results pages names its command and commit.

The pages under ``docs/results/`` are written by ``docs/results/generate.py``
and committed; a table or figure without the line saying which command at
which commit produced it could not be regenerated or dated.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
STAMP = re.compile(r"^\*\*Produced by\*\* `(?:coherence|python) [^`]+` at commit `[0-9a-f]{7,40}(\+dirty)?`")


#: A page that is one run's section names the run once at its top (the faithfulness page).
PAGE_STAMP = re.compile(r"\A# [^\n]+\n(?:[^\n]*\n){0,4}- Command: `coherence [^`]+`\n(?:- [^\n]*\n)?- Commit: `[0-9a-f]{7,40}`")


def unstamped(text: str) -> tuple[int, list[int]]:
    """The number of tables and figures in a page, and the lines of those without a stamp.

    A table is a run of lines starting with ``|``; a figure a line starting
    with ``![``. Each must be followed, after blank lines, by a stamp line.
    """
    lines = text.split("\n")
    items, missing = 0, []
    index = 0
    while index < len(lines):
        line = lines[index]
        if line.startswith("|") or line.startswith("!["):
            start = index
            if line.startswith("|"):
                while index + 1 < len(lines) and lines[index + 1].startswith("|"):
                    index += 1
            items += 1
            following = index + 1
            while following < len(lines) and not lines[following].strip():
                following += 1
            if following >= len(lines) or not STAMP.match(lines[following]):
                missing.append(start + 1)
        index += 1
    return items, missing


def test_unstamped_finds_a_removed_stamp():
    """A table and a figure, one stamp removed: found (fails if unstamped looked only at figures)."""
    stamp = "**Produced by** `coherence paper --size 32` at commit `0123abc` (today)."
    page = f"# t\n\n| a |\n|---|\n| 1 |\n\n{stamp}\n\n![f](figures/f.png)\n\ntext\n"
    assert unstamped(page) == (2, [9])
    assert unstamped(page.replace("text", stamp)) == (2, [])


PAGES = sorted(path for path in RESULTS.glob("*.md") if path.name != "index.md")


@pytest.mark.parametrize("page", PAGES, ids=lambda path: path.name)
def test_results_page_stamped(page):
    """Every table and figure of each committed results page is stamped.

    Mutation: delete one ``**Produced by**`` line from docs/results/paper.md
    (or drop ``stamp_line`` from ``_Page.table`` in docs/results/pages.py and
    regenerate): this test fails naming the line.
    """
    text = page.read_text(encoding="utf-8")
    if PAGE_STAMP.search(text):  # one run's section (analyses.faithfulness): command and commit head it
        return
    items, missing = unstamped(text)
    assert items, f"{page.name} has no table or figure"
    assert not missing, f"{page.name}: tables or figures without a command-and-commit stamp at lines {missing}"


def test_page_stamp_needs_command_and_commit():
    """A page-level stamp counts only with both lines (fails if PAGE_STAMP accepted a command alone)."""
    head = "# F\n\nintro\n\n- Command: `coherence robustness --size 64`\n- Seed: 0\n"
    assert PAGE_STAMP.search(head + "- Commit: `26d58b5`\n")
    assert not PAGE_STAMP.search(head + "\n| a |\n")


def test_results_pages_exist():
    """The results pages are committed (fails if docs/results holds none)."""
    assert PAGES
