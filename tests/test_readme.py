"""The README's Python examples run as written (in a scratch folder)."""
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"


@pytest.mark.jit_only  # renders and simulates real scenes
def test_readme_python_blocks_run(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "the README should show the Python API"
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, str(README), "exec"), {})


def test_readme_names_the_two_setup_commands():
    text = README.read_text(encoding="utf-8")
    assert "python3.11 -m pip install . && coherence" in text
    assert "bash tests/run_tests.sh" in text
    assert "bash tests/run_tests.sh" in (README.parent / ".ci" / "run").read_text()
