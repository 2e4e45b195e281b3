"""docs/outputs.md names exactly the columns that report, paper and whatif write at 32x32."""
from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from analyses.cli import main
from tracer.trace.records import COUNTER_NAMES

PAGE = Path(__file__).resolve().parents[1] / "docs" / "outputs.md"
ELEMENT_KINDS = ("sphere", "triangle", "polygon", "patch", "cone")


def _tables(text: str) -> dict[str, list[tuple[str, str, bool]]]:
    """Heading -> (first cell, second cell, optional) of each table row below it, backticks removed;
    a row is optional when it says *when ...*."""
    tables, heading = {}, None
    for line in text.splitlines():
        if line.startswith("#"):
            heading = line.lstrip("#").strip().strip("`")
        elif line.startswith("| `") and heading:
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            tables.setdefault(heading, []).append((cells[0].strip("`"), cells[1].strip("`"), "*when" in line))
    return tables


def _documented(rows, optional_too=True) -> set[str]:
    return {name for name, _, optional in rows if optional_too or not optional}


def _family(name: str, levels=("L1", "L2", "L3"), mappings=()) -> str:
    """A column's name with its level, mapping or line size replaced by the family's placeholder."""
    for level in levels:
        if name.startswith(level + "_"):
            return "<level>" + name[len(level):]
    for mapping in mappings:
        if name.startswith(mapping + "_"):
            return "<mapping>" + name[len(mapping):]
    return re.sub(r"^miss_ratio_\d+B$", "miss_ratio_<line>B", name)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("outputs")
    cache = ["--cache", str(folder / "cache")]
    assert main(["report", "tetra", "--size", "32", "--out", str(folder / "report"), *cache]) == 0
    assert main(["paper", "--size", "32", "--out", str(folder / "paper"), *cache]) == 0
    assert main(["whatif", "latency", "--size", "32", "--jobs", "1", "--out", str(folder / "whatif"), *cache]) == 0
    return folder


def _check(written: set[str], rows, what: str) -> None:
    documented = _documented(rows)
    always = _documented(rows, optional_too=False)
    assert not written - documented, f"{what}: written but not in docs/outputs.md: {sorted(written - documented)}"
    assert not always - written, f"{what}: in docs/outputs.md but not written: {sorted(always - written)}"


def test_the_run_table_and_paper_files_are_documented(outputs):
    """Fails when a writer adds, renames or drops a column the page does not follow (e.g.
    scenes.csv's ``our_rays`` renamed ``rays``)."""
    tables = _tables(PAGE.read_text(encoding="utf-8"))
    runs = pd.read_csv(outputs / "paper" / "paper.csv")
    mappings = tuple(runs["mapping"].unique())
    _check({_family(c) for c in runs.columns}, tables["The run table"], "paper.csv")
    scenes = pd.read_csv(outputs / "paper" / "scenes.csv")
    _check(set(scenes.columns), tables["scenes.csv"], "scenes.csv")
    predictions = pd.read_csv(outputs / "paper" / "predictions.csv")
    _check({_family(c, mappings=mappings) for c in predictions.columns}, tables["predictions.csv"],
           "predictions.csv")


def test_the_report_sections_and_metrics_are_documented(outputs):
    """Fails when the report writes a section or metric the page does not list (e.g. a new
    ``cache`` metric ``policy``), or stops writing one it lists."""
    tables = _tables(PAGE.read_text(encoding="utf-8"))
    results = pd.read_csv(outputs / "report" / "results.csv")
    _check(set(results.columns), tables["results.csv"][:6], "results.csv columns")
    run_columns = _documented(tables["The run table"]) - {"scene", "mapping", "n_processes"}
    documented = {}
    for section, metric, _ in tables["results.csv"][6:]:
        documented.setdefault(section, set()).update(run_columns if metric.startswith("(") else {metric})
    written = {}
    for row in results[["section", "metric"]].drop_duplicates().itertuples():
        metric = row.metric
        if row.section == "scene" and metric in COUNTER_NAMES:
            metric = "<counter>"
        elif row.section == "scene" and metric in ELEMENT_KINDS:
            metric = "<element kind>"
        elif row.section != "scene_bytes":
            metric = _family(metric)
        written.setdefault(row.section, set()).add(metric)
    path_traced_only = {"ray_orders"}  # the report of a Whitted trace (tetra here) has no ray segments
    assert set(written) == set(documented) - path_traced_only
    for section in written:
        optional = {name for name, _, is_optional in tables["The run table"] if is_optional}
        assert written[section] <= documented[section], (section, written[section] - documented[section])
        assert documented[section] - optional <= written[section], (section, documented[section] - written[section])


def test_the_whatif_table_is_documented(outputs):
    """Fails when whatif's table gains a column the page does not name."""
    tables = _tables(PAGE.read_text(encoding="utf-8"))
    table = pd.read_csv(outputs / "whatif" / "whatif-latency.csv")
    grid = {"memory_latency", "compute_scale"}
    _check({"<grid parameter>" if c in grid else c for c in table.columns}, tables["whatif-NAME.csv"],
           "whatif-latency.csv")
    documented = _documented(tables["The run table"])
    assert {_family(m) for m in table["metric"].unique()} <= documented
