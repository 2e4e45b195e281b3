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


def test_readme_is_short_and_names_every_output_file():
    """A newcomer's README: at most 150 lines, and its outputs table names every file the commands
    write, from the modules that write them. Fails when a writer gains a file the README does not
    name (e.g. REPORT_FILES["page"] = "report.html")."""
    from analyses.paper_output import CROSSOVER_FILES, PAPER_FILES
    from analyses.report import MISS_MAP_FILES, REPORT_FILES
    from analyses.robustness_output import ROBUSTNESS_FILES
    from analyses.whatif_output import WHATIF_FILES
    from tracer.trace.check import ARRAY_FILES, META_FILE

    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    names = [*REPORT_FILES.values(), *MISS_MAP_FILES, *PAPER_FILES.values(), *CROSSOVER_FILES.values(),
             *ROBUSTNESS_FILES.values(),
             *(pattern.format(name="NAME") for pattern in WHATIF_FILES.values()), *ARRAY_FILES.values(), META_FILE]
    missing = [name for name in names if f"`{name}`" not in text]
    assert not missing, f"README's outputs table does not name {missing}"
