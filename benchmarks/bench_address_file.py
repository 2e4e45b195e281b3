"""Peak memory of reading a text address file, against the same read of a 1-line file.

Writes a seeded text file of N decimal addresses (default 20 million, about
270 MB), then reads it and a 1-line file with ``cachesim.read_addresses``,
each in a fresh subprocess (numba's cache warmed first), and prints both
peak resident sizes, their difference, the ``.npy`` size of the addresses
(8 bytes each) and the target: at most twice that size more than the 1-line
read. Ends with one JSON line.

    python benchmarks/bench_address_file.py [--lines N] [--folder DIR]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
_READ = """
import resource, sys, time
from cachesim import read_addresses
start = time.perf_counter()
addresses = read_addresses(sys.argv[1])
seconds = time.perf_counter() - start
print(addresses.size, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, seconds)
"""


def write_addresses(path: Path, n_lines: int, seed: int = 2026) -> None:
    """``n_lines`` seeded decimal addresses below 2**40, one per line, written a million at a time."""
    rng = np.random.default_rng(seed)
    with open(path, "w") as stream:
        for start in range(0, n_lines, 1_000_000):
            values = rng.integers(0, 2**40, min(1_000_000, n_lines - start))
            stream.write("\n".join(map(str, values.tolist())) + "\n")


def peak_of_read(path: Path) -> tuple[int, int, float]:
    """(addresses read, peak resident bytes, seconds of the read) of a fresh process reading ``path``."""
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    done = subprocess.run([sys.executable, "-c", _READ, str(path)], capture_output=True, text=True, env=env,
                          check=True)
    count, peak, seconds = done.stdout.split()
    return int(count), int(peak), float(seconds)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lines", type=int, default=20_000_000)
    parser.add_argument("--folder", help="where to write the text file (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.folder) as folder:
        one = Path(folder) / "one.txt"
        one.write_text("4096\n")
        big = Path(folder) / "big.txt"
        write_addresses(big, args.lines)
        peak_of_read(one)  # compile (or load) the kernels outside the measurement
        _, one_peak, _ = peak_of_read(one)
        count, big_peak, seconds = peak_of_read(big)
        text_bytes = big.stat().st_size
    npy_bytes = 8 * count + 128
    extra = big_peak - one_peak
    mib = 2**20
    print(f"text file : {count:,} addresses, {text_bytes / mib:,.0f} MiB; .npy size {npy_bytes / mib:,.0f} MiB")
    print(f"peak RSS  : 1-line file {one_peak / mib:,.0f} MiB, big file {big_peak / mib:,.0f} MiB "
          f"(read in {seconds:.2f} s, {count / seconds / 1e6:.1f} M lines/s)")
    print(f"extra     : {extra / mib:,.0f} MiB = {extra / npy_bytes:.2f}x the .npy size")
    print(f"target: at most 2x the .npy size more than a 1-line file: {'met' if extra <= 2 * npy_bytes else 'not met'}")
    print(json.dumps({"lines": count, "text_bytes": text_bytes, "npy_bytes": npy_bytes, "one_line_peak": one_peak,
                      "peak": big_peak, "extra_over_npy": extra / npy_bytes, "read_seconds": seconds}))


if __name__ == "__main__":
    main()
