"""The ray-order results page, ``docs/results/ray-orders.md``, and the JSON it is written from.

Two steps, as the other results pages:

* :func:`collect` reads the outputs of the ray-order jobs of ``generate.py``
  (:data:`REPORT_JOBS`: ``coherence report --workload pathtrace``, whose
  ``summary.json`` holds the report's ray-order section; :data:`WHATIF_JOBS`:
  ``coherence whatif --orders``, whose ``whatif-orders.csv`` and its
  ``.meta.json`` hold the grid) with each job's ``stamp.json``, and stores
  what the page shows in ``docs/results/ray-orders.json``;
* :func:`page_text` writes the page from that JSON alone, every table
  followed by the stamp line naming its command and commit.

``python docs/results/ray_orders_page.py --work DIR`` does both for the jobs
found in ``DIR`` (jobs not found keep their stored entry);
``generate.py pages`` does the same. The explanations of the orders live in
``docs/ray_orders.md``; this page holds their numbers.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from pages import markdown_table, stamp_line  # noqa: E402

#: Jobs of ``generate.py`` whose report's ray-order section the page shows, in the page's order.
REPORT_JOBS = ("orders-report", "orders-report-today")
#: Jobs of ``generate.py`` running ``coherence whatif --orders``, in the page's order.
WHATIF_JOBS = ("orders-whatif-balls", "orders-whatif-tetra", "orders-whatif-tetra-l3")
#: The stored record the page is written from.
RECORD_FILE = "ray-orders.json"
PAGE_FILE = "ray-orders.md"

#: The report section's columns the page keeps (besides ``<level>_misses_per_ray``), and their headers.
REPORT_COLUMNS = {"user_seconds_max": "seconds", "reordering_gain": "gain", "reordering_overhead": "overhead",
                  "ray_state_records": "ray-state records", "queue_records": "queue records",
                  "sort_cycles": "sort cycles"}


def _stamp(folder: Path) -> dict:
    return json.loads((folder / "stamp.json").read_text(encoding="utf-8"))


def report_entry(folder: Path) -> dict:
    """One report job's entry: its stamp, what it ran on, and its ray-order section's rows.

    Raises
    ------
    ValueError
        When the report has no ray-order section (a trace without segments).
    """
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    if "ray_orders" not in summary:
        raise ValueError(f"{folder / 'summary.json'}: no ray_orders section (not a path-traced report?)")
    parameters = summary["parameters"]
    platform = parameters.get("platform")
    rows = summary["ray_orders"]
    return {"stamp": _stamp(folder),
            "machine": platform["name"] if platform else f"{parameters['hierarchy']['name']} (the study's machine)",
            "scene": parameters["scene"], "size": parameters["size"], "spp": parameters["spp"],
            "mapping": rows[0]["mapping"], "n_processes": rows[0]["n_processes"],
            "levels": [level["name"] for level in parameters["hierarchy"]["levels"]], "rows": rows}


def whatif_entry(folder: Path) -> dict:
    """One ``whatif --orders`` job's entry: its stamp, base, grid and every row of its table."""
    from analyses.order_whatif import ORDER_WHATIF_FILE

    meta = json.loads((folder / f"{ORDER_WHATIF_FILE}.meta.json").read_text(encoding="utf-8"))["parameters"]
    base = meta["experiment"]
    table = pd.read_csv(folder / ORDER_WHATIF_FILE)
    return {"stamp": _stamp(folder), "grid": list(meta["grid"]),
            "base": {"scene": base["scene"], "size": base["size"], "spp": base["spp"],
                     "max_depth": base["max_depth"], "mappings": base["mappings"],
                     "n_processes": base["n_processes"], "hierarchy": base["hierarchy"]["name"]},
            "rows": json.loads(table.to_json(orient="records"))}


def collect(work: Path, stored: dict | None = None) -> dict:
    """The page's record: ``stored``'s entries, replaced by those of the jobs that ran in ``work``.

    Returns
    -------
    dict
        ``{"reports": {job: entry}, "whatifs": {job: entry}}`` (:func:`report_entry`, :func:`whatif_entry`).
    """
    record = {"reports": dict((stored or {}).get("reports", {})), "whatifs": dict((stored or {}).get("whatifs", {}))}
    for part, jobs, entry in (("reports", REPORT_JOBS, report_entry), ("whatifs", WHATIF_JOBS, whatif_entry)):
        for job in jobs:
            if (work / job / "stamp.json").exists():
                record[part][job] = entry(work / job)
    return record


def _fixed(frame: pd.DataFrame, columns, decimals: int) -> pd.DataFrame:
    """``frame`` with ``columns`` written as text at ``decimals`` decimals (a column of ratios reads evenly)."""
    frame = frame.copy()
    for column in columns:
        frame[column] = frame[column].map(lambda value: f"{value:.{decimals}f}")
    return frame


def _bytes(value) -> str:
    value = int(value)
    for unit, size in (("MB", 2 ** 20), ("KB", 2 ** 10)):
        if value >= size and value % size == 0:
            return f"{value // size} {unit}"
    return f"{value} B"


def report_table(entry: dict) -> pd.DataFrame:
    """The page's table of one report's section: one row per order."""
    rows = pd.DataFrame(entry["rows"])
    depth_first = float(rows.loc[rows["order"] == "depth-first", "user_seconds_max"].iloc[0])
    shown = rows[["order", *[f"{level}_misses_per_ray" for level in entry["levels"]], *REPORT_COLUMNS]].copy()
    shown.insert(len(entry["levels"]) + 2, "net speed-up", depth_first / rows["user_seconds_max"])
    shown = shown.rename(columns={**{f"{level}_misses_per_ray": f"{level} misses/ray" for level in entry["levels"]},
                                  **REPORT_COLUMNS})
    for column in ("ray-state records", "queue records"):
        shown[column] = shown[column].astype(int)
    shown = _fixed(shown, [f"{level} misses/ray" for level in entry["levels"]], 2)
    return _fixed(shown, ["net speed-up", "gain", "overhead"], 4)


def whatif_table(entry: dict, metric: str, decimals: int) -> pd.DataFrame:
    """One row per grid point, one column per ray order: ``metric`` of the order at the point, at ``decimals``."""
    rows = pd.DataFrame(entry["rows"])
    grid = entry["grid"]
    wide = rows.pivot_table(index=grid + ["mapping"], columns="order", values=metric, sort=False).reset_index()
    wide.columns.name = None
    for key in grid:
        if key.endswith(".size"):
            wide[key] = wide[key].map(_bytes)
    return _fixed(wide, [column for column in wide.columns if column not in grid + ["mapping"]], decimals)


def _range(values: pd.Series) -> str:
    return f"{values.min():.3f}-{values.max():.3f}"


def whatif_ranges(entry: dict) -> pd.DataFrame:
    """Per grid point, the range over the reordering orders of their gain and overhead."""
    rows = pd.DataFrame(entry["rows"])
    rows = rows[rows["order"] != "depth-first"]
    grid = entry["grid"] + ["mapping"]
    ranges = rows.groupby(grid, sort=False).agg(gain=("reordering_gain", _range),
                                                 overhead=("reordering_overhead", _range)).reset_index()
    for key in entry["grid"]:
        if key.endswith(".size"):
            ranges[key] = ranges[key].map(_bytes)
    return ranges


def _paying(entry: dict) -> str:
    """The sentence saying at which points an order's net speed-up exceeds 1."""
    rows = pd.DataFrame(entry["rows"])
    above = rows[(rows["order"] != "depth-first") & (rows["net_speedup"] > 1)]
    points = len(rows.groupby(entry["grid"], sort=False))
    if above.empty:
        best = rows[rows["order"] != "depth-first"]["net_speedup"].max()
        return (f"No order pays for itself at any of the {points} points: the best net speed-up is "
                f"{best:.3f}.")
    found = [", ".join(f"{key} {row[key]}" for key in entry["grid"]) + f": {row['order']} ({row['net_speedup']:.3f})"
             for row in above.to_dict(orient="records")]
    return f"Orders that pay for themselves (net speed-up above 1), of {points} points: " + "; ".join(found) + "."


def _report_blocks(entry: dict) -> list[str]:
    rows = pd.DataFrame(entry["rows"])
    depth_first = float(rows.loc[rows["order"] == "depth-first", "user_seconds_max"].iloc[0])
    paying = rows.loc[(rows["order"] != "depth-first") & (rows["user_seconds_max"] < depth_first), "order"].tolist()
    return [f"### {entry['machine']}",
            f"{entry['scene']} at {entry['size']}×{entry['size']} pixels, {entry['spp']} samples per pixel, "
            f"mapping {entry['mapping']} at {entry['n_processes']} processes.",
            markdown_table(report_table(entry), digits=4), stamp_line(entry["stamp"]),
            "Orders faster than depth-first here: " + (", ".join(paying) if paying else "none") + "."]


def _whatif_blocks(entry: dict) -> list[str]:
    base = entry["base"]
    depth = "the scene's own" if base["max_depth"] is None else str(base["max_depth"])
    blocks = [f"### {base['scene']}: {', '.join(entry['grid'])}",
              f"Base: {base['scene']} at {base['size']}×{base['size']} pixels, spp {base['spp']}, bounce limit "
              f"{depth}, mapping {', '.join(base['mappings'])} at {', '.join(map(str, base['n_processes']))} "
              f"processes, caches `{base['hierarchy']}`; the grid's columns override it.",
              "Net speed-up of each order (the depth-first order's slowest-process time over the order's):",
              markdown_table(whatif_table(entry, "net_speedup", 3).drop(columns="depth-first")),
              stamp_line(entry["stamp"]),
              "The orders' reordering gain and overhead (lowest-highest over the orders):",
              markdown_table(whatif_ranges(entry)), stamp_line(entry["stamp"])]
    last = [key for key in entry["rows"][0] if key.endswith("_misses_per_ray")][-1]
    blocks += [f"{last.removesuffix('_misses_per_ray')} misses per ray, every order:",
               markdown_table(whatif_table(entry, last, 2)), stamp_line(entry["stamp"]), _paying(entry)]
    return blocks


def page_text(record: dict) -> str:
    """``ray-orders.md`` written from ``record`` (:func:`collect`) alone."""
    blocks = ["# Ray orders: where reordering pays for itself",
              "The numbers behind [the ray orders page](../ray_orders.md), which explains each order and its "
              "costs. Every table is generated from one run's output, named under it with its commit. "
              "`gain` is the reordering gain (the depth-first order's work over the order's without its own "
              "buffer, queue and sorting costs), `overhead` what those costs leave of it, and the net "
              "speed-up the depth-first order's slowest-process time over the order's: above 1, the order "
              "pays for itself."]
    if record["reports"]:
        blocks += ["## The report's ray-order section",
                   "`coherence report --workload pathtrace`: every registered order at the report's verdict "
                   "process count, for the mapping that loses most to coherence there; misses per ray by cache "
                   "level, the modelled slowest-process seconds, and the orders' own records."]
        for job in REPORT_JOBS:
            if job in record["reports"]:
                blocks += _report_blocks(record["reports"][job])
    if record["whatifs"]:
        blocks += ["## Over scene size, samples and cache size (`coherence whatif --orders`)",
                   "Each grid point is a path-traced trace of its own, replayed under every order. The "
                   "tetra scene at `scene_size` n has 4^n triangles (10: the million-triangle scene)."]
        for job in WHATIF_JOBS:
            if job in record["whatifs"]:
                blocks += _whatif_blocks(record["whatifs"][job])
    return "\n\n".join(blocks) + "\n"


def write_ray_orders_page(work: Path | None, pages: Path = HERE) -> str | None:
    """Update ``ray-orders.json`` from the jobs in ``work`` (if given) and write ``ray-orders.md`` from it.

    Returns
    -------
    str or None
        ``"ray-orders"``, or None when no record exists and no job ran.
    """
    path = pages / RECORD_FILE
    stored = json.loads(path.read_text(encoding="utf-8")) if path.exists() else None
    if work is not None and any((work / job / "stamp.json").exists() for job in REPORT_JOBS + WHATIF_JOBS):
        stored = collect(work, stored)
        temporary = path.with_suffix(".json.tmp")
        temporary.write_text(json.dumps(stored, indent=1) + "\n", encoding="utf-8")
        temporary.replace(path)
    if stored is None:
        return None
    page = pages / PAGE_FILE
    temporary = page.with_suffix(".md.tmp")
    temporary.write_text(page_text(stored), encoding="utf-8")
    temporary.replace(page)
    return "ray-orders"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, help="the folder of generate.py run (default: rewrite from the JSON)")
    args = parser.parse_args(argv)
    print(write_ray_orders_page(args.work) or "no ray-order jobs or record found")


if __name__ == "__main__":
    main()
