"""Collect the benchmarks' figures into ``docs/results/performance.json`` and render its page.

Every script in ``benchmarks/`` prints its figures as one JSON object on its
last line of output. ``python docs/results/performance.py collect [NAME ...]``
runs the chosen benchmarks (default :data:`BENCHMARKS`) and stores, per
benchmark, the exact command, its wall time and that JSON, together with the
commit and the machine. ``python docs/results/performance.py page`` (also
run by ``generate.py pages``) writes ``docs/results/performance.md`` from it.
Figures depend on the machine and its load: the page says which machine and
when; the history of speed is kept in CHANGELOG.md, not here.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import subprocess
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))
from generate import git_commit, machine  # noqa: E402
from pages import STAMP_PREFIX, markdown_table  # noqa: E402

#: Benchmark name -> its arguments (small enough to run on a busy 2-core machine).
BENCHMARKS = {
    "bench_cachesim": ["--accesses", "2000000", "--repeats", "2"],
    "bench_kdtree": ["--quick", "--repeats", "2"],
    "bench_tracer": ["--size", "128"],
}


def last_json_line(output: str) -> dict:
    """The JSON object on the last non-empty line of a benchmark's output.

    Raises
    ------
    ValueError
        When that line is not a JSON object.
    """
    lines = [line for line in output.splitlines() if line.strip()]
    if not lines:
        raise ValueError("the benchmark printed nothing")
    figures = json.loads(lines[-1])
    if not isinstance(figures, dict):
        raise ValueError(f"the last line is JSON but not an object: {lines[-1][:80]}")
    return figures


def collect(names, path: Path) -> dict:
    """Run the benchmarks ``names`` and write what they printed to ``path``."""
    record = {"commit": git_commit(), "machine": machine(),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "benchmarks": {}}
    for name in names:
        command = ["python", f"benchmarks/{name}.py", *BENCHMARKS[name]]
        started = time.perf_counter()
        done = subprocess.run([sys.executable, *command[1:]], cwd=ROOT, capture_output=True, text=True,
                              check=True)
        record["benchmarks"][name] = {"command": " ".join(command),
                                      "seconds": round(time.perf_counter() - started, 1),
                                      "figures": last_json_line(done.stdout)}
        print(f"{name}: {record['benchmarks'][name]['seconds']} s", flush=True)
    path.write_text(json.dumps(record, indent=1, default=float) + "\n", encoding="utf-8")
    return record


def flatten(figures: dict, prefix: str = ""):
    """Split a benchmark's JSON into (figure, value) pairs and tables.

    Nested objects become dotted names (``balls_one_core.rays``); a list of
    objects becomes a table of its own; other lists and nulls are left out.

    Returns
    -------
    scalars : list of (str, object)
    tables : list of (str, list of dict)
    """
    scalars, tables = [], []
    for key, value in figures.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            inner_scalars, inner_tables = flatten(value, f"{name}.")
            scalars += inner_scalars
            tables += inner_tables
        elif isinstance(value, list) and value and all(isinstance(row, dict) for row in value):
            tables.append((name, value))
        elif isinstance(value, (bool, int, float, str)):
            scalars.append((name, value))
    return scalars, tables


def write_performance_page(pages: Path = HERE) -> Path:
    """Write ``performance.md`` from ``performance.json``: one stamped table per benchmark."""
    record = json.loads((pages / "performance.json").read_text(encoding="utf-8"))
    blocks = ["# Performance",
              "Figures the benchmark scripts printed as their last line of JSON, collected by "
              "`python docs/results/performance.py collect` on one machine at one commit. "
              f"Machine: {record['machine']}; date: {record['date']}. The machine may have been "
              "shared with other work: compare figures of one run with each other, not across pages."]
    for name, entry in record["benchmarks"].items():
        stamp = (f"{STAMP_PREFIX} `{entry['command']}` at commit `{record['commit']}` "
                 f"({record['date']}, {entry['seconds']:.0f} s on {record['machine']}).")
        scalars, row_lists = flatten(entry["figures"])
        blocks.append(f"## `{name}`")
        blocks += [markdown_table(pd.DataFrame(scalars, columns=["figure", "value"]), digits=4), stamp]
        for key, rows in row_lists:
            blocks += [f"`{key}`:", markdown_table(pd.DataFrame(rows), digits=4), stamp]
    path = pages / "performance.md"
    path.write_text("\n\n".join(blocks) + "\n", encoding="utf-8")
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="step", required=True)
    run = sub.add_parser("collect")
    run.add_argument("names", nargs="*", default=list(BENCHMARKS), metavar="NAME")
    sub.add_parser("page")
    args = parser.parse_args(argv)
    if args.step == "collect":
        collect(args.names or list(BENCHMARKS), HERE / "performance.json")
    write_performance_page(HERE)


if __name__ == "__main__":
    main()
