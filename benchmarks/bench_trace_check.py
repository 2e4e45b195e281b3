"""Cost of the trace integrity check against the simulation it protects.

Renders a scene's trace once (kept in a cache folder between runs, not
timed), then times, on the same trace in one run:

- ``verify_trace``: the XXH3-64 checksums of every array plus the record
  kind/index and offset checks that every ``AccessTrace.load`` performs;
- a plain ``np.load`` of the three arrays (what a load cost before);
- ``coherence.study()`` of one mapping (S) at 1 and 8 processes, the least
  work any command does with a loaded trace.

Prints the three times and the check's share of load + study.

    python benchmarks/bench_trace_check.py [--scene balls] [--size 256] [--cache DIR]
"""
import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from coherence.studies import study
from timing import best_of
from tracer.rendering.render import RenderOptions, render
from tracer.scenes.catalog import load
from tracer.trace.access import AccessTrace, verify_trace
from tracer.trace.check import META_FILE
from tracer.trace.check import read_meta


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="balls")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "coherence-bench-check")
    args = parser.parse_args()
    path = args.cache / f"{args.scene}-{args.size}"
    scene = load(args.scene)
    if not (path / META_FILE).is_file():
        start = time.perf_counter()
        render(scene, options=RenderOptions(size=args.size), trace_path=path)
        print(f"rendered {args.scene} {args.size}x{args.size} in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    trace = AccessTrace.load(path)
    checksums = read_meta(path)["checksums"]
    size_mb = (trace.records.nbytes + trace.pixel_offsets.nbytes + trace.counters.nbytes) / 1e6

    check, _ = best_of(3, lambda: verify_trace(trace, checksums))
    plain, _ = best_of(3, lambda: [np.asarray(np.load(path / f"{name}.npy")) for name in
                             ("pixel_offsets", "records", "counters")])
    study(trace, ["S"], [8], progress=False)  # compile outside the timing
    simulate, _ = best_of(1, lambda: study(trace, ["S"], [8], progress=False))
    print(f"{args.scene} {args.size}x{args.size}: {trace.n_records:,} records, {size_mb:.0f} MB of arrays")
    print(f"integrity check (xxh3 + kinds/indices/offsets): {check:8.3f} s  ({size_mb / check:,.0f} MB/s)")
    print(f"plain np.load of the arrays                  : {plain:8.3f} s")
    print(f"study, mapping S at n = 1 and 8              : {simulate:8.3f} s")
    print(f"check / study = {check / simulate:.3f}; check / (load + study) = {check / (plain + simulate):.3f}")


if __name__ == "__main__":
    main()
