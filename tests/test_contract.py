"""Two rules of the library code, checked on every run.

- No function outside a compiled kernel takes more than ten parameters
  (``self`` and ``cls`` not counted): related choices travel as one object.
- No comment or string points outside the repository (a design-notes file
  nobody has, "issue 12", a section sign): say the fact in place or point
  into ``docs/`` (``docs/design.md`` holds the design).

Library code is every package at the repository's root (a folder with an
``__init__.py``), tests and benchmarks aside.
"""
from __future__ import annotations

import ast
import functools
import io
import re
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_PARAMETERS = 10

# "DESIGN.md", "issue 12", "issues 12 and 13", "issue #12", "§4"
_OUTSIDE = re.compile(r"DESIGN\.md|\b[Ii]ssues?\s+#?\d+|§")
# "docs/memory_image.md" or "docs/design.md, "Layers"" (a page and one of its headings)
_INTO_DOCS = re.compile(r"\bdocs/([\w./-]*\w)(?:, \"([^\"]+)\")?")


def _library_files(root: Path = ROOT) -> list[Path]:
    packages = [path.parent for path in root.glob("*/__init__.py")
                if path.parent.name not in ("tests", "benchmarks", "docs", "build", "dist")]
    return sorted(file for package in packages for file in package.rglob("*.py"))


def _is_kernel(node: ast.FunctionDef) -> bool:
    return any("jit" in ast.unparse(decorator) for decorator in node.decorator_list)


@functools.cache
def _texts(root: Path) -> tuple[tuple[str, int, str], ...]:
    """``(path, first line, text)`` of every comment and string of the library code."""
    found = []
    for path in _library_files(root):
        source = path.read_text(encoding="utf-8")
        for token in tokenize.generate_tokens(io.StringIO(source).readline):
            if token.type in (tokenize.COMMENT, tokenize.STRING):
                found.append((path.relative_to(root).as_posix(), token.start[0], token.string))
    return tuple(found)


def over_the_limit(root: Path = ROOT) -> list[str]:
    """``"path:function takes N parameters"`` for every non-kernel function of more than ten."""
    found = []
    for path in _library_files(root):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_kernel(node):
                arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                count = len([a for a in arguments if a.arg not in ("self", "cls")])
                if count > MAX_PARAMETERS:
                    found.append(f"{path.relative_to(root).as_posix()}:{node.name} takes {count} parameters")
    return found


def pointers_outside(root: Path = ROOT) -> list[str]:
    """``"path:line: text"`` for every comment or string naming something outside the repository."""
    found = []
    for path, first_line, text in _texts(root):
        for match in _OUTSIDE.finditer(text):
            line = first_line + text.count("\n", 0, match.start())
            found.append(f"{path}:{line}: {match.group(0)!r}")
    return found


def unresolved_pointers(root: Path = ROOT) -> list[str]:
    """``"path: docs/page"`` (or ``docs/page, "heading"``) for every pointer into
    docs/ whose page, or whose heading on that page, does not exist."""
    found = []
    for path, _, token in _texts(root):
        text = " ".join(token.replace("#", " ").split())  # a pointer may wrap onto the next line
        for match in _INTO_DOCS.finditer(text):
            page = root / "docs" / match.group(1)
            headings = ()
            if page.is_file() and page.suffix == ".md":
                headings = {" ".join(line.lstrip("#").split()) for line in
                            page.read_text(encoding="utf-8").splitlines() if line.startswith("#")}
            if not page.is_file() or (match.group(2) is not None and match.group(2) not in headings):
                found.append(f"{path}: {match.group(0)}")
    return found


def test_no_function_takes_more_than_ten_parameters():
    """Fails if ``coherence.metrics.add_speedups`` gets ten more keyword
    parameters (``*, a=0, b=0, ...``), or any other non-kernel function an eleventh."""
    offending = over_the_limit()
    assert not offending, "pass a bundle instead of:\n" + "\n".join(offending)


def test_no_comment_points_outside_the_repository():
    """Fails if a comment ``# see DESIGN.md`` (or ``# issue 12``) is added to
    ``coherence/metrics.py``."""
    offending = pointers_outside()
    assert not offending, "say it in place or point into docs/:\n" + "\n".join(offending)


def test_pointers_into_docs_resolve():
    """Every page of docs/ that library code names exists, with the heading it
    quotes. Fails if the heading "Layers" of docs/design.md is renamed."""
    assert not unresolved_pointers(), "\n".join(unresolved_pointers())


def test_the_checks_see_what_they_look_for(tmp_path):
    """The checks find a hand-made offender of each rule and spare a kernel.
    Fails if ``_is_kernel`` returns True for every function."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "m.py").write_text(
        "from numba import njit\n\n\n"
        "def wide(a, b, c, d, e, f, g, h, i, j, k):\n    '''See issue 7.'''\n\n\n"
        "class C:\n    def method(self, a, b, c, d, e, f, g, h, i, j):  # as DESIGN.md says\n        pass\n\n\n"
        "@njit(cache=True)\ndef _kernel(a, b, c, d, e, f, g, h, i, j, k, l):\n    return a\n")
    (package / "n.py").write_text('# docs/page.md, "Layers" and docs/page.md are here,\n'
                                  '# docs/page.md, "Floors" and docs/gone.md are not\n')
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("# Page\n\n## Layers\n")
    assert over_the_limit(tmp_path) == ["pkg/m.py:wide takes 11 parameters"]
    assert pointers_outside(tmp_path) == ["pkg/m.py:5: 'issue 7'", "pkg/m.py:9: 'DESIGN.md'"]
    assert unresolved_pointers(tmp_path) == ['pkg/n.py: docs/page.md, "Floors"', "pkg/n.py: docs/gone.md"]
