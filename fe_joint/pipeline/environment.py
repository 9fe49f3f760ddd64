"""What a stage ran on: the code's commit, the versions of the numerical packages, the ranks.

Recorded in every stage manifest (``DIR/stages/<stage>.json``, key ``environment``) when the stage
has run, so the report can state the provenance of each artifact without importing anything
itself: dolfinx, PETSc and SLEPc versions are read only from modules a stage has already imported
(``sys.modules``), never imported here.
"""
from __future__ import annotations

import platform
import subprocess
import sys
import time
from pathlib import Path

#: packages whose version is recorded when they are loaded (import name → label)
PACKAGES = ("numpy", "scipy", "h5py", "matplotlib", "mpi4py", "pyfftw", "gmsh", "dolfinx",
            "petsc4py", "slepc4py", "meshio")
#: the source tree of the code that runs (a git checkout, or an installed copy)
SOURCE = Path(__file__).resolve().parents[2]


def git_describe(path: Path = SOURCE) -> str:
    """``git describe --always --dirty --tags`` of the tree at ``path``; "unknown" outside git.

    Args:
        path: a folder inside the checkout.
    Returns:
        e.g. ``08dcbd2`` or ``08dcbd2-dirty``; "unknown" when git or the checkout is missing.
    """
    try:
        r = subprocess.run(["git", "-C", str(path), "describe", "--always", "--dirty", "--tags"],
                           capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else "unknown"


def _version(name: str) -> str | None:
    """The version of a module already imported, None when it is not loaded (never imports)."""
    mod = sys.modules.get(name)
    if mod is None:
        return None
    v = getattr(mod, "__version__", None)
    if v is None and name == "gmsh":
        v = getattr(mod, "GMSH_API_VERSION", None)
    return str(v) if v is not None else "loaded (no version attribute)"


def run_environment(comm=None) -> dict:
    """The environment of the running process, for a stage manifest.

    Args:
        comm: the run's communicator (None: serial without MPI).
    Returns:
        {"commit", "python", "platform", "host", "ranks", "time" (UTC, ISO 8601), "packages":
        {name: version} of the loaded ones}.
    """
    pk = {n: _version(n) for n in PACKAGES}
    return {"commit": git_describe(), "python": platform.python_version(),
            "platform": platform.platform(), "host": platform.node(),
            "ranks": int(comm.size) if comm is not None else 1,
            "time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "packages": {n: v for n, v in pk.items() if v is not None}}
