"""Digests of real outputs, to prove a refactor changed nothing.

    python tests/output_digests.py OUT.txt [--work DIR]

Runs a fixed set of command-line jobs in a scratch folder and writes one line
per output file: ``sha256  path``. Arrays (``.npy``) are digested by dtype,
shape and bytes; CSV files byte for byte; JSON files after dropping what
differs between two runs of the same commit: ``versions`` blocks, wall times
(``timings``, ``*seconds``), the scratch folder's name in paths, and the
hash part of ``trace_key`` (it hashes the tracer's source by design, so any
edit of ``tracer/`` changes it).
The jobs: each paper scene rendered with its trace at 64x64 (SAH and median
kd-trees for balls), ``simulate`` on the balls trace, ``paper`` at 64x64,
``report balls`` at 128x128 and two ``whatif`` studies at 32x32.

Compare two digest files with ``diff``; any line that differs names the output
that changed.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

SCENES = ("balls", "tetra", "shell", "room", "fluid")


# The command-line front end: analyses.cli once the CLI sits at the top layer.
CLI_MODULE = "analyses" if importlib.util.find_spec("analyses.cli") else "coherence"


def jobs(work: pathlib.Path) -> list[list[str]]:
    cache = ["--cache", str(work / "cache")]
    out = []
    for scene in SCENES:
        out.append(["render", scene, "--size", "64", "--trace", str(work / f"trace-{scene}"), "--json"])
    out.append(["render", "balls", "--size", "64", "--kd", "median", "--trace", str(work / "trace-balls-median")])
    out.append(["simulate", str(work / "trace-balls"), "--processes", "1", "3", "8", "12",
                "--csv", str(work / "simulate" / "results.csv"), "--processes-csv",
                str(work / "simulate" / "processes.csv")])
    out.append(["paper", "--size", "64", "--out", str(work / "paper"), *cache])
    out.append(["report", "balls", "--size", "128", "--out", str(work / "report"), *cache])
    for study in ("assoc", "latency"):
        out.append(["whatif", study, "--size", "32", "--jobs", "1", "--out", str(work / f"whatif-{study}"), *cache])
    return out


# JSON keys renamed on purpose, new name -> old name: digested under the old name, so that a
# rename alone leaves the reference file as it was while every value is still compared.
RENAMED_KEYS: dict[str, str] = {}


def _stable(value, work: str):
    """The JSON value without what changes from run to run of one commit.

    ``meta_checksum`` hashes the trace metadata, which holds the command line
    and so the scratch folder; the arrays' own checksums stay in.
    ``memory_shares`` and ``runs_at_once`` follow the machine's CPU count
    (:func:`analyses.memory_budget.runs_at_once`), and results do not depend
    on them.
    """
    if isinstance(value, dict):
        return {RENAMED_KEYS.get(k, k): (v.rsplit("-", 1)[0] if k == "trace_key" else _stable(v, work))
                for k, v in value.items()
                if k not in ("versions", "timings", "meta_checksum", "memory_shares", "runs_at_once")
                and not k.endswith("seconds")}
    if isinstance(value, list):
        return [_stable(v, work) for v in value]
    if isinstance(value, str):
        return value.replace(work, "<work>")
    return value


def digest(path: pathlib.Path, work: pathlib.Path) -> str | None:
    if path.suffix == ".npy":
        array = np.load(path, mmap_mode="r")
        h = hashlib.sha256(f"{array.dtype.str}{array.shape}".encode())
        h.update(np.ascontiguousarray(array).tobytes())
        return h.hexdigest()
    if path.suffix == ".csv":
        return hashlib.sha256(path.read_bytes()).hexdigest()
    if path.suffix == ".json":
        data = _stable(json.loads(path.read_text()), str(work))
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
    return None


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="digest file to write")
    parser.add_argument("--work", help="scratch folder (default: a temporary one)")
    parser.add_argument("--digest-only", action="store_true", help="digest the outputs already in --work")
    args = parser.parse_args(argv)
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="digests-"))
    (work / "simulate").mkdir(parents=True, exist_ok=True)
    for job in [] if args.digest_only else jobs(work):
        name = job[0] + " " + job[1]
        print("running", name, file=sys.stderr, flush=True)
        done = subprocess.run([sys.executable, "-m", CLI_MODULE, *job], capture_output=True, text=True)
        if done.returncode != 0:
            print(done.stdout, done.stderr, file=sys.stderr)
            return 1
        if "--json" in job and job[0] == "render":
            (work / f"render-{job[1]}.json").write_text(done.stdout)
    lines = []
    for path in sorted(work.rglob("*")):
        rel = path.relative_to(work)
        if rel.parts[0] == "cache" or not path.is_file():
            continue
        value = digest(path, work)
        if value is not None:
            lines.append(f"{value}  {rel.as_posix()}")
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"{len(lines)} outputs digested into {args.out} (work folder {work})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
