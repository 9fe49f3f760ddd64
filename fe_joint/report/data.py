"""What the report reads: a run folder's artifacts gathered once into a :class:`ReportData`.

Everything comes from files the earlier stages wrote (stage manifests, ``fe/reduced_model.h5``,
``contact/surfaces.npz``, the curves and v3 records in ``dynamics/``, ``speed/speed_error.json``),
never from the solvers, so the report runs without dolfinx, PETSc or the HBM solver.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..case import Case
from ..model.reduced_model import ReducedModel
from ..pipeline.runner import read_manifest, read_stage_log
from ..study.artifacts import (BackboneKey, CurveKey, load_artifact, load_backbones, load_curves,
                               read_json_artifact, v3_job_name)
from ..study.contact import SurfaceContact, load_surfaces
from ..study.frf import CurveResult

#: the stages whose manifests the report reads (summary and wall time)
STAGES_READ = ("mesh", "fe", "contact", "dynamics")
#: the stages whose wall time and job queue the cost table shows (the speed stage's tables are
#: read from ``speed/speed_error.json``; nothing of summary.json comes from its manifest)
STAGES_TIMED = STAGES_READ + ("speed",)

#: the paper's numbers for the side-by-side tables (contact fraction in % per Rq in µm, N/mm³, s)
PAPER = {
    "contact_fraction": {1.0: 22.1, 10.0: 2.7, 15.0: 2.0},
    "kn_smooth_mean": 6.6e4, "kn_smooth_max": 1.74e5,
    "hbm_seconds": {"smooth": 13682, "Rq1": 6957, "Rq5": 6362, "Rq10": 6031, "Rq15": 5954},
}


@dataclass
class ReportData:
    """A finished run's artifacts, as the report uses them.

    Attributes:
        out: the run folder.
        case: the validated case of the run.
        summaries: stage → the ``summary`` of its manifest ({} when the stage has none).
        stage_seconds: stage → wall time from its manifest, s (stages without one are left out).
        rm: the reduced model (pair coordinates in mm, tributary areas in mm²).
        surfaces: Rq in µm → the rough contact of that surface.
        extra: the smooth arrays saved beside the surfaces (``kn_smooth`` N/mm³, ``p_s`` MPa, …).
        curves: every finished FRF of ``dynamics/``.
        v3_records: Rq in µm → the v3 fixed point's record (``history``, ``converged``, …).
        v3_arrays: Rq in µm → the converged v3 stiffnesses {``kn``, ``kt``}, (ne,) N/mm³ each.
        speed: the speed-against-error tables, None when the file is missing.
        seeds: the contact stage's seed statistics (``contact/seeds.json``), None if missing.
        hardness: the hardness-capped sweep (``contact/hardness.json``), None if missing.
        backbones: every finished backbone of ``dynamics/backbones/`` ({} for a run without).
        environments: stage → what it ran on (commit, versions, ranks, time: its manifest's
            ``environment``; {} for stages run before it was recorded).
        stage_log: the entries of ``DIR/stage_log.jsonl`` (stage, action, seconds, time).
    """
    out: Path
    case: Case
    summaries: dict[str, dict]
    stage_seconds: dict[str, float]
    rm: ReducedModel
    surfaces: dict[float, SurfaceContact]
    extra: dict[str, np.ndarray]
    curves: dict[CurveKey, CurveResult]
    v3_records: dict[float, dict]
    v3_arrays: dict[float, dict[str, np.ndarray]]
    speed: dict | None
    seeds: dict | None = None
    hardness: dict | None = None
    backbones: dict = field(default_factory=dict)
    environments: dict[str, dict] = field(default_factory=dict)
    stage_log: list[dict] = field(default_factory=list)

    @property
    def dynamics(self) -> dict:
        """The dynamics stage's summary (levels, level_info, f_lin, linear_peak_rel_error)."""
        return self.summaries["dynamics"]

    @property
    def levels(self) -> list[float]:
        """Excitation levels of the study, N."""
        return self.dynamics["levels"]

    @property
    def macroslip(self) -> float:
        """Linear (stuck-joint) macroslip estimate, N."""
        return self.dynamics["level_info"]["macroslip"]

    @property
    def mid(self) -> int:
        """Index of the middle level (the Rq sweep's level)."""
        return len(self.levels) // 2

    @property
    def top(self) -> int:
        """Index of the highest level (resonance maps and loops)."""
        return len(self.levels) - 1

    @property
    def configs(self) -> list[str]:
        """The configurations the case compares, in the case's order."""
        return list(self.case.dynamics.configurations)

    @property
    def v_rq(self) -> float:
        """Rq of the v1/v2/v3 comparison surface, µm."""
        return self.case.roughness.v_rq_um

    @property
    def rqs(self) -> list[float]:
        """Rq of every contact surface, ascending, µm."""
        return sorted(self.surfaces)

    @property
    def cell_area(self) -> float:
        """Cell area of the global BEM grid, mm² (the grid spans overlap × plate width)."""
        g = self.case.geometry
        return g.overlap * g.plate_width / self.extra["mask"].size

    @property
    def xy(self) -> np.ndarray:
        """(ne, 2) in-plane coordinates of the friction elements, mm."""
        return np.asarray(self.rm.pair_xyz)[:, :2]

    @property
    def area(self) -> np.ndarray:
        """(ne,) tributary areas of the friction elements, mm²."""
        return np.asarray(self.rm.pair_area)

    def backbone_curves(self, key: BackboneKey) -> dict:
        """The forced curves of a backbone's joint, {level index: CurveResult} (v3: on its
        surface)."""
        return {k.level_index: cr for k, cr in self.curves.items()
                if k.config == key.config and k.level_index is not None
                and (key.config != "v3" or k.rq_um == key.rq_um)}

    def curve(self, config: str, level_index: int) -> CurveResult | None:
        """The FRF of a configuration at a level (v3: on the comparison surface), None if absent."""
        rq = self.v_rq if config == "v3" else None
        return self.curves.get(CurveKey(config, level_index, rq))


def _read_json(path: Path) -> dict | None:
    return read_json_artifact(path) if path.exists() else None


def _v3_files(dyn: Path, rqs: list[float]) -> tuple[dict[float, dict], dict[float, dict]]:
    """The v3 records and converged stiffness arrays present in ``dyn`` for the given Rq (µm)."""
    records, arrays = {}, {}
    for rq in rqs:
        rec = _read_json(dyn / f"{v3_job_name(rq)}.json")
        if rec is not None:
            records[rq] = rec
        f = dyn / f"{v3_job_name(rq)}.arrays.npz"
        if f.exists():
            def read(p):
                with np.load(p) as a:
                    return {"kn": a["kn"], "kt": a["kt"]}
            arrays[rq] = load_artifact(f, read)
    return records, arrays


def load_report_data(out: Path, case: Case) -> ReportData:
    """Read a run folder's artifacts.

    Args:
        out: the run's folder (``stages/``, ``fe/``, ``contact/``, ``dynamics/``, ``speed/``).
        case: the validated case of the run.
    Returns:
        the artifacts as a ReportData.
    """
    out = Path(out)
    manifests = {s: read_manifest(out, s) or {} for s in STAGES_TIMED}
    surfaces, extra = load_artifact(out / "contact" / "surfaces.npz", load_surfaces)
    records, arrays = _v3_files(out / "dynamics", sorted(surfaces))
    return ReportData(
        out=out, case=case,
        summaries={s: m.get("summary", {}) for s, m in manifests.items()},
        stage_seconds={s: m["seconds"] for s, m in manifests.items() if "seconds" in m},
        rm=load_artifact(out / "fe" / "reduced_model.h5", lambda p: ReducedModel.load(str(p))),
        surfaces=surfaces, extra=extra, curves=load_curves(out / "dynamics"),
        v3_records=records, v3_arrays=arrays,
        speed=_read_json(out / "speed" / "speed_error.json"),
        seeds=_read_json(out / "contact" / "seeds.json"),
        hardness=_read_json(out / "contact" / "hardness.json"),
        backbones=load_backbones(out / "dynamics"),
        environments={s: m["environment"] for s, m in manifests.items() if "environment" in m},
        stage_log=read_stage_log(out))
