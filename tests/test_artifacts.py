"""Artifacts checked before use, per-curve cache, result guards (issue 14, items 2, 4, 5).

Fast tests on synthetic files and a synthetic study: the file records and their checks, a
loader that names the broken file, the runner rebuilding a stage whose file was truncated or
deleted, the dynamics jobs' keys and plan (a truncated curve reruns its job only; a new level
runs only its curves, renumbered levels are relabelled), and the guards on a small
Craig–Bampton chain and on the gross-slip estimate.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla

from fe_joint.case import load_case
from fe_joint.errors import ArtifactError, CaseError, classify
from fe_joint.pipeline.guards import (CUTOFF_REL_TOL, RunWarning, cutoff_guard, done_line,
                                      gross_slip_guard, unstable_guard, v3_guard)
from fe_joint.pipeline.runner import STAGES, read_stage_log, run_stages
from fe_joint.study import jobs as study
from fe_joint.study.artifacts import (CurveKey, check_files, file_record, load_artifact,
                                      load_curves)
from fe_joint.study.frf import CurveResult, SweepSettings


# --- file records ---------------------------------------------------------------------------

def test_file_record_finds_missing_truncated_and_changed_files(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    (tmp_path / "a").mkdir()
    blobs = {"a/x.bin": rng.bytes(5000), "a/y.bin": rng.bytes(300), "z.txt": b"hello"}
    for rel, b in blobs.items():
        (tmp_path / rel).write_bytes(b)
    rec = file_record(tmp_path, [tmp_path / "a", tmp_path / "z.txt", tmp_path / "absent"])
    assert sorted(rec) == sorted(blobs)
    import hashlib
    for rel, b in blobs.items():    # the record is the bytes' size and sha256
        assert rec[rel] == {"size": len(b), "sha256": hashlib.sha256(b).hexdigest()}
    assert check_files(tmp_path, rec) is None
    x = tmp_path / "a" / "x.bin"
    x.write_bytes(blobs["a/x.bin"][:2500])
    assert check_files(tmp_path, rec) == "a/x.bin truncated (2500 of 5000 bytes)"
    x.write_bytes(blobs["a/x.bin"][:-1] + bytes([blobs["a/x.bin"][-1] ^ 1]))   # one bit, same size
    assert check_files(tmp_path, rec) == "a/x.bin changed (sha256 differs)"
    x.unlink()
    (tmp_path / "z.txt").unlink()
    assert check_files(tmp_path, rec) == "a/x.bin missing (and 1 more)"


def test_broken_artifacts_fail_with_one_line_naming_the_path(tmp_path: Path) -> None:
    import h5py
    from fe_joint.model.reduced_model import ReducedModel
    h5 = tmp_path / "fe" / "reduced_model.h5"
    h5.parent.mkdir()
    with h5py.File(h5, "w") as f:
        f["K"] = np.eye(400)
    h5.write_bytes(h5.read_bytes()[: h5.stat().st_size // 2])
    npz = tmp_path / "c.npz"
    np.savez(npz, a=np.arange(1000.0))
    npz.write_bytes(npz.read_bytes()[:500])
    cases = [(h5, lambda p: ReducedModel.load(str(p))), (npz, CurveResult.load),
             (tmp_path / "gone.npz", CurveResult.load)]
    for path, loader in cases:
        with pytest.raises(ArtifactError) as e:
            load_artifact(path, loader)
        code, msg = classify(e.value)
        assert code == 2 and str(path) in msg and "\n" not in msg, msg


# --- the runner: a stage's files are checked before it is skipped ---------------------------

def _writing_registry(calls: list) -> dict:
    """Stages that write a file each (fe: fe/reduced_model.h5, 1 MB) and log their calls."""
    rng = np.random.default_rng(1)

    def make(name):
        def f(ctx):
            calls.append(name)
            if ctx.rank == 0:
                ctx.path(name).mkdir(exist_ok=True)
                fname = "reduced_model.h5" if name == "fe" else "out.bin"
                ctx.path(name, fname).write_bytes(rng.bytes(1 << 20 if name == "fe" else 100))
            return {}
        return f
    return {s: make(s) for s in STAGES}


def test_truncated_or_deleted_reduced_model_reruns_fe_and_downstream(tmp_path: Path, capsys) -> None:
    case = load_case(preset="quick")
    calls: list = []
    stages = ("mesh", "fe", "contact")
    run_stages(case, tmp_path, stages, _writing_registry(calls))
    man = json.loads((tmp_path / "stages" / "fe.json").read_text())
    assert man["files"]["fe/reduced_model.h5"]["size"] == 1 << 20
    calls.clear()
    run_stages(case, tmp_path, stages, _writing_registry(calls))
    assert calls == []                                     # intact: all cached
    h5 = tmp_path / "fe" / "reduced_model.h5"
    for damage, why in ((lambda: h5.write_bytes(h5.read_bytes()[: 1 << 19]), "truncated"),
                        (h5.unlink, "missing")):
        damage()
        capsys.readouterr()
        calls.clear()
        run_stages(case, tmp_path, stages, _writing_registry(calls))
        assert calls == ["fe", "contact"]                  # the stage that wrote it, and after
        lines = [l for l in capsys.readouterr().out.splitlines() if "fe/reduced_model.h5" in l]
        assert len(lines) == 1 and why in lines[0], lines
        assert h5.stat().st_size == 1 << 20
    log = [(e["stage"], e["action"]) for e in read_stage_log(tmp_path)]
    assert log[-3:] == [("mesh", "cached"), ("fe", "ran"), ("contact", "ran")]


# --- dynamics jobs: per-curve keys and the plan ----------------------------------------------

def _inputs(levels: list[float], mu: float = 0.6) -> study.StudyInputs:
    """A synthetic study (random arrays of the right kinds): enough for keys and plans."""
    rng = np.random.default_rng(2)
    ne, n = 6, 30
    case = load_case(preset="quick")
    case = dataclasses.replace(
        case, roughness=dataclasses.replace(case.roughness, rq_um=[15.0], v_rq_um=15.0),
        contact=dataclasses.replace(case.contact, mu=mu),
        dynamics=dataclasses.replace(case.dynamics, configurations=["baseline", "v1", "v2", "v3"],
                                     levels=levels))
    rm = SimpleNamespace(K=rng.random((n, n)), M=rng.random((n, n)),
                         pair_dofs=rng.integers(0, n, (ne, 2, 3)), damping_ratio=1e-3,
                         excitation_dof=0, response_dof=0)
    setup = SimpleNamespace(pair_xy=rng.random((ne, 2)), area=rng.random(ne), n0_fe=rng.random(ne),
                            gap_fe=np.zeros(ne), p_s=rng.random((8, 8)), g_s=np.zeros((8, 8)),
                            side=1.0, patch=8, young=2e5, poisson=0.3,
                            ig=SimpleNamespace(mask=np.ones((8, 8), bool),
                                               owner=rng.integers(0, ne, (8, 8)),
                                               xc=rng.random((8, 8)), yc=rng.random((8, 8))))
    sc = SimpleNamespace(rq_um=15.0, z=rng.random((8, 8)), n0=rng.random(ne), gap_el=np.zeros(ne),
                         kn=rng.random(ne), kt_mindlin=rng.random(ne))
    from fe_joint.model.joint import JointModel
    joints = {c: JointModel(c, n0=rng.random(ne), gap=np.zeros(ne), kn=rng.random(ne),
                            kt=rng.random(ne), area=setup.area) for c in ("baseline", "v1", "v2")}
    return study.StudyInputs(rm=rm, setup=setup, surfaces={15.0: sc}, kn_smooth=rng.random(ne),
                             joints=joints, levels=levels, f_lin={c: 250.0 for c in joints},
                             case=case, settings=SweepSettings.from_case(case))


def _keyed(inp: study.StudyInputs) -> list[study.Job]:
    rmk = study.rm_digest(inp.rm)
    first = study.with_keys(inp, study.jobs_for(inp.case, inp.levels), rmk)
    v3 = {j.rq_um: j.key for j in first if j.kind == "v3"}
    return first + study.with_keys(inp, study.follow_up_jobs(inp.case, inp.levels), rmk, v3)


def _fake_run(inp: study.StudyInputs, job: study.Job) -> dict:
    """A job's result without solving: a small curve whose peak encodes the level."""
    level = inp.levels[job.level_index]
    ne, p = 6, 5

    def curve():
        return CurveResult(config=job.config, level=level, omega_hz=np.linspace(240, 250, p),
                           amplitude=np.full(p, level), stable=np.ones(p, bool), peak_hz=245.0,
                           peak_amplitude=level * 1e-3, status=np.zeros(ne, np.int64),
                           energy=np.zeros(ne), mean_normal=np.zeros(ne), q_amp=np.zeros((ne, 2)),
                           loop_u=np.zeros(8), loop_T=np.zeros(8), elem_u=np.zeros((ne, 8)),
                           elem_T=np.zeros((ne, 8)), seconds=0.0, newton_iterations=1, n_points=p,
                           n_active=ne, n_nonlinear=0)
    curves = {k: curve().with_key(k) for k in job.curve_keys}
    if job.kind != "v3":
        return {"curves": curves, "meta": {}, "arrays": {}}
    return {"curves": curves, "meta": {"history": [], "converged": True, "rq_um": job.rq_um,
                                       "f_lin": 250.0},
            "arrays": {"kn": np.ones(ne), "kt": np.ones(ne)}, "pass0": curve()}


def _run_study(folder: Path, inp: study.StudyInputs, say=print) -> list[str]:
    """Plan and (fake-)run every job; the names of those that ran."""
    todo = study.plan_jobs(folder, _keyed(inp), say=say)
    for job in todo:
        study.write_job(folder, job, _fake_run(inp, job))
    return sorted(j.name for j in todo)


def test_truncated_curve_reruns_its_job_only(tmp_path: Path) -> None:
    inp = _inputs([2.0, 15.0])
    ran = _run_study(tmp_path, inp)
    assert ran == sorted(j.name for j in _keyed(inp))
    assert _run_study(tmp_path, inp) == []                       # all cached
    f = tmp_path / "v1@L0.npz"
    f.write_bytes(f.read_bytes()[:100])
    with pytest.raises(ArtifactError, match="v1@L0.npz"):        # a reader names it
        load_curves(tmp_path)
    said: list = []
    assert _run_study(tmp_path, inp, said.append) == ["v1@L0"]
    assert len(said) == 1 and "dynamics/v1@L0.npz truncated" in said[0], said
    assert len(load_curves(tmp_path)) == len(_keyed(inp)) - 1 + 1   # v3 job: 1 curve each


def test_new_level_runs_only_its_curves_and_renumbered_levels_are_relabelled(tmp_path: Path) -> None:
    _run_study(tmp_path, _inputs([2.0, 15.0]))
    # a level added on top (the middle level stays 15 N): only its curves run
    assert _run_study(tmp_path, _inputs([2.0, 15.0, 40.0])) == ["baseline@L2", "v1@L2", "v2@L2",
                                                                "v3-rq15@L2"]
    # one added below: every index moves (15 N is now L2), nothing but the new level runs
    inp = _inputs([1.0, 2.0, 15.0, 40.0])
    assert _run_study(tmp_path, inp) == ["baseline@L0", "v1@L0", "v2@L0", "v3-rq15@L0"]
    curves = load_curves(tmp_path)
    assert {k.name for k in curves} == {j.curve_keys[0].name for j in _keyed(inp)}
    for k, cr in curves.items():     # each file holds its own key and its level's result
        assert cr.level == inp.levels[k.level_index] and cr.peak_amplitude == cr.level * 1e-3
    # the folder holds this study's files only, each marker naming its own job
    assert {f.name for f in tmp_path.iterdir()} == {f for j in _keyed(inp) for f in j.files}
    for j in _keyed(inp):
        assert json.loads((tmp_path / f"{j.name}.json").read_text())["job"]["level_index"] == \
            j.level_index
    assert _run_study(tmp_path, inp) == []


def test_job_keys_follow_what_each_job_reads() -> None:
    a = {j.name: j.key for j in _keyed(_inputs([2.0, 15.0]))}
    # μ enters every FRF and the v3 loops: every job reruns
    b = {j.name: j.key for j in _keyed(_inputs([2.0, 15.0], mu=0.3))}
    assert all(a[n] != b[n] for n in a)
    # the speed study's switch and the report's inputs are not read by any job
    inp = _inputs([2.0, 15.0])
    inp.case = dataclasses.replace(inp.case, dynamics=dataclasses.replace(inp.case.dynamics,
                                                                          speed_study=True))
    assert {j.name: j.key for j in _keyed(inp)} == a
    # a configuration's joint changes (k_ref → baseline and v1): only its curves
    inp = _inputs([2.0, 15.0])
    inp.joints["baseline"] = dataclasses.replace(inp.joints["baseline"],
                                                 kn=inp.joints["baseline"].kn * 2)
    c = {j.name: j.key for j in _keyed(inp)}
    assert sorted(n for n in a if a[n] != c[n]) == ["baseline@L0", "baseline@L1"]


# --- guards --------------------------------------------------------------------------------

def _chain_cb(cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Free–free spring–mass chain (60 DOFs) and its Craig–Bampton model (3 boundary DOFs plus
    the fixed-interface modes up to ``cutoff_hz``), built here independently of fe_joint.fe.

    Returns:
        (full, reduced) elastic frequencies, Hz, ascending (the first 8).
    """
    n, k, m = 60, 1e6, 1e-3
    K = np.zeros((n, n))
    for i in range(n - 1):
        K[np.ix_([i, i + 1], [i, i + 1])] += k * np.array([[1, -1], [-1, 1]])
    M = np.diag(np.full(n, m))
    b = np.array([0, 30, 59])
    i = np.setdiff1d(np.arange(n), b)
    psi = -np.linalg.solve(K[np.ix_(i, i)], K[np.ix_(i, b)])
    lam, phi = sla.eigh(K[np.ix_(i, i)], M[np.ix_(i, i)])
    phi = phi[:, np.sqrt(lam) / (2 * np.pi) <= cutoff_hz]
    T = np.zeros((n, len(b) + phi.shape[1]))
    T[b, : len(b)] = np.eye(len(b))
    T[np.ix_(i, range(len(b)))] = psi
    T[np.ix_(i, range(len(b), T.shape[1]))] = phi

    def elastic(K_, M_):
        f = np.sqrt(np.abs(sla.eigh(K_, M_, eigvals_only=True))) / (2 * np.pi)
        return f[1:9]                   # one rigid mode (free–free chain)
    return elastic(K, M), elastic(T.T @ K @ T, T.T @ M @ T)


def test_cutoff_guard_on_a_craig_bampton_chain() -> None:
    full, _ = _chain_cb(1.0)
    band_top = 1.01 * full[0]          # FRFs around the first elastic mode
    # a cut-off far above the band: the reduced model matches there, no warning
    f, r = _chain_cb(20 * band_top)
    assert np.abs(r[f <= 2 * band_top] / f[f <= 2 * band_top] - 1).max() < CUTOFF_REL_TOL
    assert cutoff_guard(f, r, 20 * band_top, band_top) == []
    # no fixed-interface mode kept (a cut-off of 1e-6 Hz, Guyan): the band is missed
    f, r = _chain_cb(1e-6)
    assert len(r) == 2                 # 3 boundary DOFs: one rigid, two elastic modes
    w = cutoff_guard(f, r, 1e-6, band_top)
    assert len(w) == 1 and w[0].kind == "cutoff" and w[0].value > 0.01
    sel = (f[:2] <= 2 * band_top) | (np.arange(2) == 0)
    assert w[0].value == pytest.approx(np.abs(r / f[:2] - 1)[sel].max())
    # a cut-off between the band and its margin: the modes may still agree, the margin does not
    f, r = _chain_cb(1.5 * band_top)
    w = cutoff_guard(f, r, 1.5 * band_top, band_top)
    assert len(w) == 1 and w[0].kind == "cutoff"


def test_gross_slip_guard_against_the_stuck_joint_estimate() -> None:
    """One element between a mass A (x, y, z) and a grounded, nearly massless body B: at the
    stuck resonance the joint's shear per newton of excitation is 1/(2ζ) (the spring carries
    the whole dynamic force, amplified by the resonance), so gross slip starts at 2ζ·μN0.
    Levels below it pass, above it warn, 100× beyond it are rejected with exit 2."""
    from fe_joint.model.joint import JointModel, slip_onset
    zeta, mu, n0, k = 1e-3, 0.5, 100.0, 1e4
    # A's y and z stiffer: x is the first mode; B nearly rigidly grounded (its x moves 1e-4 of A's)
    K = np.diag([0.0, 1e6, 1e6, 1e8, 1e8, 1e8])
    M = np.diag([1e-3] * 3 + [1e-6] * 3)
    pair = np.array([[[0, 1, 2], [3, 4, 5]]])
    joint = JointModel("j", n0=np.array([n0]), gap=np.zeros(1), kn=np.array([k]),
                       kt=np.array([k]), area=np.ones(1))
    est = slip_onset(K, M, pair, joint, 0, zeta, mu)["macroslip"]
    assert est == pytest.approx(2 * zeta * mu * n0, rel=1e-3)
    assert gross_slip_guard([0.5 * est, 0.99 * est], est, mu, n0) == []
    w = gross_slip_guard([0.5 * est, 3 * est], est, mu, n0)
    assert [x.subject for x in w] == ["L1"] and w[0].value == pytest.approx(3.0)
    assert f"{est:.4g} N" in w[0].message
    with pytest.raises(CaseError) as e:
        gross_slip_guard([150 * est], est, mu, n0)
    code, msg = classify(e.value)
    assert code == 2 and msg.startswith("dynamics.levels") and "\n" not in msg


def test_v3_and_unstable_guards_and_the_last_line() -> None:
    rec = {"converged": False, "history": [{"change": None}, {"change": 0.02}, {"change": 0.004}]}
    w = v3_guard("v3-rq15", rec, 1e-3) + v3_guard("v3-rq1", {"converged": True}, 1e-3)
    assert [x.subject for x in w] == ["v3-rq15"] and w[0].value == 0.004
    st = np.array([True, False, False, True])
    w += unstable_guard("v1@L2", np.array([240.0, 241.0, 242.0, 243.0]), st)
    w += unstable_guard("v1@L0", np.arange(4.0), np.ones(4, bool))
    assert [x.subject for x in w] == ["v3-rq15", "v1@L2"] and w[1].value == 2
    assert [RunWarning.from_dict(x.to_dict()) for x in w] == w
    line = done_line("out", w)
    assert line.startswith("[fe-joint] done with 2 warnings:") and "v3-rq15" in line \
        and "v1@L2" in line and "\n" not in line
    assert done_line("out", []) == "[fe-joint] done: out"
