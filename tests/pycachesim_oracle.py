"""Run pycachesim (test-only oracle) in a subprocess on a stream.

pycachesim's import name is ``cachesim`` too, so it lives in a folder of its
own (``.oracle/pycachesim`` by default, or ``$PYCACHESIM_DIR``), installed by
``tests/run_tests.sh`` with ``pip install --target``, and never shares our
interpreter. Arrays and results travel through files.
"""
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
ORACLE_DIR = Path(os.environ.get("PYCACHESIM_DIR", ROOT / ".oracle" / "pycachesim"))
RUNNER = Path(__file__).resolve().parent / "oracle" / "run_pycachesim.py"


def available() -> bool:
    return (ORACLE_DIR / "cachesim" / "__init__.py").is_file()


def run(addresses, hierarchy) -> dict:
    """Counts per level from pycachesim: accesses, hits, misses, evictions, seconds."""
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        np.save(folder / "addresses.npy", np.asarray(addresses, dtype=np.uint64))
        (folder / "config.json").write_text(json.dumps(hierarchy.to_dict()))
        environment = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
        completed = subprocess.run(
            [sys.executable, str(RUNNER), str(ORACLE_DIR), str(folder / "config.json"),
             str(folder / "addresses.npy"), str(folder / "out.json")],
            cwd=folder, env=environment, capture_output=True, text=True, check=False)
        if completed.returncode != 0:
            raise RuntimeError(f"pycachesim run failed:\n{completed.stderr}")
        return json.loads((folder / "out.json").read_text())
