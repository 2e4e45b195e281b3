"""The ray-order results page (docs/results/ray-orders.md) shows what its stored JSON holds.

``docs/results/ray_orders_page.py`` stores what the ray-order jobs of
``generate.py`` produced in ``ray-orders.json`` and writes the page from it.
These tests read the page's tables back, by their headers, and compare each
cell with the JSON's row it names.
"""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


_SPEC = importlib.util.spec_from_file_location("ray_orders_page", RESULTS / "ray_orders_page.py")
page_module = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(page_module)
RECORD = json.loads((RESULTS / "ray-orders.json").read_text(encoding="utf-8"))
PAGE = (RESULTS / "ray-orders.md").read_text(encoding="utf-8")


def _tables_after(text: str, heading: str) -> list[list[dict]]:
    """The pipe tables between ``heading`` (a whole line) and the next heading, each as rows of dicts by header."""
    lines = text.split("\n")
    start = lines.index(heading) + 1
    stop = next((i for i in range(start, len(lines)) if lines[i].startswith("#")), len(lines))
    tables, index = [], start
    while index < stop:
        if lines[index].startswith("|"):
            block = []
            while index < stop and lines[index].startswith("|"):
                block.append([cell.strip() for cell in lines[index].strip().strip("|").split("|")])
                index += 1
            tables.append([dict(zip(block[0], row)) for row in block[2:]])
        index += 1
    return tables


def _close(cell: str, value: float, decimals: int) -> bool:
    return abs(float(cell) - value) <= 0.5 * 10 ** -decimals + 1e-12


def _bytes_value(cell: str) -> int:
    number, unit = cell.split()
    return int(number) * {"B": 1, "KB": 2 ** 10, "MB": 2 ** 20}[unit]


def test_page_is_written_from_its_json():
    """ray-orders.md is what page_text writes from the stored ray-orders.json.

    Mutation: edit one figure in ray-orders.md (or in ray-orders.json) without regenerating: fails (checked).
    """
    assert PAGE == page_module.page_text(RECORD)


def test_page_holds_every_job():
    """Both machines' report sections and the three whatif grids are on the page (fails if a job is left out
    of REPORT_JOBS or WHATIF_JOBS, checked with ``orders-whatif-tetra-l3`` removed)."""
    assert set(RECORD["reports"]) == set(page_module.REPORT_JOBS) == {"orders-report", "orders-report-today"}
    assert set(RECORD["whatifs"]) == set(page_module.WHATIF_JOBS)
    assert any("(the study's machine)" in entry["machine"] for entry in RECORD["reports"].values())
    assert "zen4-7950x" in [entry["machine"] for entry in RECORD["reports"].values()]
    assert 10 in [row["scene_size"] for entry in RECORD["whatifs"].values() for row in entry["rows"]
                  if "scene_size" in row]  # the million-triangle tetra


@pytest.mark.parametrize("job", ["orders-report", "orders-report-today"])
def test_report_table_cells_are_the_json_rows(job):
    """Each row of a machine's section table shows its order's JSON row: misses per ray by level, seconds
    (slowest process), gain, overhead and the orders' records; every order of the JSON appears once, with
    the treelet order's queue records above 0.

    Mutation: swap the headers of reordering_gain and reordering_overhead in REPORT_COLUMNS and regenerate
    the page: fails here while test_page_is_written_from_its_json still passes (checked).
    """
    entry = RECORD["reports"][job]
    (table,) = _tables_after(PAGE, f"### {entry['machine']}")
    by_order = {row["order"]: row for row in entry["rows"]}
    assert [row["order"] for row in table] == list(by_order)
    depth_first = by_order["depth-first"]["user_seconds_max"]
    for shown in table:
        row = by_order[shown["order"]]
        for level in entry["levels"]:
            assert _close(shown[f"{level} misses/ray"], row[f"{level}_misses_per_ray"], 2), (row["order"], level)
        assert float(shown["seconds"]) == pytest.approx(row["user_seconds_max"], rel=5e-4)
        assert _close(shown["net speed-up"], depth_first / row["user_seconds_max"], 4)
        assert _close(shown["gain"], row["reordering_gain"], 4), row["order"]
        assert _close(shown["overhead"], row["reordering_overhead"], 4), row["order"]
        assert int(shown["queue records"]) == row["queue_records"]
        assert int(shown["ray-state records"]) == row["ray_state_records"]
    assert by_order["treelet"]["queue_records"] > 0


@pytest.mark.parametrize("job", ["orders-whatif-balls", "orders-whatif-tetra", "orders-whatif-tetra-l3"])
def test_whatif_net_speedups_are_the_json_rows(job):
    """Each cell of a grid's net speed-up table is the JSON row of its grid point and order, every point once.

    Mutation: pivot ``reordering_gain`` instead of ``net_speedup`` into the first table and regenerate: fails
    (checked).
    """
    entry = RECORD["whatifs"][job]
    heading = f"### {entry['base']['scene']}: {', '.join(entry['grid'])}"
    net = _tables_after(PAGE, heading)[0]
    orders = sorted({row["order"] for row in entry["rows"]} - {"depth-first"})
    points = set()
    for shown in net:
        point = tuple(_bytes_value(shown[key]) if key.endswith(".size") else int(shown[key]) for key in entry["grid"])
        points.add(point)
        for order in orders:
            (row,) = [row for row in entry["rows"] if row["order"] == order and row["mapping"] == shown["mapping"]
                      and tuple(row[key] for key in entry["grid"]) == point]
            assert _close(shown[order], row["net_speedup"], 3), (point, order)
    assert len(points) == len(net) == len({tuple(row[key] for key in entry["grid"]) for row in entry["rows"]})


def test_every_table_names_its_job_command():
    """Each table's stamp line quotes the command its JSON entry's stamp recorded (fails if an entry's tables
    were stamped with another job's stamp, checked by giving every whatif table the first report's)."""
    entries = list(RECORD["reports"].values()) + list(RECORD["whatifs"].values())
    commands = re.findall(r"^\*\*Produced by\*\* `([^`]+)`", PAGE, flags=re.M)
    tables = {entry["stamp"]["command"]: 1 if entry in RECORD["reports"].values() else 3 for entry in entries}
    assert sorted(commands) == sorted(command for command, count in tables.items() for _ in range(count))
