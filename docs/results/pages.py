"""Write the results pages (MyST Markdown) from the outputs ``generate.py run`` left.

Each page is built from one job's folder; every table and figure on it is
followed by :func:`stamp_line`, naming the command and commit that produced
it, the date and the machine. Nothing here computes a result: it selects
columns, rounds and copies figures.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd

#: What every stamp line starts with; ``tests/test_results_pages.py`` looks for it.
STAMP_PREFIX = "**Produced by**"


def stamp_line(stamp: dict) -> str:
    """The line under a table or figure: command, commit, date, wall time and machine.

    Parameters
    ----------
    stamp : dict
        A job's ``stamp.json`` (``command``, ``commit``, ``date``,
        ``seconds``, ``machine``).
    """
    return (f"{STAMP_PREFIX} `{stamp['command']}` at commit `{stamp['commit']}` "
            f"({stamp['date']}, {stamp['seconds']:.0f} s on {stamp['machine']}).")


def markdown_table(frame: pd.DataFrame, digits: int = 3) -> str:
    """A pipe table of ``frame`` (index dropped), floats rounded to ``digits`` significant figures."""
    def cell(value):
        if isinstance(value, float):
            return f"{value:.{digits}g}"
        return str(value).replace("|", "\\|")
    lines = ["| " + " | ".join(str(column) for column in frame.columns) + " |",
             "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join(lines)


class _Page:
    """A page being written: text blocks, each table or figure stamped."""

    def __init__(self, title: str, intro: str):
        self.blocks = [f"# {title}", intro.strip()]

    def text(self, text: str):
        self.blocks.append(text.strip())

    def table(self, frame: pd.DataFrame, stamp: dict, digits: int = 3):
        self.blocks += [markdown_table(frame, digits), stamp_line(stamp)]

    def figure(self, source: Path, target: Path, alt: str, stamp: dict):
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
        self.blocks += [f"![{alt}](figures/{target.name})", stamp_line(stamp)]

    def write(self, path: Path):
        path.write_text("\n\n".join(self.blocks) + "\n", encoding="utf-8")


def _stamp(folder: Path) -> dict:
    return json.loads((folder / "stamp.json").read_text(encoding="utf-8"))


def _job(work: Path, name: str, summary_file: str):
    """A finished job's folder, stamp, JSON summary and image size; None when it did not run."""
    folder = work / name
    if not (folder / "stamp.json").exists():
        return None
    summary = json.loads((folder / summary_file).read_text(encoding="utf-8"))
    return folder, _stamp(folder), summary, summary["parameters"].get("size", "?")


def paper_page(job: tuple, pages: Path) -> str:
    folder, stamp, summary, size = job
    page = _Page("The study reproduced", f"""
`coherence paper` at {size}×{size} pixels: the study's five scenes on its
machine (the 21164's inclusive caches, 8 CPUs, other users' load), the
study-era tracer, the cost model fitted to the study's five sequential Strip
times only (targets scaled by pixel count), then every mapping at every
process count. The study used 512×512; a smaller image changes the
per-process loads, so compare the verdicts, not the last digit.""")
    page.text("## The study's table beside ours")
    scenes = pd.read_csv(folder / "scenes.csv")
    page.table(scenes[["scene", "study_elements", "our_elements", "study_tests_1e6", "our_tests_1e6",
                       "study_seconds", "target_seconds", "fitted_seconds", "relative_error"]], stamp)
    page.text("""`our_tests_1e6` counts tests at this image size; `target_seconds` is the
study's sequential time scaled to it, `fitted_seconds` what the fitted
costs give, `relative_error` their relative difference (negative: the fit
falls short).""")
    page.text("## The fitted costs, and the time they leave unexplained")
    calibration = summary["calibration"]
    page.table(pd.DataFrame(calibration["fitted"])[["name", "reference", "cycles", "low", "high", "at_bound"]], stamp)
    page.text("""Each fitted cost stays inside its prior range (`low` to `high` cycles,
from the instruction count of its routine on the 21164; `docs/unknowns.md`);
`at_bound` marks a cost the fit pushed against a bound of its range.""")
    residuals = pd.DataFrame(calibration["residuals"])
    page.table(residuals[["scene", "target_seconds", "fitted_seconds", "unexplained_seconds", "relative_error"]], stamp)
    page.text("""`unexplained_seconds` is the study's time (scaled to this image) minus the
fitted model's, with every cost inside its prior: the time our counters do not
explain, shown here instead of being absorbed by one cost.""")
    page.text("## Verdicts at 8 processes")
    verdicts = pd.DataFrame(summary["verdicts"])
    page.table(verdicts[["scene", "best_mapping", "best_speedup_user", "best_speedup_real",
                         "max_imbalance_loss", "max_imbalance_mapping", "max_coherence_loss",
                         "max_coherence_mapping", "decided_by"]], stamp)
    page.text("## Sequential times of every mapping, predicted from the fit")
    page.table(pd.read_csv(folder / "predictions.csv"), stamp)
    page.text("## Speed-up figures")
    for column, what in (("speedup_user", "user time"), ("speedup_real", "real time")):
        page.figure(folder / f"{column}.png", pages / "figures" / f"paper-{column}.png",
                    f"speed-up by {what}, one panel per scene", stamp)
    page.write(pages / "paper.md")
    return "paper"


def report_page(job: tuple, pages: Path) -> str:
    folder, stamp, summary, size = job
    page = _Page("One scene's report: balls", f"""
`coherence report balls` at {size}×{size} pixels on today's SAH tracer and the
default machine. The verdict, as the report states it:

> {summary['verdict']['headline']}""")
    results = pd.read_csv(folder / "results.csv")
    runs = results[(results["section"] == "runs") & (results["n_processes"] == summary["verdict"]["n_processes"])]
    if not runs.empty:
        wide = runs.pivot_table(index="mapping", columns="metric", values="value", sort=False).reset_index()
        keep = [c for c in ("mapping", "speedup_user", "speedup_real", "efficiency", "load_balance",
                            "coherence_factor", "dispatch_factor", "L1_hit_rate", "L2_hit_rate", "L3_hit_rate")
                if c in wide.columns]
        page.text(f"## Runs at {summary['verdict']['n_processes']} processes")
        page.table(wide[keep], stamp)
    page.text("## Misses per pixel")
    page.figure(folder / "miss_map.png", pages / "figures" / "report-balls-miss_map.png",
                "misses per pixel and cache level", stamp)
    page.write(pages / "report-balls.md")
    return "report-balls"


def whatif_page(work: Path, pages: Path) -> str | None:
    jobs = [name for name in ("whatif-caches", "whatif-texture") if (work / name / "stamp.json").exists()]
    if not jobs:
        return None
    page = _Page("What-if studies", """
Built-in `coherence whatif` studies at their own default size (128×128, 8
processes; balls, and its textured version for the texture study). A positive `coherence_minus_imbalance` means coherence
lost more efficiency than imbalance at that point.""")
    for name in jobs:
        folder = work / name
        stamp = _stamp(folder)
        table = pd.read_csv(folder / f"{name}.csv")
        grid = list(table.columns[:list(table.columns).index("mapping")])
        wide = table.pivot_table(index=grid + ["mapping"], columns="metric", values="value",
                                 sort=False).reset_index()
        wide["coherence_minus_imbalance"] = wide["coherence_loss"] - wide["imbalance_loss"]
        keep = grid + ["mapping", "imbalance_loss", "coherence_loss", "coherence_minus_imbalance"]
        keep += [c for c in wide.columns if c.startswith("texel_L1")]
        page.text(f"## `{name.removeprefix('whatif-')}`: {', '.join(grid)}")
        page.table(wide[keep], stamp)
        page.figure(folder / f"{name}.png", pages / "figures" / f"{name}.png", name, stamp)
    page.write(pages / "whatif.md")
    return "whatif"


def today_page(work: Path, pages: Path) -> str | None:
    """``today.md``: the study's question asked of a machine of today (jobs today-report and today-sharing)."""
    report = _job(work, "today-report", "summary.json")
    sharing_folder = work / "today-sharing"
    if report is None or not (sharing_folder / "stamp.json").exists():
        return None
    folder, stamp, summary, size = report
    platform = summary["parameters"]["platform"]
    sharing_stamp = _stamp(sharing_folder)
    sharing = pd.read_csv(sharing_folder / "sharing.csv")
    page = _Page("Today's machine: does load balance still decide?", f"""
The study's question asked of `{platform['name']}` ({platform['n_cores']} cores, SMT{platform['smt']},
levels shared by {', '.join(platform['shared_by'])}; `docs/platforms.md`), on balls at
{size}×{size} pixels rendered by today's tracer with its per-ray data and frame-buffer
writes logged. Small images: every figure here is at {size}×{size}, not the study's
512×512, and DB's 32×32 blocks number {(size // 32) ** 2}.

How the schedule's runs simulate the shared levels is recorded in the report's
parameters: *{platform['shared_levels']}*. The sharing tables below replay one
interleaved stream exactly through the shared levels instead
(`docs/results/today_sharing.py`).""")
    results = pd.read_csv(folder / "results.csv")
    runs = results[(results["section"] == "runs") & (results["n_processes"] > 1)]
    wide = runs.pivot_table(index=["n_processes", "mapping"], columns="metric", values="value",
                            sort=False).reset_index()
    wide["n_processes"] = wide["n_processes"].astype(int)
    page.text("## Load balance or coherence, at 8, 16 and 32 threads")
    page.text(f"The report's verdict at {summary['verdict']['n_processes']} processes: "
              f"*{summary['verdict']['headline']}*")
    page.table(wide[["n_processes", "mapping", "speedup_user", "speedup_real", "imbalance_loss",
                     "coherence_loss", "dispatch_loss"]], stamp)
    lines = []
    for count, rows in wide.groupby("n_processes", sort=True):
        rows = rows.set_index("mapping")
        imbalance, coherence = rows["imbalance_loss"].astype(float), rows["coherence_loss"].astype(float)
        larger = "load balance" if imbalance.max() > coherence.max() else "coherence"
        lines.append(f"- {count} processes: {larger} costs more (imbalance up to {imbalance.max():.1%} "
                     f"({imbalance.idxmax()}), coherence up to {coherence.max():.1%} ({coherence.idxmax()})); "
                     f"best user speed-up {rows['speedup_user'].astype(float).max():.2f} "
                     f"({rows['speedup_user'].astype(float).idxmax()}).")
    page.text("\n".join(lines))
    three = sharing[sharing["frame_buffer_bytes"] == 3]
    page.text("## False sharing of 3-byte pixels, and DB's counter")
    page.table(three[["mapping", "threads", "smt", "L1_misses", "L2_misses", "L3_misses", "coherence_misses",
                      "false_sharing_misses", "counter_accesses", "counter_coherence_misses"]], sharing_stamp)
    page.text("""A false-sharing miss is a miss on a line this cache lost to another thread's
write of other bytes, counted when the thread comes back to the line. P's
threads write pixels `n` apart: with 3-byte pixels a 64-byte line holds 21,
so at 8 threads a thread returns to a line it shared, at 32 its next pixel
lies on another line and it never returns. DB's counter is written once per
task; a copy evicted before another thread's write is a capacity miss, not a
coherence miss. These counter figures come from the thread streams' idealised
round-robin hand-outs; the schedule's own DB runs follow.""")
    if "task_counter_accesses" in wide:
        _counter_section(page, wide, stamp)
    page.text("## Frame-buffer pixel size (S and P)")
    page.table(sharing[sharing["mapping"].isin(["S", "P"])][["frame_buffer_bytes", "mapping", "threads", "smt",
                                                             "false_sharing_misses", "memory_cycles"]]
               .sort_values(["mapping", "threads", "smt", "frame_buffer_bytes"], kind="stable"), sharing_stamp)
    smt = three.pivot_table(index=["mapping", "threads"], columns="smt", values="memory_cycles",
                            sort=False).dropna().reset_index()
    smt.columns = ["mapping", "threads", "memory_cycles_smt_on", "memory_cycles_smt_off"]
    smt["on_over_off"] = smt["memory_cycles_smt_on"] / smt["memory_cycles_smt_off"]
    page.text("## SMT: two threads a core or one")
    page.table(smt, sharing_stamp)
    page.text("""`memory_cycles` sums each access's latency at the level that served it. SMT on
packs thread pairs onto half the cores, sharing their L1 and L2; off, every
thread has a core. Below 1, neighbouring threads sharing a core's caches
gained more than the halved capacity cost.""")
    prefetch_folder = work / "today-prefetch"
    if (prefetch_folder / "stamp.json").exists():
        _prefetch_section(page, prefetch_folder)
    page.write(pages / "today.md")
    return "today"


def _counter_section(page: _Page, wide: pd.DataFrame, stamp: dict) -> None:
    """DB's task-counter traffic in the report's runs on the shared levels (its ``task_counter_*`` columns)."""
    db = wide[wide["mapping"] == "DB"]
    page.text("## DB's counter in the schedule's runs")
    page.table(db[["n_processes", "task_counter_accesses", "task_counter_invalidations",
                   "task_counter_coherence_misses", "dispatch_loss", "speedup_user"]], stamp)
    page.text("""In the report's runs every task a DB process takes is an atomic read-modify-write of the
shared counter's line on its hardware thread, through the shared levels: the accesses are the hand-outs, the
invalidations the copies other threads' caches lost to them, and a coherence miss a hand-out that found its
line taken away by another thread's (both summed over the levels, so a hand-out can count at L1 and L2). The
hand-out waits for the line, so its latency is dispatch time.""")


def _prefetch_section(page: _Page, folder: Path) -> None:
    """The prefetchers on/off what-if of the today page (job today-prefetch: ``whatif-grid.csv``)."""
    stamp = _stamp(folder)
    long = pd.read_csv(folder / "whatif-grid.csv")
    wide = long.pivot_table(index=["prefetch", "mapping", "n_processes"], columns="metric", values="value",
                            sort=False).reset_index()
    wide["n_processes"] = wide["n_processes"].astype(int)
    from coherence.platforms import PREFETCHERS_ON

    levels = [column.removesuffix("_misses_per_ray") for column in wide.columns if column.endswith("_misses_per_ray")]
    prefetching = levels[:len(PREFETCHERS_ON)]  # the levels prefetch=on gives a prefetcher
    n = int(wide["n_processes"].iloc[0])
    page.text(f"## Prefetchers on and off, at {n} processes")
    page.text("""`prefetch=on` puts the generic prefetchers of `coherence.platforms.PREFETCHERS_ON` on the
platform (next-line on a miss at L1, a stride table two strides ahead at L2; `docs/prefetch.md`); every
access of the schedule trains them. A prefetch completes at once and costs no cycles or memory bandwidth, so
the gains below are an upper bound of what these prefetchers give. Misses are demand misses (a line a
prefetch brought from memory is no demand miss); a useful prefetch is one a demand access hit before it left
the level.""")
    columns = ["prefetch", "mapping", "user_seconds_max", "speedup_user", "imbalance_loss", "coherence_loss",
               *[f"{level}_misses_per_ray" for level in levels]]
    page.table(wide[columns].sort_values(["mapping", "prefetch"], kind="stable"), stamp)
    on = wide[wide["prefetch"] == "on"].set_index("mapping")
    off = wide[wide["prefetch"] == "off"].set_index("mapping")
    counts = on[[f"{level}_prefetches_{what}" for level in prefetching
                 for what in ("issued", "useful", "useless")]].astype("int64").reset_index()
    page.text("Prefetches at `prefetch=on`, summed over each level's instances (a prefetched line still "
              "unused at the end is neither useful nor useless):")
    page.table(counts, stamp)
    gain = (off["user_seconds_max"] / on["user_seconds_max"]).sort_values()
    lines = [f"- {mapping}: the slowest process {ratio:.3f} times as fast with prefetchers"
             for mapping, ratio in gain.items()]
    verdicts = []
    for switch, rows in (("on", on), ("off", off)):
        larger = rows.index[rows["coherence_loss"] > rows["imbalance_loss"]]
        verdicts.append(f"prefetch {switch}: coherence costs more than imbalance for "
                        f"{', '.join(larger) if len(larger) else 'no mapping'} (largest imbalance "
                        f"{rows['imbalance_loss'].max():.1%}, largest coherence loss "
                        f"{rows['coherence_loss'].max():.1%})")
    page.text("\n".join(lines) + "\n\n" + "; ".join(verdicts) + ".")


def write_pages(work: Path, pages: Path) -> list[str]:
    """Write every page whose job's outputs are in ``work``, and the index.

    Returns
    -------
    list of str
        The pages written (without ``.md``), in the index's order.
    """
    paper = _job(work, "paper", "paper.json")
    report = _job(work, "report-balls", "summary.json")
    written = [paper_page(paper, pages) if paper else None, report_page(report, pages) if report else None,
               whatif_page(work, pages), today_page(work, pages)]
    # faithfulness.md and faithfulness-sobol.md are written by analyses.faithfulness from the .json beside each
    # (its command and commit head each page); they are listed, not rewritten
    for name in ("faithfulness", "faithfulness-sobol"):
        if (pages / f"{name}.md").exists():
            written.append(name)
    from ray_orders_page import write_ray_orders_page  # noqa: PLC0415 (beside this script)
    # written from ray-orders.json beside it, which the ray-order jobs found in work update first
    written.append(write_ray_orders_page(work, pages))
    written = [name for name in written if name]
    # anchors.md is written by anchors.py from anchors.json beside it; it is listed, not rewritten
    if (pages / "anchors.md").exists():
        written.append("anchors")
    if (pages / "performance.json").exists():
        from performance import write_performance_page  # noqa: PLC0415 (beside this script)
        write_performance_page(pages)
        written.append("performance")
    index = ["# Results", "",
             "Generated pages: each table and figure names the command and the commit that",
             "produced it. `python docs/results/generate.py run --work DIR` reruns the",
             "commands, `python docs/results/generate.py pages --work DIR` rewrites the pages;",
             "the documentation build never reruns them.", "",
             "```{toctree}", ":maxdepth: 1", ""] + written + ["```", ""]
    (pages / "index.md").write_text("\n".join(index), encoding="utf-8")
    return written
