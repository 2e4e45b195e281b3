"""The package versions recorded with every trace and result file."""
from __future__ import annotations

import platform
from importlib.metadata import PackageNotFoundError, version

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
