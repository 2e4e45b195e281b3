"""Generate the results pages of the documentation from one command each.

Two steps, so that the long runs and the page writing can be repeated apart:

``python docs/results/generate.py run --work DIR [--size N] [--only NAME ...]``
    runs each job's ``coherence`` command offline into ``DIR/<job>/`` and
    writes ``DIR/<job>/stamp.json``: the exact command, the git commit it ran
    at (with ``+dirty`` when the work tree had uncommitted changes), the
    machine, the date and the wall time.
``python docs/results/generate.py pages --work DIR``
    writes the MyST pages ``docs/results/*.md`` and copies their figures to
    ``docs/results/figures/``. Every table and figure is followed by a stamp
    line naming its command and commit (``tests/test_results_pages.py``
    checks that none is missing).

The pages and figures are committed; the documentation build reads them and
never reruns the commands.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGES = Path(__file__).resolve().parent

#: Job name -> the ``coherence`` arguments it runs (``--out`` is added), or a
#: ``python`` script of the repository and its arguments.
#: ``{size}`` is the image size chosen with ``--size``; whatif studies keep
#: their own default size; the today jobs take ``--today-size``.
JOBS = {
    "paper": ["paper", "--size", "{size}"],
    "report-balls": ["report", "balls", "--size", "{size}"],
    "whatif-caches": ["whatif", "caches"],
    "whatif-texture": ["whatif", "texture"],
    "robustness": ["robustness", "--size", "{robustness_size}", "--trajectories", "{trajectories}",
                   "--faithfulness-md", "{out}/faithfulness.md"],
    # Sobol's design on the two scenes whose samples cost least (docs/results/faithfulness-sobol.md)
    "robustness-sobol": ["robustness", "--size", "{robustness_size}", "--scenes", "tetra", "fluid",
                         "--trajectories", "{trajectories}", "--sobol", "64",
                         "--faithfulness-md", "{out}/faithfulness-sobol.md"],
    "today-report": ["report", "balls", "--platform", "zen4-7950x", "--size", "{today_size}",
                     "--processes", "8", "16", "32"],
    "today-sharing": ["python", "docs/results/today_sharing.py", "--size", "{today_size}", "--platform",
                      "zen4-7950x"],
    "today-prefetch": ["whatif", "--scene", "balls", "--platform", "zen4-7950x", "--grid", "prefetch=on,off",
                       "--size", "{today_size}"],
    # the ray-order page (docs/results/ray_orders_page.py): the report's section on both machines, the
    # whatif --orders grids; sizes fixed so that each runs in minutes on 2 cores
    "orders-report": ["report", "balls", "--workload", "pathtrace", "--spp", "4", "--size", "256",
                      "--mappings", "P", "--processes", "8"],
    "orders-report-today": ["report", "balls", "--workload", "pathtrace", "--spp", "4", "--size", "256",
                            "--mappings", "P", "--processes", "8", "--platform", "zen4-7950x"],
    "orders-whatif-balls": ["whatif", "--orders", "--grid", "spp=1,4", "--grid", "max_depth=2,5",
                            "--grid", "L1.size=8KB,64KB", "--size", "32"],
    "orders-whatif-tetra": ["whatif", "--orders", "--scene", "tetra", "--grid", "scene_size=6,10",
                            "--grid", "spp=1,4", "--grid", "L1.size=8KB,64KB", "--size", "32"],
    "orders-whatif-tetra-l3": ["whatif", "--orders", "--scene", "tetra", "--grid", "scene_size=10",
                               "--grid", "L3.size=1MB,4MB", "--size", "128"],
}


def git_commit() -> str:
    """The work tree's commit, with ``+dirty`` when tracked files differ from it."""
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True, check=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.strip()
    return commit + ("+dirty" if dirty else "")


def machine() -> str:
    """A one-line description of the machine: CPU model, logical CPUs, OS, Python."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}, Python {platform.python_version()}"


def run_job(name: str, work: Path, values: dict) -> dict:
    """Run one job's command into ``work/name`` and write its stamp.

    Returns
    -------
    dict
        The stamp: ``command``, ``commit``, ``machine``, ``date`` (UTC) and
        ``seconds`` (wall time).
    """
    out = work / name
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    arguments = [part.format(out=out, **values) for part in JOBS[name]] + ["--out", str(out)]
    shown = [part.replace(str(out), "OUT") for part in arguments]
    if arguments[0] == "python":
        command, shown = [sys.executable, *arguments[1:]], shlex.join(shown)
    else:
        command, shown = [sys.executable, "-m", "analyses", *arguments], "coherence " + shlex.join(shown)
    stamp = {"command": shown, "commit": git_commit(),
             "machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    started = time.perf_counter()
    with open(out / "log.txt", "w", encoding="utf-8") as log:
        subprocess.run(command, cwd=ROOT, check=True,
                       stdout=log, stderr=subprocess.STDOUT)
    stamp["seconds"] = round(time.perf_counter() - started, 1)
    (out / "stamp.json").write_text(json.dumps(stamp, indent=1) + "\n", encoding="utf-8")
    return stamp


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="step", required=True)
    run = sub.add_parser("run", help="run the jobs' commands into --work")
    run.add_argument("--work", type=Path, required=True)
    run.add_argument("--size", type=int, default=512, help="image size of paper and report (default 512)")
    run.add_argument("--robustness-size", type=int, default=256)
    run.add_argument("--trajectories", type=int, default=10)
    run.add_argument("--today-size", type=int, default=256, help="image size of the today jobs (default 256)")
    run.add_argument("--only", nargs="+", choices=sorted(JOBS), default=sorted(JOBS))
    pages = sub.add_parser("pages", help="write docs/results/*.md from --work")
    pages.add_argument("--work", type=Path, required=True)
    args = parser.parse_args(argv)
    if args.step == "run":
        values = {"size": args.size, "robustness_size": args.robustness_size,
                  "trajectories": args.trajectories, "today_size": args.today_size}
        for name in args.only:
            stamp = run_job(name, args.work, values)
            print(f"{name}: {stamp['command']} ({stamp['seconds']} s)", flush=True)
    else:
        from pages import write_pages  # noqa: PLC0415 (beside this script)
        write_pages(args.work, PAGES)


if __name__ == "__main__":
    main()
