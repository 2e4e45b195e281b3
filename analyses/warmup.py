"""Compile the simulation's kernels in a second process while the first one renders.

The first report after an install compiles the tracer (the kd-tree builder
and the render kernel) and then the simulation (the schedule's event loop
with its cache paths, the record-to-line conversion, reuse distances), each
for a good part of a minute. Numba compiles under one lock
per process, so a thread cannot overlap the two; a second process can.

:func:`simulation_warm_up` starts ``python -m analyses.warmup`` when the
simulation kernels are not in numba's on-disk cache yet. The child runs the
report's simulation steps on a tiny synthetic trace with the report's own
hierarchy, layout, cost model, machine and mappings, loaded through the same
memory-mapped trace files as a real one, so the kernels it compiles have the
types the report will ask for and land in the shared cache. The report waits
for the child before it simulates, then loads those kernels instead of
compiling them.

The warm-up only ever saves time: the child writes nothing but numba's
cache (whose files numba replaces atomically), its output is discarded, and
if it fails (a mapping that cannot be pickled, say) or a kernel's types
differ, the report compiles that kernel itself as before. Results never
depend on it.
"""
from __future__ import annotations

import dataclasses
import os
import pickle
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["simulation_kernels_cached", "simulation_warm_up", "synthetic_trace", "WARM_UP_TIMEOUT"]

#: Seconds the report waits for the child before it stops it and compiles alone.
WARM_UP_TIMEOUT = 300.0


def simulation_kernels_cached() -> bool:
    """Whether numba's on-disk cache already holds the schedule's event loop.

    True too when there is nothing to compile (``NUMBA_DISABLE_JIT``) or
    the cache cannot be inspected.
    """
    from coherence.scheduler import run_schedule

    cache = getattr(run_schedule, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    return index is None or os.path.exists(index)


class _WarmUp:
    """A running warm-up child, or none (``process`` None)."""

    def __init__(self, process: subprocess.Popen | None):
        self.process = process

    def wait(self, timeout: float = WARM_UP_TIMEOUT, progress: bool = False) -> int | None:
        """Let the child finish compiling (stop it after ``timeout`` seconds).

        With ``progress``, say on stderr why the report pauses. Returns the
        child's exit status (None if there was no child or it was stopped).
        """
        if self.process is None:
            return None
        if progress and self.process.poll() is None:
            print("compiling the simulation kernels (first run after an install only)...", file=sys.stderr,
                  flush=True)
        try:
            status = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            status = None
            self.stop()
        self.process = None
        return status

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process = None


@contextmanager
def simulation_warm_up(hierarchy, layout, cost, machine, mappings, *, enabled: bool = True):
    """Compile the simulation kernels in a child process during the ``with`` block.

    Parameters
    ----------
    hierarchy : cachesim.Hierarchy
    layout : coherence.layout.MemoryLayout
    cost : coherence.cost.CostModel
    machine : coherence.simulation.Machine
    mappings : sequence of coherence.mappings.Mapping
        The objects the report will simulate with.
    enabled : bool
        False: do nothing (a study spread over a cluster compiles on the
        workers).

    Yields
    ------
    object
        Call its ``wait()`` before simulating. On leaving the block the
        child is stopped if it still runs.
    """
    warm = _WarmUp(None)
    if enabled and not simulation_kernels_cached():
        try:
            payload = pickle.dumps((hierarchy, layout, cost, machine, list(mappings)))
        except Exception:  # a mapping defined where pickle cannot reach: compile in the report instead
            payload = None
        if payload is not None:
            warm = _WarmUp(_start_child(payload))
    try:
        yield warm
    finally:
        warm.stop()


def _start_child(payload: bytes) -> subprocess.Popen | None:
    env = dict(os.environ, NUMBA_NUM_THREADS="1")  # it compiles; the cores are for the render
    project = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (project, env.get("PYTHONPATH")) if p)
    try:
        process = subprocess.Popen([sys.executable, "-m", "analyses.warmup"], stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        process.stdin.write(payload)
        process.stdin.close()
    except OSError:
        return None
    return process


def synthetic_trace(folder, width: int = 6, height: int = 5, seed: int = 0):
    """A small random trace of every scene record kind, saved to ``folder`` and memory-mapped back.

    Its arrays have the dtypes, layouts and read-only flags of a cached
    render's, which is what the compiled kernels are specialised on. Some
    records are writes, as in the study-era workload.
    """
    from tracer.trace.records import RecordKind, pack
    from tracer.trace.access import COUNTER_NAMES, AccessTrace

    rng = np.random.default_rng(seed)
    kinds = [RecordKind.KD_NODE, RecordKind.INDEX_ENTRY, RecordKind.SPHERE, RecordKind.TRIANGLE,
             RecordKind.POLYGON, RecordKind.MATERIAL, RecordKind.LIGHT, RecordKind.RAY_STACK,
             RecordKind.HIT_RECORD, RecordKind.SHADING_TEMP, RecordKind.FRAME_BUFFER]
    n_each = 40
    lengths = rng.integers(1, 30, width * height)
    chosen = rng.choice(np.array(kinds, dtype=np.int64), int(lengths.sum()))
    writes = (chosen >= RecordKind.RAY_STACK) & (rng.random(chosen.size) < 0.5)
    records = pack(chosen, rng.integers(0, n_each, chosen.size), writes)
    offsets = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
    counters = rng.integers(0, 50, (width * height, len(COUNTER_NAMES))).astype(np.int64)
    metadata = {"record_counts": {kind.name.lower(): n_each for kind in kinds}}
    trace = AccessTrace(offsets, records, counters, width, height, metadata)
    return AccessTrace.load(trace.save(Path(folder) / "trace"), mmap=True)


def _compile(hierarchy, layout, cost, machine, mappings) -> None:
    """The report's simulation steps on a synthetic trace (see :mod:`analyses.report`)."""
    from coherence.missmap import miss_map
    from coherence.studies import Execution, place_layout, study
    from tracer.trace.access import COUNTER_NAMES

    from analyses.report_curves import miss_ratio_curves

    if layout.heap is not None:
        # the synthetic trace has no scene to allocate a heap from; the kernels are the same without it
        layout = dataclasses.replace(layout, heap=None)
    with tempfile.TemporaryDirectory(prefix="coherence-warmup-") as folder:
        trace = synthetic_trace(folder)
        placed = place_layout(layout, trace)
        study(trace, mappings, (1, 2), hierarchy=hierarchy, layout=layout, cost=cost, machine=machine,
              progress=False, execution=Execution(n_jobs=1))
        miss_map(trace, mappings[0], 2, hierarchy=hierarchy, layout=layout, cost=cost, machine=machine)
        miss_ratio_curves(trace, placed, mappings, hierarchy, False)
        cost.compute_cycles(trace.counters, COUNTER_NAMES)
        del trace, placed  # the memory maps close before the folder goes


if __name__ == "__main__":
    _compile(*pickle.loads(sys.stdin.buffer.read()))
