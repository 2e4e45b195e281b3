"""One home per fact: where a fact must also appear elsewhere (a help text, a
page of docs/), the copy is read from its home or checked against it here."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from tracer.scenes.study import STUDY_SCENES

ROOT = Path(__file__).resolve().parents[1]


def _help_text(*command: str) -> str:
    """``coherence COMMAND --help`` as printed, in a subprocess (the help is built when printed)."""
    return subprocess.run([sys.executable, "-m", "analyses", *command, "--help"], capture_output=True, text=True,
                          check=True, cwd=ROOT).stdout


def _help(*command: str) -> str:
    """The help with its line breaks and indents folded into single spaces."""
    return " ".join(_help_text(*command).split())


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


def _listed_outputs(text: str) -> list[str]:
    """File names an epilog's "Output folder" block lists, one at the start of each entry."""
    block = text.split("Output folder", 1)[1].split("\n\n", 1)[0]
    return re.findall(r"^  (\S+\.[a-z]+) ", block, flags=re.M)


def test_help_lists_the_files_the_writers_name():
    """``coherence report --help`` and ``coherence paper --help`` list exactly the
    files of ``REPORT_FILES`` (with ``MISS_MAP_FILES``) and ``PAPER_FILES`` (with
    ``TODAY_FILES``, written under --platform); paper's --crossover names ``CROSSOVER_FILES``. Fails if ``REPORT_FILES["summary"]``
    becomes ``"report.json"``."""
    from analyses.paper_output import CROSSOVER_FILES, PAPER_FILES
    from analyses.paper_today import TODAY_FILES
    from analyses.report import MISS_MAP_FILES, REPORT_FILES

    report, paper = _help_text("report"), _help_text("paper")
    assert sorted(_listed_outputs(report)) == sorted([*REPORT_FILES.values(), *MISS_MAP_FILES])
    assert sorted(_listed_outputs(paper)) == sorted([*PAPER_FILES.values(), *TODAY_FILES.values()])
    assert all(name in " ".join(paper.split()) for name in CROSSOVER_FILES.values())


def test_whatif_help_names_its_files():
    """``coherence whatif --help`` names each file of ``WHATIF_FILES`` (``<name>`` for
    the study's name) and the sidecar's suffix. Fails if ``WHATIF_FILES["figure"]``
    becomes ``"whatif-{name}.svg"``."""
    from analyses.whatif_output import WHATIF_FILES
    from coherence.provenance import META_SUFFIX

    text = _help("whatif")
    for pattern in WHATIF_FILES.values():
        assert pattern.format(name="<name>") in text
    assert f"with {META_SUFFIX}" in text


def test_a_saved_trace_holds_exactly_the_format_files(tmp_path):
    """A saved trace folder holds ``META_FILE``, ``META_CHECKSUM`` and ``ARRAY_FILES``,
    nothing else, and loads back. Fails if ``AccessTrace.save`` writes the counters
    to ``tmp / "counts.npy"``."""
    from trace_factory import random_trace
    from tracer.trace.access import AccessTrace
    from tracer.trace.check import ARRAY_FILES, META_CHECKSUM, META_FILE

    trace = random_trace(6, 4, seed=2)
    trace.save(tmp_path / "t")
    assert sorted(path.name for path in (tmp_path / "t").iterdir()) == sorted(
        [META_FILE, META_CHECKSUM, *ARRAY_FILES.values()])
    assert AccessTrace.load(tmp_path / "t").n_records == trace.n_records
