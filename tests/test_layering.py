"""The layering of fe_joint: only fe_joint.fe imports dolfinx/PETSc/SLEPc; the report of a run is
rebuilt without them."""
from __future__ import annotations

import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import fe_joint

ROOT = Path(__file__).resolve().parents[1]
#: a prelude that makes importing the FE stack fail, as on a machine without it
BLOCK = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('dolfinx', 'petsc4py', 'slepc4py', 'ufl', 'ffcx', 'basix'):
            raise ImportError(f'{name} is blocked in this test')
        return None
sys.meta_path.insert(0, _Block())
"""


def _non_fe_modules() -> list[str]:
    names = []
    for m in pkgutil.walk_packages(fe_joint.__path__, "fe_joint."):
        if m.name == "fe_joint.fe" or m.name.startswith("fe_joint.fe."):
            continue
        names.append(m.name)
    return names


def _run_blocked(code: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True, text=True,
                          env=env, cwd=cwd)


def test_every_non_fe_module_imports_without_dolfinx() -> None:
    mods = _non_fe_modules()
    assert len(mods) >= 20          # the walk found the subpackages' modules
    r = _run_blocked("import importlib\nfor m in %r:\n    importlib.import_module(m)\n"
                     "print(sum(k.split('.')[0] == 'dolfinx' for k in sys.modules))" % mods)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "0"


def test_fe_modules_do_import_dolfinx_when_blocked_fails() -> None:
    """The block works: the FE package itself cannot be imported under it."""
    r = _run_blocked("import fe_joint.fe.elasticity")
    assert r.returncode != 0 and "blocked in this test" in r.stderr


def test_public_api_names_resolve() -> None:
    for name in fe_joint.__all__:
        assert getattr(fe_joint, name) is not None
