"""Reliability of the command line: bad input gives one line and the right exit status.

A table of command lines (input -> exit status and a fragment of the message)
runs in subprocesses, so that a segfault (rc 139 or -11) fails the test
instead of killing the test run. Cases are grouped: one subprocess runs a
group through ``analyses.cli.main`` in turn, so the start-up cost is paid
once per group; a crash names the case that was running. Then messages that
fit their cause: memory budgets, out of memory, user errors told from bugs.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from analyses import traces
from tracer.trace.records import RecordKind, pack
from reliability_files import ROOT, flip, png_header, recorded_anew


# ------------------------------------------------------------- command lines
# Each case: (argv, expected exit status, a fragment of stderr), optionally a dict of environment
# variables. Paths are relative to a scratch folder that holds: afile (a regular file), adir (a
# folder), pipe.nff and pipe.txt (FIFOs), trace8 (a tetra 8x8 trace), trace8-flipped (one byte of
# its records flipped), trace8-outside (a record beyond the scene, digests recorded anew), trace8-old
# (no meta.json.xxh3), trace8-f8 (counters' header says float64), trace8-magic (records.npy's magic
# string damaged), addresses.txt,
# bom.txt (addresses after a UTF-8 byte-order mark), binary.toml (not text), petabyte.toml (a
# hierarchy whose 4 PB level cannot be allocated),
# empty.nff, noview.nff and digits.nff (NFF files the strict reader refuses), huge.nff (a
# triangle at 1e300, which the renderer refuses), bom.nff (after a UTF-8 byte-order mark),
# depth0.nff ('# max_depth 0'), negative.nff (Kd -0.5), usemtl.obj (usemtl without mtllib), vn.obj
# (normal 2 of 1), badvt.obj ('f 1/a 2 3'), huge-texture.nff (a 16384 x 16384 PNG header) and
# bom-study.toml (a what-if study without a grid, after a byte-order mark).
CLI_CASES = [
    (["render", "balls", "--size", "20000"], 2, "needs about"),
    (["render", "tetra", "--size", "0"], 2, "--size must be >= 1"),
    (["render", "tetra", "--size", "8", "--png", "nodir/x.png"], 2, "'nodir' does not exist"),
    (["render", "tetra", "--size", "8", "--png", "adir"], 2, "is a folder"),
    (["render", "tetra", "--size", "8", "--trace", "afile"], 2, "is a file, not a trace folder"),
    (["render", "tetra", "--size", "8", "--trace", "adir/../afile/t"], 2, "is a file, not a folder"),
    (["render", "pipe.nff", "--size", "8"], 2, "not a regular file"),
    (["render", "empty.nff", "--size", "8"], 2, "empty.nff:2:1: expected at least one object"),
    (["scene", "noview.nff"], 2, "noview.nff:1:1: expected a view"),
    (["scene", "digits.nff"], 2, "digits.nff:8:3: expected a number"),
    (["render", "huge.nff", "--size", "8"], 2, "row 0 holds 1e+300; coordinates and sizes must be finite"),
    (["render", "tetra", "--size", "8", "--max-depth", "0"], 2, "--max-depth must be in [1, 64]"),
    (["render", "tetra", "--size", "8", "--memory-budget", "0"], 2, "--memory-budget must be > 0"),
    (["render", "tetra", "--size", "8", "--memory-budget", "nan"], 2, "--memory-budget must be > 0"),
    (["render", "tetra", "--size", "4", "--png", "ok.png", "--trace", "ok-trace"], 0, "wrote ok.png"),
    (["scene", "balls", "--max-depth", "0"], 2, "--max-depth must be in [1, 64]"),
    (["scene", "balls", "--nff-out", "nodir/x.nff"], 2, "'nodir' does not exist"),
    (["scene", "pipe.nff"], 2, "not a regular file"),
    (["scene", "adir"], 2, ""),
    (["scene", "missing.nff"], 2, "missing.nff"),
    (["simulate", "afile"], 2, "is a file"),
    (["simulate", "adir"], 2, "lacks meta.json"),
    (["simulate", "trace8", "--csv", "nodir/x.csv"], 2, "'nodir' does not exist"),
    (["simulate", "trace8", "--csv", "adir"], 2, "is a folder"),
    (["simulate", "trace8", "--processes", "0"], 2, "--processes must be >= 1"),
    (["simulate", "trace8", "--cpus", "0"], 2, "--cpus must be >= 1"),
    (["simulate", "trace8", "--background", "-1"], 2, "--background must be >= 0"),
    (["simulate", "trace8", "--quantum", "-1"], 2, "--quantum must be"),
    (["simulate", "trace8", "--background-footprint", "-1"], 2, "--background-footprint must be >= 0"),
    (["simulate", "trace8", "--page-seed", "-1"], 2, "--page-seed must be >= 0"),
    (["simulate", "trace8", "--page-placement", "buddy"], 2, "invalid choice: 'buddy'"),
    (["simulate", "trace8", "--page-placement", "random", "--hierarchy", "alpha21164-dtb", "--csv", "paged.csv"], 0,
     ""),
    (["simulate", "trace8-flipped"], 2, "damaged"),
    (["simulate", "trace8-outside"], 2, "beyond the"),
    (["simulate", "trace8-old"], 2, "re-render it with `coherence render tetra --size 8 --trace trace8-old`"),
    (["simulate", "trace8-f8"], 2, "counters.npy's header does not match its checksum"),
    (["simulate", "trace8-magic"], 2, "records.npy is damaged (not a .npy file"),
    (["simulate", "trace8", "--mapping", "S", "--processes", "2", "--csv", "runs.csv"], 0, ""),
    (["cachesim", "pipe.txt"], 2, "not a regular file"),
    (["cachesim", "adir"], 2, "is a folder"),
    (["cachesim", "missing.txt"], 2, "no such file"),
    (["cachesim", "addresses.txt", "--csv", "nodir/x.csv"], 2, "'nodir' does not exist"),
    (["cachesim", "addresses.txt", "--hierarchy", "pipe.txt.toml"], 2, ""),
    (["cachesim", "addresses.txt", "--hierarchy", "binary.toml"], 2, "binary.toml:1: not a text file"),
    (["cachesim", "addresses.txt", "--hierarchy", "petabyte.toml"], 2, "use smaller caches"),
    (["cachesim", "bom.txt"], 0, ""),
    (["whatif", "--grid", "L1.size=4KB", "--grid", "L1.size=8KB"], 2, "--grid L1.size is given more than once"),
    (["whatif", "latency", "--jobs", "0"], 2, "--jobs must be >= 1"),
    (["whatif", "latency", "--jobs", "-1"], 2, "--jobs must be >= 1"),
    (["whatif", "latency", "--processes", "0"], 2, "--processes must be >= 1"),
    (["whatif", "latency", "--size", "20000"], 2, "needs about"),
    (["whatif", "latency", "--out", "afile"], 2, "is not a folder"),
    (["whatif", "--file", "pipe.txt"], 2, "not a regular file"),
    (["whatif", "latency", "--cache", "afile"], 2, "is a file, not a folder"),
    (["whatif", "latency", "--dask", "tcp://127.0.0.1:9"], 2, "pip install 'raytrace-coherence[cluster]'",
     {"BLOCK_DISTRIBUTED": "1"}),
    (["report", "tetra", "--size", "8", "--cache", "afile"], 2, "cache folder 'afile'"),
    (["report", "tetra", "--size", "8"], 2, "$COHERENCE_CACHE 'afile'", {"COHERENCE_CACHE": "afile"}),
    (["report", "tetra", "--size", "20000"], 2, "needs about"),
    (["report", "tetra", "--size", "8", "--max-processes", "0"], 2, "--max-processes must be >= 1"),
    (["report", "tetra", "--size", "8", "--processes", "0"], 2, "--processes must be >= 1"),
    (["report", "pipe.nff", "--size", "8"], 2, "not a regular file"),
    (["report", "tetra", "--size", "32", "--mappings", "DB", "--max-processes", "2", "--out", "one-mapping"], 0, ""),
    (["paper", "--size", "8", "--cache", "afile"], 2, "is a file, not a folder"),
    (["paper", "--size", "8", "--page-seed", "-1"], 2, "--page-seed must be >= 0"),
    (["report", "tetra", "--size", "8", "--background-footprint", "-1"], 2, "--background-footprint must be >= 0"),
    (["report", "tetra", "--size", "8", "--page-placement", "buddy"], 2, "invalid choice: 'buddy'"),
    (["paper", "--size", "20000"], 2, "needs about"),
    (["scene", "bom.nff"], 0, ""),
    (["scene", "depth0.nff"], 2, "depth0.nff:9:13: expected a max_depth in 1..64, found '0'"),
    (["render", "depth0.nff", "--size", "4"], 2, "depth0.nff:9:13: expected a max_depth in 1..64"),
    (["scene", "negative.nff"], 2, "negative.nff:8:9: expected Kd >= 0"),
    (["scene", "usemtl.obj"], 0, "usemtl.obj:1: 'usemtl red' names a material, but no 'mtllib'"),
    (["scene", "vn.obj"], 2, "vn.obj:5: expected a normal index in 1..1 or negative, found '1//2'"),
    (["scene", "badvt.obj"], 2, "badvt.obj:4: expected a texture coordinate index, found '1/a'"),
    (["scene", "huge-texture.nff"], 2, "huge.png' is 16384 x 16384 (268,435,456 texels); a texture may hold at most"),
    (["render", "huge-texture.nff", "--size", "4"], 2, "huge.png' is 16384 x 16384"),
    (["render", "tetra", "--size", "8", "--png", "counted.png", "--memory-budget", "0.001"], 0, "wrote counted.png"),
    (["render", "tetra", "--size", "8", "--png", "x.jpg"], 2, "--png 'x.jpg' must end in .png"),
    (["report", "tetra", "--size", "8", "--out", ""], 2, "output folder '' is an empty name"),
    (["whatif", "latency", "--out", ""], 2, "output folder '' is an empty name"),
    (["paper", "--size", "8", "--out", ""], 2, "output folder '' is an empty name"),
    (["whatif", "--file", "binary.toml"], 2, "binary.toml:1: not a text file (byte 0 is not UTF-8)"),
    (["whatif", "--file", "bom-study.toml"], 2, "bom-study.toml: needs a [grid] table"),
]

_RUNNER = textwrap.dedent('''
    import contextlib, io, json, os, sys
    cases = json.load(sys.stdin)
    if os.environ.get("BLOCK_DISTRIBUTED_ALL"):
        sys.modules["distributed"] = None
    from analyses.cli import main
    for number, (argv, env) in enumerate(cases):
        with open("running.txt", "w") as status:
            status.write(" ".join(argv))
        saved = {key: os.environ.get(key) for key in env}
        os.environ.update(env)
        blocked = sys.modules.get("distributed", False)
        if env.get("BLOCK_DISTRIBUTED"):
            sys.modules["distributed"] = None
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(argv)
            except SystemExit as exit:
                status = exit.code
            except BaseException as error:
                status = "traceback"
                err.write(f"{type(error).__name__}: {error}")
        if env.get("BLOCK_DISTRIBUTED"):
            if blocked is False:
                del sys.modules["distributed"]
            else:
                sys.modules["distributed"] = blocked
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        print(json.dumps({"status": status, "stderr": err.getvalue()}), flush=True)
''')


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """The scratch folder the table's paths are relative to."""
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    folder = tmp_path_factory.mktemp("cli")
    (folder / "afile").write_text("x\n")
    (folder / "adir").mkdir()
    os.mkfifo(folder / "pipe.nff")
    os.mkfifo(folder / "pipe.txt")
    os.mkfifo(folder / "pipe.txt.toml")
    (folder / "addresses.txt").write_text("0\n64\n4096\n0\n")
    (folder / "binary.toml").write_bytes(b"\xff\xfe\x00n\x00a")
    (folder / "bom.txt").write_bytes(b"\xef\xbb\xbf0\n64\n")
    (folder / "petabyte.toml").write_text('[[levels]]\nname = "L1"\nsize = 4503599627370496\nline_size = 64\n')
    (folder / "empty.nff").write_text("# nothing but a comment\n")
    (folder / "noview.nff").write_text("s 0 0 0 1\n")
    view = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 8 8\n"
    (folder / "digits.nff").write_text(view + "s 1_0 0 0 1\n")
    (folder / "huge.nff").write_text(view + "p 3 0 0 0 1e300 0 0 0 1e300 0\n")
    (folder / "bom.nff").write_bytes(b"\xef\xbb\xbf" + (view + "s 0 0 0 1\n").encode())
    (folder / "depth0.nff").write_text(view + "s 0 0 0 1\n# max_depth 0\n")
    (folder / "negative.nff").write_text(view + "f 1 1 1 -0.5 0 0 0 1\ns 0 0 0 1\n")
    triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    (folder / "usemtl.obj").write_text("usemtl red\n" + triangle + "f 1 2 3\n")
    (folder / "vn.obj").write_text(triangle + "vn 0 0 1\nf 1//2 2//1 3//1\n")
    (folder / "badvt.obj").write_text(triangle + "f 1/a 2 3\n")
    (folder / "huge.png").write_bytes(png_header(16384, 16384))
    (folder / "bom-study.toml").write_bytes(b"\xef\xbb\xbfjobs = 1\n")
    (folder / "huge-texture.nff").write_text(view + "texture big huge.png\nusetexture big\ns 0 0 0 1\n")
    render(load("tetra"), options=RenderOptions(size=8), trace_path=folder / "trace8")
    for name in ("trace8-flipped", "trace8-outside", "trace8-old", "trace8-f8", "trace8-magic"):
        shutil.copytree(folder / "trace8", folder / name)
    flip(folder / "trace8-flipped" / "records.npy", 9)
    outside = folder / "trace8-outside"
    records = np.load(outside / "records.npy")
    triangles = json.loads((outside / "meta.json").read_text())["metadata"]["record_counts"]["triangle"]
    records[3] = pack(RecordKind.TRIANGLE, triangles)
    recorded_anew(outside, records=records)
    (folder / "trace8-old" / "meta.json.xxh3").unlink()
    counters = folder / "trace8-f8" / "counters.npy"
    counters.write_bytes(counters.read_bytes().replace(b"'<i8'", b"'<f8'", 1))
    (folder / "trace8-magic" / "records.npy").write_bytes(b"\x93NUMPX" + (folder / "trace8" / "records.npy").read_bytes()[6:])
    return folder


def run_cli_cases(folder: Path, cases, timeout: float = 900):
    """Run ``cases`` ((argv, env) pairs) in one subprocess; a list of {status, stderr}.

    Fails the calling test when the subprocess dies (a segfault: rc 139 or
    -11), naming the case that was running.
    """
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "COHERENCE_CACHE": str(folder / "cache"), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", _RUNNER], input=json.dumps([list(case) for case in cases]),
                          capture_output=True, text=True, cwd=folder, env=env, timeout=timeout)
    results = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{\"status\"")]
    if done.returncode != 0:
        running = (folder / "running.txt").read_text()
        kind = "segfault" if done.returncode in (139, -11) else f"rc {done.returncode}"
        pytest.fail(f"the runner died ({kind}) during: coherence {running}\n{done.stderr[-2000:]}")
    return results


def test_command_line_table(scratch):
    cases = [(case[0], case[3] if len(case) > 3 else {}) for case in CLI_CASES]
    results = run_cli_cases(scratch, cases)
    failures = []
    for case, result in zip(CLI_CASES, results):
        argv, status, fragment = case[:3]
        lines = [line for line in result["stderr"].splitlines() if "error" in line or "Error" in line]
        if (result["status"] != status or fragment not in result["stderr"] or "Traceback" in result["stderr"]
                or len(lines) > 1):
            failures.append(f"coherence {' '.join(argv)}: want {status} with {fragment!r}, got "
                            f"{result['status']}: {result['stderr'][-400:]!r}")
    assert not failures, "\n".join(failures)
    assert (scratch / "one-mapping" / "index.html").is_file()
    assert not (scratch / "nodir").exists()


def _cli(*argv, **options):
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.Popen([sys.executable, "-m", "analyses", *argv], env=env, text=True, **options)


def test_ctrl_c_prints_one_line_and_dies_by_sigint(tmp_path):
    import signal
    import time

    process = _cli("render", "balls", "--size", "2048", "--no-log", stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                   cwd=tmp_path)
    deadline = time.monotonic() + 120
    seen = ""
    while "rendering" not in seen and time.monotonic() < deadline:  # interrupt in the middle of the work
        seen += process.stderr.readline()
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == -signal.SIGINT, err  # killed by SIGINT: a shell reports 130
    said = err.strip().splitlines()  # numba compiling (a cold cache) adds the line that says it holds Ctrl-C
    assert said[-1] == "coherence render: interrupted"
    assert all(line.startswith("coherence render: interrupt received;") for line in said[:-1]) and len(said) <= 2


def test_broken_pipe_exits_quietly(tmp_path):
    process = _cli("scene", "balls", "--json", stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    process.stdout.close()  # the reader goes away before the output comes (like '| head -0'), at start-up
    err = process.stderr.read()
    process.wait(timeout=120)
    assert process.returncode == 141 and err == ""


# A process without work once crashed the simulation kernel; these cases run
# apart so that a segfault there would not hide the others.
NO_WORK_CASES = [
    (["report", "tetra", "--size", "15", "--mappings", "S", "--max-processes", "16", "--out", "small"], 0, ""),
    (["simulate", "trace8", "--mapping", "S", "--processes", "9"], 0, ""),
    (["simulate", "trace8", "--mapping", "P", "--processes", "65"], 0, ""),
]


def test_processes_without_work_do_not_crash(scratch):
    results = run_cli_cases(scratch, [(case[0], {}) for case in NO_WORK_CASES])
    assert [result["status"] for result in results] == [case[1] for case in NO_WORK_CASES]


def test_a_trace_that_will_not_fit_on_disk_is_refused_before_rendering(tmp_path, monkeypatch):
    import shutil

    from analyses import output

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=10_000))
    with pytest.raises(ValueError, match=r"the trace of tetra at 64x64 needs about [\d.]+ kB of disk space in .*, "
                                         r"9\.8 kB free"):
        traces.cached_trace("tetra", 64, cache_dir=tmp_path, progress=False)
    assert not list((tmp_path / "traces").iterdir())
    output.check_free_space("small", tmp_path, 5_000)  # what fits passes


# ------------------------------------------------------------- messages that fit the cause
def _scenes_help(capsys) -> str:
    from analyses.cli import main

    with pytest.raises(SystemExit):
        main(["paper", "--help"])
    text = capsys.readouterr().out
    return " ".join(text.split("--scenes SCENE [SCENE ...]")[-1].split("\n  --", 1)[0].split())


def test_paper_help_lists_only_the_scenes_paper_accepts(capsys):
    """Every scene ``paper --help`` names for --scenes is accepted, and all the study's are named.

    Fails if the --scenes help says ``%(scenes)s`` (every named scene, textured ones too) again.
    """
    import re

    from analyses.paper_study import check_scenes
    from tracer.scenes.catalog import NAMED_SCENES, PAPER_SCENES

    listed = [word for word in re.findall(r"[a-z][a-z-]*", _scenes_help(capsys)) if word in NAMED_SCENES]
    assert sorted(listed) == sorted(PAPER_SCENES)
    assert check_scenes(listed) == listed


@pytest.mark.parametrize("command, runs_at_once", [("report", 1), ("paper", 2)])  # the paper maps two scenes at once
def test_the_least_memory_budget_named_is_the_one_the_run_needs(command, runs_at_once):
    """The least --memory-budget the command line names passes both its own check and the run's
    (``memory_shares``), one MB less is refused by the command line, and a budget too big is not told
    to be "at least" anything.

    Fails if ``memory_budget_bytes`` checks against ``MIN_MEMORY_BUDGET`` alone again (it then passes
    704 MB, which the run refuses for any image).
    """
    import re

    from analyses.cli import build_parser
    from analyses.commands.options import memory_budget_bytes
    from analyses.memory_budget import memory_shares

    parser = build_parser()
    for size in (64, 700):
        args = parser.parse_args([command, "--size", str(size), "--memory-budget", "704"])
        with pytest.raises(ValueError, match="--memory-budget must be at least") as refused:
            memory_budget_bytes(args)
        least = int(re.search(r"at least (\d+) MB", str(refused.value)).group(1))
        args.memory_budget = float(least)
        memory_shares(memory_budget_bytes(args), size * size, runs_at_once)
        args.memory_budget = least - 1.0
        with pytest.raises(ValueError, match=f"at least {least} MB"):
            memory_budget_bytes(args)
    for value, said in ((2e12, "at most"), (float("nan"), "a number")):
        args.memory_budget = value
        with pytest.raises(ValueError, match=f"--memory-budget must be {said}"):
            memory_budget_bytes(args)


def test_small_sizes_are_not_told_as_zero_gigabytes(tmp_path, monkeypatch):
    """The disk check names sizes in a unit that shows them: 50,000 bytes needed, 10,000 free.

    Fails if ``check_free_space`` formats both sizes in GB again ("0.0 GB ... 0.0 GB free").
    """
    import re
    import shutil

    from analyses import output

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage._replace(free=10_000))
    with pytest.raises(ValueError) as refused:
        output.check_free_space("the file", tmp_path, 50_000)
    units = {"bytes": 1, "kB": 2**10, "MB": 2**20, "GB": 2**30}
    sizes = [float(number) * units[unit] for number, unit in re.findall(r"([\d.]+) (bytes|kB|MB|GB)", str(refused.value))]
    assert len(sizes) == 2 and abs(sizes[0] - 50_000) < 0.01 * 50_000 and abs(sizes[1] - 10_000) < 0.01 * 10_000


@pytest.mark.parametrize("argv, hint", [(["cachesim", "addresses.txt"], False),
                                        (["report", "tetra", "--size", "8"], True)])
def test_out_of_memory_names_size_only_where_there_is_one(monkeypatch, capsys, argv, hint):
    """A MemoryError suggests a smaller --size only in a command that has --size.

    Fails if the command line's MemoryError message names --size whatever the command again.
    """
    import importlib

    from analyses.cli import main

    def run(args):
        raise MemoryError

    monkeypatch.setattr(importlib.import_module(f"analyses.commands.{argv[0]}"), "run", run)
    assert main(argv) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "out of memory" in said[0] and ("--size" in said[0]) == hint


@pytest.mark.parametrize("error, status", [("input", 2), (ZeroDivisionError("division by zero"), 1),
                                           (TypeError("unsupported operand"), 1), (IndexError("out of range"), 1),
                                           (ValueError("setting an array element with a sequence"), 1)])
def test_user_errors_and_bugs_are_told_apart(monkeypatch, capsys, error, status):
    """An InputError (the toolkit's own check) exits 2 with one line; any other exception is a bug: exit 1,
    its traceback, and a last line that says "internal error" and names it.

    Fails if ``main`` no longer catches ``Exception`` as an internal error (the exception escapes it), or
    takes a bare ValueError (numpy's, a bug's) for the user's again.
    """
    from analyses.cli import main
    from analyses.commands import cachesim
    from rtcommon.validate import InputError

    raised = InputError("--thing must be >= 1, got 0") if error == "input" else error

    def run(args):
        raise raised

    monkeypatch.setattr(cachesim, "run", run)
    assert main(["cachesim", "addresses.txt"]) == status
    said = capsys.readouterr().err.strip().splitlines()
    if status == 2:
        assert said == ["coherence cachesim: error: --thing must be >= 1, got 0"]
    else:
        assert said[0].startswith("Traceback") and f"{type(raised).__name__}: {raised}" in said[-2]
        assert said[-1] == f"coherence cachesim: internal error (a bug in the toolkit, not in what it was given): " \
                           f"{type(raised).__name__}: {raised}"


def test_the_toolkit_raises_no_bare_value_error():
    """Every error the toolkit raises for bad input is an InputError, which the command line tells apart
    from a bug's ValueError (exit 2 with one line, not exit 1 with a traceback).

    Fails if any library module raises ``ValueError(...)`` itself, or defines an error class on
    ``ValueError`` rather than ``InputError``, as every check did before.
    """
    import re

    found = []
    for package in ("tracer", "cachesim", "coherence", "analyses", "rtcommon"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"raise ValueError\(|^class (?!InputError\()\w+\(ValueError\)", line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "raise InputError (rtcommon.validate) instead:\n" + "\n".join(found)
