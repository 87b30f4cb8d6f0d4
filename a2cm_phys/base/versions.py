"""The package's version, and the versions of the libraries a run's floats depend on."""

from __future__ import annotations

import sys
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("a2cm_phys")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

VERSIONED = ("a2cm_phys", "numpy", "torch", "pymunk", "scipy")
"""The packages whose versions a run records: a rebuilt environment can change a run's
floats (the same seed's long runs then differ), and the record says which one ran."""


def library_versions() -> dict[str, str]:
    """Python's version and those of :data:`VERSIONED` (``"absent"`` if not installed)."""
    versions = {"python": sys.version.split()[0]}
    for name in VERSIONED:
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = "absent"
    return versions
