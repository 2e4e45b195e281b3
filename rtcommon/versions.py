"""The package versions recorded with every trace and result file."""
from __future__ import annotations

import platform
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

#: Distributions whose versions can change a trace or a result.
PACKAGES = ("raytrace-coherence", "numpy", "numba", "pandas", "scipy")


def package_versions() -> dict[str, str]:
    """``{"python": ..., <package>: ...}`` for Python and :data:`PACKAGES`."""
    versions = {"python": platform.python_version()}
    for package in PACKAGES:
        try:
            versions[package] = version(package)
        except PackageNotFoundError:
            versions[package] = "not installed"
    return versions


def source_commit() -> str:
    """The git commit of the checkout this project's code is imported from.

    ``"<hash>+dirty"`` when a tracked file differs from that commit, and
    ``"unknown"`` when the code is not in a git checkout or git cannot be run.
    """
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=30)
        if head.returncode != 0:
            return "unknown"
        status = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    commit = head.stdout.strip()
    return commit + "+dirty" if status.returncode != 0 or status.stdout.strip() else commit
