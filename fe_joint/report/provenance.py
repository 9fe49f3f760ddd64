"""The report's parameter table (the case's values beside the paper's) and the run's provenance.

Parameters come from the run's case (``DIR/case.toml``, read into :class:`~fe_joint.case.Case`)
and the dynamics stage's summary (the levels in N); provenance from what the stages recorded
(``environment`` in ``DIR/stages/<stage>.json``: commit, versions, ranks, time) and the stage log.
A run made before the environment was recorded says "not recorded"; the commit then falls back
to the report's own (``git describe``, "unknown" outside a git checkout), labelled as such.
"""
from __future__ import annotations

import platform
from dataclasses import dataclass

import numpy as np

from ..pipeline.environment import git_describe
from ..study.artifacts import rq_label
from .data import STAGES_READ, ReportData

#: the version rows of the provenance table, in order (package import names)
VERSION_PACKAGES = ("numpy", "scipy", "h5py", "matplotlib", "mpi4py", "pyfftw", "gmsh", "dolfinx",
                    "petsc4py", "slepc4py")
NOT_RECORDED = "not recorded"


@dataclass(frozen=True)
class Parameter:
    """One row of the parameter table: what, our value, unit, the case key, the paper's value."""
    name: str
    value: str
    unit: str
    key: str
    paper: str


def _levels_text(data: ReportData) -> str:
    """The levels in N, and how they were chosen."""
    lv = ", ".join(f"{x:.4g}" for x in data.levels)
    how = "auto" if data.case.dynamics.levels == "auto" else "case"
    return f"{lv} ({how})"


def parameters(data: ReportData) -> list[Parameter]:
    """The parameter table of the run.

    Args:
        data: the run's artifacts (case and dynamics summary).
    Returns:
        rows in reading order; numbers in the case's units (N, mm, µm, N/mm³, MPa).
    """
    c = data.case
    r, d, ct = c.roughness, c.dynamics, c.contact
    seeds = f"{r.seeds} (seeds {r.seed} … {r.seed + r.seeds - 1}; study surface: seed {r.seed})"
    P = Parameter
    return [
        P("friction coefficient μ", f"{ct.mu:g}", "–", "contact.mu", "0.6"),
        P("structural modal damping ζ", f"{c.reduction.damping_ratio:g}", "–",
          "reduction.damping_ratio", "not stated"),
        P("harmonics H (plus the 0th)", f"{d.harmonics}", "–", "dynamics.harmonics", "3"),
        P("AFT time samples per period", f"{d.samples}", "–", "dynamics.samples", "not stated"),
        P("reference stiffness k_ref (baseline k_n = k_t)", f"{ct.k_ref:.4g}", "N/mm³",
          "contact.k_ref", "6e4"),
        P("correlation length λ", f"{r.corr_length:g}", "mm", "roughness.corr_length", "0.5"),
        P("Rq sweep", ", ".join(rq_label(q) for q in r.rq_um), "µm", "roughness.rq_um",
          "1, 5, 10, 15"),
        P("Rq of the v1/v2/v3 comparison", rq_label(r.v_rq_um), "µm", "roughness.v_rq_um", "10"),
        P("Rq of smooth-ms", rq_label(r.smooth_rq_um), "µm", "roughness.smooth_rq_um",
          "“smooth” (not stated)"),
        P("surface realizations per Rq", seeds, "–", "roughness.seeds, roughness.seed", "1"),
        P("global BEM grid", f"{r.grid}²", "cells", "roughness.grid", "256²"),
        P("element patch", f"{r.patch}²", "cells", "roughness.patch", "16²"),
        P("hardness cap of the study (0: elastic)", f"{r.hardness:g}", "MPa", "roughness.hardness",
          "0 (elastic)"),
        P("hardness of the capped variant", f"{r.material_hardness:g}", "MPa",
          "roughness.material_hardness", "–"),
        P("bolt preload", f"{c.preload.bolt_force:g}", "N", "preload.bolt_force", "30 000"),
        P("excitation levels", _levels_text(data), "N", "dynamics.levels", "500, 1000, 2000"),
        P("v3 fixed point and Rq sweep level", f"L{data.mid} = {data.levels[data.mid]:.4g}", "N",
          "(middle level)", "1000 (Fig. 21: all three)"),
        P("v3 tolerance / passes", f"{ct.kt_tol:g} / {ct.kt_max_passes}", "–",
          "contact.kt_tol, contact.kt_max_passes", "one pass"),
        P("friction elements (matched pairs)", f"{len(data.area)}", "–", "geometry (mesh)", "340"),
        P("sweep band / f_lin", " … ".join(f"{b:g}" for b in d.band), "–", "dynamics.band", "–"),
    ]


def parameters_markdown(data: ReportData) -> list[str]:
    """The parameter table as Markdown lines."""
    L = ["## Parameters", "", "| parameter | this run | unit | case key | paper |", "|---|---|---|---|---|"]
    L += [f"| {p.name} | {p.value} | {p.unit} | `{p.key}` | {p.paper} |" for p in parameters(data)]
    return L + [""]


def _run_times(data: ReportData) -> tuple[str, str]:
    """(first, last) time a computing stage (mesh … dynamics) ran, from the stage log: not the
    report's own entry, which is logged after the report is written (a rebuilt report is the same)."""
    ran = [e["time"] for e in data.stage_log
           if e.get("action") == "ran" and "time" in e and e.get("stage") in STAGES_READ]
    return (ran[0], ran[-1]) if ran else (NOT_RECORDED, NOT_RECORDED)


def provenance(data: ReportData) -> dict:
    """Where the run's numbers come from.

    Args:
        data: the run's artifacts (stage environments, stage log).
    Returns:
        {"commit", "commit_source" ("run" or "report"), "stage_commits" {stage: commit},
        "python", "versions" {package: version or "not recorded"}, "ranks", "started",
        "finished", "report_python", "case_file"}.
    """
    env = data.environments
    commits = {s: (env.get(s) or {}).get("commit", NOT_RECORDED) for s in STAGES_READ}
    recorded = [c for c in commits.values() if c != NOT_RECORDED]
    versions: dict[str, str] = {}
    for s in ("mesh", "fe", "contact", "dynamics"):   # later stages win: the numbers are theirs
        versions.update((env.get(s) or {}).get("packages", {}))
    ranks = sorted({e["ranks"] for e in env.values() if "ranks" in e})
    pythons = sorted({e["python"] for e in env.values() if "python" in e})
    first, last = _run_times(data)
    return {"commit": recorded[-1] if recorded else git_describe(),
            "commit_source": "run" if recorded else "report",
            "stage_commits": commits,
            "stages": {s: {"commit": commits[s],
                           "ranks": (env.get(s) or {}).get("ranks", NOT_RECORDED),
                           "time": (env.get(s) or {}).get("time", NOT_RECORDED)} for s in STAGES_READ},
            "python": ", ".join(pythons) or NOT_RECORDED,
            "versions": {p: versions.get(p, NOT_RECORDED) for p in VERSION_PACKAGES},
            "ranks": ", ".join(str(r) for r in ranks) or NOT_RECORDED,
            "started": first, "finished": last,
            "report_python": platform.python_version(), "report_numpy": np.__version__,
            "case_file": "case.toml"}


def provenance_markdown(data: ReportData, prov: dict) -> list[str]:
    """The provenance tables as Markdown lines (``prov`` from :func:`provenance`)."""
    commit = prov["commit"] + ("" if prov["commit_source"] == "run" else
                               " (the report's code: the run recorded none)")
    if len(set(prov["stage_commits"].values())) > 1:
        commit += " (the stages differ: see below)"
    L = ["## Provenance", "", "| | |", "|---|---|",
         f"| commit (`git describe`) | {commit} |",
         f"| case file | [`case.toml`](case.toml) (the effective case of the run, every key) |",
         f"| MPI ranks | {prov['ranks']} |",
         f"| stages ran | {prov['started']} … {prov['finished']} (stage_log.jsonl, local time) |",
         f"| python (run) | {prov['python']} |"]
    L += [f"| {p} | {v} |" for p, v in prov["versions"].items()]
    L += [f"| report written with | python {prov['report_python']}, numpy {prov['report_numpy']} |", "",
          "| stage | commit | ranks | finished (UTC) |", "|---|---|---|---|"]
    L += [f"| {s} | {v['commit']} | {v['ranks']} | {v['time']} |" for s, v in prov["stages"].items()]
    return L + ["", "(\"not recorded\": the stage ran before stages recorded their environment.)", ""]
