"""Real outputs of the command line, digested, against the committed reference.

The jobs of :mod:`output_digests` (every paper scene rendered at 64x64,
``simulate``, ``paper`` at 64x64, ``report balls`` at 128x128 and two
``whatif`` studies at 32x32) run in a scratch folder, and each output file's
digest must equal its line in ``tests/data/output_digests.txt``. This is the
proof every refactor claims: a change that moves one hit count, one float in
a CSV or one parameter in a JSON file fails here and names the file.

An intended change of outputs re-records the reference in the same commit
(``python tests/output_digests.py tests/data/output_digests.txt``) and says
why in a ``#`` line at the top of that file; JSON keys renamed on purpose are
listed in :data:`output_digests.RENAMED_KEYS`, so that their values are still
compared under their old names.
"""
from __future__ import annotations

from pathlib import Path

import output_digests

REFERENCE = Path(__file__).parent / "data" / "output_digests.txt"


def _read(path: Path) -> dict[str, str]:
    lines = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    return {name: value for value, name in lines}


def test_outputs_are_identical_to_the_reference(tmp_path):
    """Fails when any output byte changes: ``CostModel.node_visit``'s default 60 -> 61 changes
    nine outputs (report, simulate and whatif tables among them)."""
    out = tmp_path / "digests.txt"
    assert output_digests.main([str(out), "--work", str(tmp_path / "work")]) == 0
    expected, got = _read(REFERENCE), _read(out)
    missing = sorted(set(expected) - set(got))
    extra = sorted(set(got) - set(expected))
    changed = sorted(name for name in set(expected) & set(got) if expected[name] != got[name])
    assert not (missing or extra or changed), (
        f"outputs differ from {REFERENCE.name}: changed {changed}, missing {missing}, new {extra}; "
        "if intended, re-record the file and say why in its first line")
