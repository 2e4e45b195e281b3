"""One home per fact: where a fact must also appear elsewhere (a help text, a
page of docs/), the copy is read from its home or checked against it here."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tracer.scenes.study import STUDY_SCENES

ROOT = Path(__file__).resolve().parents[1]


def _help(*command: str) -> str:
    """``coherence COMMAND --help`` as printed, in a subprocess (the help is built when printed)."""
    done = subprocess.run([sys.executable, "-m", "analyses", *command, "--help"], capture_output=True, text=True,
                          check=True, cwd=ROOT)
    return " ".join(done.stdout.split())


def test_paper_help_quotes_the_study_table():
    """``coherence paper --help`` names the fitting targets from ``tracer.scenes.study``'s
    table: every scene's sequential S time and the five scenes. Fails if
    ``HelpFormatter._format_text`` stops expanding the epilog's names (the
    help then prints ``%(study_times)s``)."""
    text = _help("paper")
    times = ", ".join(f"{scene.name.capitalize()} {scene.sequential_seconds} s" for scene in STUDY_SCENES.values())
    assert f"({times} at 512x512;" in text
    assert f"(default all five: {', '.join(STUDY_SCENES)})" in text
    assert "%(" not in text


def _size_text(record) -> str:
    """A RecordLayout as the memory-image page writes it: ``104 [8]`` or ``112 + 24 n [8]``."""
    per_vertex = f" + {record.per_vertex} n" if record.per_vertex else ""
    return f"{record.size}{per_vertex} [{record.align}]"


def test_memory_image_page_shows_the_layout_table():
    """docs/memory_image.md's table has one row per record kind whose
    ``compact`` and ``alpha1997`` sizes are the code's. Fails if the
    ``alpha1997`` sphere in ``PRESET_RECORDS`` becomes ``RecordLayout(96, 8)``."""
    from coherence.layout import get_layout
    from tracer.trace.records import RecordKind

    rows = {}
    for line in (ROOT / "docs" / "memory_image.md").read_text(encoding="utf-8").splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if line.startswith("| `") and len(cells) >= 3:
            rows[cells[0].strip("`")] = (cells[1].split(":")[0], cells[2].split(":")[0])
    kinds = [kind.name.lower() for kind in RecordKind]
    assert sorted(rows) == sorted(kinds)
    compact, alpha1997 = get_layout("compact"), get_layout("alpha1997")
    for kind in kinds:
        assert rows[kind] == (_size_text(compact.record(kind)), _size_text(alpha1997.record(kind))), kind
