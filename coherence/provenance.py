"""Versions and parameters recorded beside every result file.

Result files are written atomically (a temporary name beside the target,
then a rename), so a crash never leaves half a file. Each table gets a
sidecar ``<name>.meta.json`` with the parameters and package versions that
produced it; no timestamps, so the same inputs give byte-identical outputs.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from rtcommon.files import write_text_atomic
from rtcommon.versions import package_versions

#: What the sidecar of a result file adds to its name: ``runs.csv`` -> ``runs.csv.meta.json``.
META_SUFFIX = ".meta.json"


def meta_path(path: str | os.PathLike) -> Path:
    """The sidecar of result file ``path``: the same name with :data:`META_SUFFIX` added."""
    path = Path(path)
    return path.with_name(path.name + META_SUFFIX)


def provenance(**parameters) -> dict:
    """``{"parameters": ..., "versions": ...}`` for a result file."""
    return {"parameters": parameters, "versions": package_versions()}


def write_csv_atomic(table, path: str | os.PathLike, meta: dict) -> Path:
    """Write a DataFrame to CSV and ``meta`` to ``<path>.meta.json``, both atomically.

    Raises
    ------
    FileNotFoundError
        If the target folder does not exist.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path}: folder {path.parent} does not exist")
    write_text_atomic(path, table.to_csv(index=False, lineterminator="\n"))
    write_text_atomic(meta_path(path), json.dumps(meta, indent=2) + "\n")
    return path
