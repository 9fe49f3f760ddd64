"""fe-joint: multiscale nonlinear dynamics of bolted joints with rough contact.

Subpackages, one concern each (docs/design.md, "Layering"):

* :mod:`fe_joint.case` — the case: typed, validated settings (``load_case``).
* :mod:`fe_joint.fe` — the FE chain in dolfinx (mesh, preload, modes, Craig–Bampton); the only
  subpackage that imports dolfinx, PETSc or SLEPc.
* :mod:`fe_joint.model` — the numpy hand-over: ``ReducedModel``, ``JointModel``, the interface
  contact solver of the preload.
* :mod:`fe_joint.study` — FE → BEM coupling, the configurations, FRFs, the v3 fixed point, the
  MPI job queue, typed artifact keys.
* :mod:`fe_joint.report` — figures, report.md, summary.json from a run's artifacts.
* :mod:`fe_joint.pipeline` — the stage runner (hashes, manifests, resume) and the stages.

The names below are loaded on first use, so ``import fe_joint`` stays light and never imports
dolfinx.
"""
from __future__ import annotations

import importlib

#: public name → module that defines it
_EXPORTS = {
    "Case": "fe_joint.case", "CaseError": "fe_joint.errors", "load_case": "fe_joint.case",
    "ConvergenceError": "fe_joint.errors",
    "ReducedModel": "fe_joint.model.reduced_model", "JointModel": "fe_joint.model.joint",
    "stuck_modes": "fe_joint.model.joint",
    "CurveKey": "fe_joint.study.artifacts", "CurveResult": "fe_joint.study.frf",
    "SweepSettings": "fe_joint.study.frf", "frf": "fe_joint.study.frf",
    "run_stages": "fe_joint.pipeline.runner", "STAGES": "fe_joint.pipeline.runner",
    "write_report": "fe_joint.report",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'fe_joint' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
