"""One home per fact: where a fact must also appear elsewhere (a help text, a
page of docs/), the copy is read from its home or checked against it here."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tracer.study import STUDY_SCENES

ROOT = Path(__file__).resolve().parents[1]


def _help(*command: str) -> str:
    """``coherence COMMAND --help`` as printed, in a subprocess (the help is built when printed)."""
    done = subprocess.run([sys.executable, "-m", "analyses", *command, "--help"], capture_output=True, text=True,
                          check=True, cwd=ROOT)
    return " ".join(done.stdout.split())


def test_paper_help_quotes_the_study_table():
    """``coherence paper --help`` names the fitting targets from ``tracer.study``'s
    table: every scene's sequential S time and the five scenes. Fails if
    ``HelpFormatter._format_text`` stops expanding the epilog's names (the
    help then prints ``%(study_times)s``)."""
    text = _help("paper")
    times = ", ".join(f"{scene.name.capitalize()} {scene.sequential_seconds} s" for scene in STUDY_SCENES.values())
    assert f"({times} at 512x512;" in text
    assert f"(default all five: {', '.join(STUDY_SCENES)})" in text
    assert "%(" not in text
