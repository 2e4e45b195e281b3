"""Both phases of ``coherence robustness`` against the issue's budgets, per scene and in total.

Renders (or loads from the trace cache) every trace the study will read
(each scene's tree variants at ``--size``, the base's tree at half and
twice it for the size check) and compiles the kernels first, untimed. Then
one :func:`analyses.robustness.robustness` call per scene of ``--scenes``
with ``--trajectories`` Morris trajectories, the size check and Sobol's
design of ``--sobol`` base samples, every phase timed (wall, and this
process's CPU time over all its threads) and printed as the scene ends
(**measured**), with the share of its runs re-costed from stored miss counts
and reused (:mod:`coherence.recost`).

The budgeted designs are larger than the measured ones, and cover every
study scene (:data:`tracer.scenes.catalog.PAPER_SCENES`); their times are
**projected**:

- Morris screening, r = 10 trajectories over every unknown (17 samples
  each) per scene, plus the size check (run once a scene whatever the
  design): target <= 20 minutes;
- Sobol over the top 4 unknowns with N = 64 (N (4 + 2) = 384 samples) per
  scene: target <= 60 minutes.

Both targets are judged twice: for each scene's study alone
(``coherence robustness --scenes NAME``) and for the five scenes' study
together (the command's default).

A measured scene's design is projected from its own rate per sample. A
scene not measured is projected from the measured scenes' CPU time per
trace record (the study's base tree at ``--size``; every sample replays
about that many records), a coarser estimate, marked "by trace size".
The times for the target's 2 idle cores come from the CPU times, which a
machine shared with other work does not inflate as it does wall times:
the samples of a phase go through one
:func:`coherence.studies.study_stream`, which simulates their runs on one
thread per CPU, so every simulated run's CPU time (its thread's) is
recorded, and the phase's runs are laid on 2 cores as the stream's pool
takes them (each run to the first free core, in the order they started;
where the stream waited for the runs under way before working out a new
placement's line addresses, the runs after wait for all before), plus the
CPU time spent outside the runs (line addresses, re-costing, tables), on
one core after them. That gives a phase's time on 2 idle cores; its ratio
to the phase's CPU time projects the budgeted design, and a target counts
as met when that time meets it. Also printed: the time with the work
outside the runs beside them (the stream plans the next samples while runs
are under way): the runs laid out as before or the phase's CPU time / 2,
whichever is longer; the bounds CPU time / 2 (both cores always busy)
and CPU time (one core), and how many cores (or Dask workers, ``coherence
robustness --dask``, each run a task) the projected CPU time needs. The
wall times are as measured on this machine, which may be shared with other
work. With ``--dask ADDRESS`` the
runs go to that scheduler's workers: this process's CPU time then leaves
their work out, and only wall times are meaningful. Ends with one JSON
line.

    python benchmarks/bench_robustness.py [--size 256] [--trajectories 2] [--sobol 2] [--scenes balls tetra ...]
                                          [--dask tcp://host:8786]
"""
import argparse
import json
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from analyses.robustness import ROBUSTNESS_EXPERIMENT, SOBOL_FACTORS, robustness  # noqa: E402
from analyses.robustness_factors import FACTORS  # noqa: E402
from analyses.robustness_output import BUDGET_SOBOL, BUDGET_TRAJECTORIES  # noqa: E402
from analyses.robustness_size import check_sizes  # noqa: E402
from coherence.unknowns import TREE_VARIANTS  # noqa: E402
from tracer.scenes.catalog import PAPER_SCENES  # noqa: E402

class RunClock:
    """Records the CPU time of every simulated run, grouped by the study's streams of samples.

    Installed around ``analyses.robustness._stream`` (one stream a phase of a scene: its Morris samples, the
    size check, Sobol's samples), ``coherence.studies.simulate_run`` (each run's thread CPU time, in the order
    the runs start) and ``coherence.studies._wait_for`` (where the stream waits for the runs under way before
    working out a new placement's line addresses: a new segment), for the measured studies only; the results
    do not depend on it.
    """

    def __init__(self):
        import threading

        self.streams = []  # per stream: segments, each the CPU seconds of its runs in the order they started
        self.lock = threading.Lock()

    def install(self):
        import analyses.robustness as robustness_module
        import coherence.studies as studies

        stream, simulate_run, wait_for = robustness_module._stream, studies.simulate_run, studies._wait_for

        def timed_stream(calls):
            with self.lock:
                self.streams.append([[]])
            return stream(calls)

        def timed_run(*args, **kwargs):
            start = time.thread_time()
            run = simulate_run(*args, **kwargs)
            with self.lock:
                self.streams[-1][-1].append(time.thread_time() - start)
            return run

        def timed_wait(plans):
            plans = list(plans)
            if plans:
                with self.lock:
                    self.streams[-1].append([])
            wait_for(plans)

        robustness_module._stream, studies.simulate_run, studies._wait_for = timed_stream, timed_run, timed_wait

    def run_seconds(self, stream: int) -> float:
        """CPU seconds of the simulated runs of stream number ``stream``."""
        return sum(sum(runs) for runs in self.streams[stream])

    def overlapped(self, stream: int, cpu_seconds: float) -> float:
        """A lower bound on the seconds on 2 idle cores of stream number ``stream`` with the CPU time
        outside the runs done beside them (the stream plans the next samples while runs are under way, but
        also waits for runs before working out a new placement's line addresses, which this ignores): the
        runs' segments laid on the cores, or all its CPU time shared by both cores, whichever is longer."""
        return max(sum(makespan(runs, CORES) for runs in self.streams[stream]), cpu_seconds / CORES)

    def two_cores(self, stream: int, cpu_seconds: float) -> float:
        """Seconds on 2 idle cores of stream number ``stream``, which took ``cpu_seconds`` of CPU: each
        segment's runs laid on the cores in the order they started (a segment waits for the one before),
        plus the CPU time outside the runs on one core."""
        segments = self.streams[stream]
        in_runs = self.run_seconds(stream)
        return sum(makespan(runs, CORES) for runs in segments) + max(cpu_seconds - in_runs, 0.0)


def makespan(durations, cores: int) -> float:
    """When the last of ``durations`` ends, each started in order on the first free of ``cores``."""
    free = [0.0] * cores
    for duration in durations:
        core = free.index(min(free))
        free[core] += duration
    return max(free)


MORRIS_TARGET_SECONDS = 20 * 60.0
SOBOL_TARGET_SECONDS = 60 * 60.0
CORES = 2
#: What is projected per phase: wall seconds at the measured rate, CPU seconds, seconds on 2 idle cores.
RATES = ("seconds", "cpu_seconds", "two_core_seconds", "overlapped_seconds")


def prepare(base, scenes) -> float:
    """Compile the kernels and render or load every trace the study reads; seconds taken."""
    from analyses.traces import cached_trace

    start = time.perf_counter()
    robustness(replace(base, size=16), scenes=scenes[:1], trajectories=2, sobol=2)  # compile
    for scene in scenes:
        sizes = [(variant, base.size) for variant in TREE_VARIANTS]
        sizes += [(base.tree_variant, size) for size in check_sizes(base.size)]
        for variant, size in sizes:
            cached_trace(scene, size, kd=base.kd_builder(), max_depth=None, progress=False, workload=base.workload,
                         tree_variant=variant)
    return time.perf_counter() - start


def trace_records(base, scene) -> int:
    """Records of ``scene``'s trace on the base's tree at the base's size (rendered if not cached)."""
    from analyses.traces import cached_trace

    _, trace, _ = cached_trace(scene, base.size, kd=base.kd_builder(), max_depth=None, progress=False,
                               workload=base.workload, tree_variant=base.tree_variant)
    return int(len(trace.records))


def scene_phases(result, timings, clock: RunClock, first: int) -> dict:
    """Per phase of one scene's study: seconds, CPU seconds, seconds on 2 idle cores, samples and run paths.

    ``clock`` recorded the study's streams from its stream ``first`` on: the Morris samples, the size check,
    then Sobol's samples, one stream each.
    """
    (scene, summary), = result.summary["scenes"].items()
    design = result.samples["design"]
    phases = {}
    for stream, phase in enumerate(("morris", "size_check", "sobol"), start=first):
        figures = timings[scene][phase]
        phases[phase] = {**figures, "two_core_seconds": clock.two_cores(stream, figures["cpu_seconds"]),
                         "overlapped_seconds": clock.overlapped(stream, figures["cpu_seconds"]),
                         "run_cpu_seconds": clock.run_seconds(stream),
                         "samples": int((design == phase).sum()),
                         "runs": summary["sobol"]["runs"] if phase == "sobol" else
                         summary["runs"] if phase == "morris" else dict.fromkeys(("simulated", "re_costed", "reused"), 0)}
    return phases


def add_phases(totals: dict, phases: dict) -> None:
    """Add one scene's ``phases`` into ``totals`` (same shape)."""
    for phase, figures in phases.items():
        total = totals.setdefault(phase, {"seconds": 0.0, "cpu_seconds": 0.0, "two_core_seconds": 0.0,
                                          "overlapped_seconds": 0.0, "run_cpu_seconds": 0.0, "samples": 0,
                                          "runs": dict.fromkeys(figures["runs"], 0)})
        for key in ("seconds", "cpu_seconds", "two_core_seconds", "overlapped_seconds", "run_cpu_seconds",
                    "samples"):
            total[key] += figures[key]
        for path, count in figures["runs"].items():
            total["runs"][path] += count


def share(runs: dict) -> str:
    total = sum(runs.values())
    if not total:
        return "no runs counted"
    return (f"{runs['simulated']} runs simulated, {runs['re_costed']} re-costed ({100 * runs['re_costed'] / total:.0f}%),"
            f" {runs['reused']} reused ({100 * runs['reused'] / total:.0f}%)")


def budget_samples() -> dict:
    """Samples a scene's budgeted design takes, per phase (the size check is a fixed cost, not scaled)."""
    return {"morris": BUDGET_TRAJECTORIES * (len(FACTORS) + 1), "sobol": BUDGET_SOBOL * (SOBOL_FACTORS + 2)}


def project_scene(phases: dict) -> dict:
    """A measured scene's budgeted phases, from its own rates: phase -> RATES."""
    budget = budget_samples()
    out = {}
    for phase in ("morris", "sobol"):
        measured = phases[phase]
        out[phase] = {rate: measured[rate] * budget[phase] / measured["samples"]
                      + (phases["size_check"][rate] if phase == "morris" else 0.0)
                      for rate in RATES}
    return out


def project_by_records(projected: dict, records: dict, scene: str) -> dict:
    """An unmeasured scene's budgeted phases: the measured scenes' projected seconds per trace record."""
    measured = list(projected)
    total_records = sum(records[name] for name in measured)
    return {phase: {rate: sum(projected[name][phase][rate] for name in measured) * records[scene] / total_records
                    for rate in RATES} for phase in ("morris", "sobol")}


def judge(figures: dict, target: float) -> str:
    """Whether a phase's projected ``figures`` (RATES) meet ``target`` on the target's cores, and the cores
    its CPU time would need."""
    cpu_seconds, two = figures["cpu_seconds"], figures["two_core_seconds"]
    verdict = "met" if two <= target else f"NOT met ({two / target:.1f}x over)"
    return (f"on {CORES} idle cores {two:.0f} s (the runs laid on {CORES} cores as measured, the work outside "
            f"them after; {figures['overlapped_seconds']:.0f} s with that work beside the runs, a lower bound; "
            f"bounds {cpu_seconds / CORES:.0f} s both busy, {cpu_seconds:.0f} s one busy); "
            f"target <= {target:.0f} s: "
            f"{verdict}; needs >= {max(1, -(-int(cpu_seconds) // int(target)))} busy cores (or Dask workers)")


def scene_verdict(figures: dict, target: float) -> str:
    """Whether one scene's projected phase (RATES) meets ``target`` on the target's idle cores."""
    two = figures["two_core_seconds"]
    return "met" if two <= target else f"NOT met ({two / target:.1f}x over)"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--trajectories", type=int, default=2)
    parser.add_argument("--sobol", type=int, default=2, help="Sobol base samples measured (a power of two)")
    parser.add_argument("--scenes", nargs="+", default=list(PAPER_SCENES), help="the scenes measured")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dask", metavar="ADDRESS", help="simulate the runs on this Dask scheduler")
    args = parser.parse_args()

    from analyses.cluster import dask_executor

    base = replace(ROBUSTNESS_EXPERIMENT, size=args.size)
    warnings.simplefilter("ignore")
    prepared = prepare(base, args.scenes)
    print(f"{len(args.scenes)} scene(s) measured at {args.size}x{args.size}; {os.cpu_count()} CPUs here"
          f"{'; runs on Dask at ' + args.dask + ' (CPU times leave the workers out)' if args.dask else ''}; "
          f"traces and compilation before, untimed: {prepared:.0f} s", flush=True)
    totals, per_scene, projected = {}, {}, {}
    clock = RunClock()
    clock.install()
    with dask_executor(args.dask) as executor:
        for scene in args.scenes:
            timings = {}
            first = len(clock.streams)
            result = robustness(base, scenes=[scene], trajectories=args.trajectories, seed=args.seed,
                                sobol=args.sobol, timings=timings, executor=executor)
            per_scene[scene] = scene_phases(result, timings, clock, first)
            add_phases(totals, per_scene[scene])
            projected[scene] = project_scene(per_scene[scene])
            print(f"measured {scene}: " + "; ".join(
                f"{phase} {f['samples']} samples {f['seconds']:.0f} s wall {f['cpu_seconds']:.0f} s CPU "
                f"({f['run_cpu_seconds']:.0f} s in simulated runs; {f['two_core_seconds']:.0f} s on {CORES} cores, "
                f"{f['overlapped_seconds']:.0f} s overlapped, a lower bound), "
                f"{share(f['runs'])}" for phase, f in per_scene[scene].items()), flush=True)
    records = {scene: trace_records(base, scene) for scene in PAPER_SCENES}
    how = {scene: "from its own rate" for scene in projected}
    for scene in PAPER_SCENES:
        if scene not in projected:
            projected[scene] = project_by_records({name: projected[name] for name in args.scenes}, records, scene)
            how[scene] = "by trace size (not measured)"
    morris, check, sobol = (totals[phase] for phase in ("morris", "size_check", "sobol"))
    print(f"measured in total: Morris {args.trajectories} trajectories x {len(FACTORS) + 1} samples a scene, "
          f"{morris['samples']} samples in {morris['seconds']:.0f} s wall, {morris['cpu_seconds']:.0f} s CPU, "
          f"{share(morris['runs'])}; size check {check['seconds']:.0f} s wall, {check['cpu_seconds']:.0f} s CPU "
          f"(5 samples a scene at {' and '.join(map(str, check_sizes(args.size)))}); Sobol N = {args.sobol} over "
          f"the top {SOBOL_FACTORS}: {sobol['samples']} samples in {sobol['seconds']:.0f} s wall, "
          f"{sobol['cpu_seconds']:.0f} s CPU, {share(sobol['runs'])}")
    budget = budget_samples()
    for scene in PAPER_SCENES:
        figures = projected[scene]
        print(f"projected {scene} ({how[scene]}, {records[scene]} records): Morris r = {BUDGET_TRAJECTORIES} + "
              f"size check {figures['morris']['cpu_seconds']:.0f} s CPU, {figures['morris']['two_core_seconds']:.0f}"
              f" s on {CORES} cores ({figures['morris']['seconds']:.0f} s at the measured wall rate); Sobol N = "
              f"{BUDGET_SOBOL}: {figures['sobol']['cpu_seconds']:.0f} s CPU, {figures['sobol']['two_core_seconds']:.0f}"
              f" s on {CORES} cores ({figures['sobol']['seconds']:.0f} s wall rate); this scene's study alone "
              f"(--scenes {scene}) against the targets: Morris {scene_verdict(figures['morris'], MORRIS_TARGET_SECONDS)}"
              f", Sobol {scene_verdict(figures['sobol'], SOBOL_TARGET_SECONDS)}")
    total = {phase: {rate: sum(projected[scene][phase][rate] for scene in PAPER_SCENES)
                     for rate in RATES} for phase in ("morris", "sobol")}
    for phase, target in (("morris", MORRIS_TARGET_SECONDS), ("sobol", SOBOL_TARGET_SECONDS)):
        design = (f"r = {BUDGET_TRAJECTORIES} over {len(FACTORS)} unknowns + size check" if phase == "morris"
                  else f"N = {BUDGET_SOBOL} over {SOBOL_FACTORS} unknowns")
        print(f"projected total {phase} over {len(PAPER_SCENES)} scenes ({design}, "
              f"{budget[phase] * len(PAPER_SCENES)} samples; {len(args.scenes)} scene(s) measured): "
              f"{total[phase]['seconds']:.0f} s at the measured wall rate; " + (
                  f"target <= {target:.0f} s: {'met' if total[phase]['seconds'] <= target else 'NOT met'} on this "
                  "Dask cluster (by wall time: the CPU times leave the workers out)" if args.dask
                  else judge(total[phase], target)))
    print(json.dumps({"size": args.size, "scenes": args.scenes, "trajectories": args.trajectories,
                      "sobol": args.sobol, "dask": args.dask, "morris": morris, "size_check": check,
                      "sobol_phase": sobol, "per_scene": per_scene, "records": records, "projected_how": how,
                      "budget_samples_per_scene": budget,
                      "projected_seconds": {scene: {p: {k: round(v, 1) for k, v in d.items()} for p, d in f.items()}
                                            for scene, f in projected.items()},
                      "projected_total": {p: {k: round(v, 1) for k, v in d.items()} for p, d in total.items()},
                      "targets": {"morris": MORRIS_TARGET_SECONDS, "sobol": SOBOL_TARGET_SECONDS},
                      "per_scene_targets_met": {scene: {phase: projected[scene][phase]["two_core_seconds"] <= target
                                                        for phase, target in (("morris", MORRIS_TARGET_SECONDS),
                                                                              ("sobol", SOBOL_TARGET_SECONDS))}
                                                for scene in PAPER_SCENES},
                      "cpus": os.cpu_count()}, default=float))


if __name__ == "__main__":
    main()
