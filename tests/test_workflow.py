"""Coarse end-to-end runs of the whole pipeline (issue 6): invariants of the study.

One serial run of every stage on the quick preset (coarse mesh, 64² BEM grid, H = 1) is shared
by the tests of this module; the MPI test reruns a lighter case on 1 rank (COMM_SELF on rank 0)
and on 2 ranks and compares the summaries.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fe_joint.cli import main
from fe_joint.case import load_case
from fe_joint.pipeline.runner import STAGES, read_stage_log, run_stages
from fe_joint.study.frf import PEAK_XTOL

CASE = """
name = "e2e"
[roughness]
rq_um = [1.0, 15.0]
v_rq_um = 15.0
[dynamics]
configurations = ["baseline", "v3"]
levels = [2.0, 15.0, 40.0]
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("e2e")
    case = d / "case.toml"
    case.write_text(CASE)
    out = d / "out"
    # a run 'killed' after its first stage, then the full run: the mesh must not be rebuilt
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--stages", "mesh",
                 "--no-progress"]) == 0
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--no-progress"]) == 0
    return out


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


DATA = Path(__file__).parent / "data"


#: Tolerances of the recorded-reference comparison, by key fragment (first match wins; default
#: REF_RTOL). Two runs of the same code on one machine differ at round-off in the FE stage (1e-8 in
#: frequencies: PETSc/gmsh are not bitwise repeatable run to run), which moves the peaks by ≤ 1e-5,
#: the v3 history and energies by ≤ 1e-3, and the discrete counts (continuation points, elements
#: at the slip threshold) and round-off diagnostics arbitrarily: those are not compared.
#: Recorded on one machine, compared on another (CI): a different CPU changes the round-off
#: again, which the tolerances below cover, except at a peak on a fold: the quick model's
#: baseline top-level peak lies where X(ω) has two sheets 1.3e-4 apart, and the reference
#: recorded in session 3 held the upper one, this machine and CI the lower one (2.5e-8 apart).
REF_RTOL = 1e-6
REF_TOLERANCES = (  # texts: their numbers, printed to 3–4 digits, are compared at their source
                  ("/findings", 1e-2),
                  # the baseline's top-level peak: the two sheets 1.3e-4 apart (above); the
                  # harmonic-block preconditioner of issue 16 (since replaced) landed on the
                  # other one here, so either is accepted, nothing wider
                  ("/peaks/baseline@L2/peak_", 3e-4), ("/peaks/baseline@L2/modal_amplitude", 3e-4),
                  ("/peaks/baseline@L2/zeta_from_amplitude", 3e-4),
                  # interpolated on the backbones (whose points are not compared: below), and the
                  # k_t definitions on the v3 peaks' loops: as the peaks
                  ("/like_for_like/", 1e-4), ("/stiffness_definitions/loops", 1e-4),
                  # backbones: checked by their own tests below (SNMS vs forced, energy balance,
                  # linear limit); where a stalled continuation stops is a knife edge
                  ("/backbones/", None),
                  # a spread over seeds is a difference of nearly equal frequencies: the FE
                  # round-off (1e-8) reaches it at 1e-5
                  ("stuck_hz/std", 1e-3),
                  ("check-linear@tiny/zeta_fric", None), ("zeta_from_amplitude", 1e-4), ("zeta_", 1e-2),
                  ("loss_factor", 1e-2), ("modal_amplitude", 1e-4), ("slip_onset", 1e-4),
                  ("n_points", None), ("/points", None), ("n_nonlinear", None), ("coupling_rel_error", None),
                  ("linear_peak_rel_error", None), ("check-linear@tiny/dissipated", None),
                  ("joint_shear", 1e-2), ("dissipated", 1e-2), ("/v3/", 1e-2),
                  ("interface_motion", 1e-4), ("peak_", 1e-4), ("reduced_vs_full", 1e-3),
                  # which curves have unstable points is a discrete count too; the warnings are
                  # checked against the rest of the summary in test_warnings_list_the_suspect_results
                  ("/warnings", None))


#: absolute tolerance of a v3 pass's relative change (the peaks' relative tolerance)
REF_ABS_CHANGE = 1e-4


def test_summary_equals_the_recorded_reference(run: Path) -> None:
    """The same case gives the same summary.json as the one recorded (timings skipped): each
    number within the tolerance its computation allows (REF_TOLERANCES)."""
    from fe_joint.report.compare import differences
    ref = json.loads((DATA / "e2e_summary.json").read_text())
    bad = []
    for rel, path, a, b in differences(ref, _summary(run)):
        if a == "<missing>":
            continue       # a key newer than the recorded reference: nothing to compare it with
        if path.endswith("/change"):
            # a v3 pass's change is itself a relative difference of two peaks: compare it
            # absolutely, at the peaks' tolerance (1e-5 of FE round-off in a peak is 3 % of a
            # change of 3e-4)
            if abs(float(a) - float(b)) > REF_ABS_CHANGE:
                bad.append((abs(float(a) - float(b)), path, a, b))
            continue
        tol = next((t for frag, t in REF_TOLERANCES if frag in path), REF_RTOL)
        if tol is not None and rel > tol:
            bad.append((rel, path, a, b))
    assert not bad, sorted(bad, key=lambda d: -d[0])[:5]


def test_report_rebuilt_from_artifacts_without_dolfinx(run: Path, tmp_path: Path) -> None:
    """`fe-joint report DIR` on a copy of the finished run, with dolfinx/PETSc/SLEPc blocked,
    writes the same summary.json and every figure again."""
    import shutil

    from fe_joint.report.compare import differences
    from test_layering import _run_blocked
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    (copy / "summary.json").unlink()
    shutil.rmtree(copy / "figures")
    r = _run_blocked(f"from fe_joint.cli import main\nsys.exit(main(['report', {str(copy)!r}]))")
    assert r.returncode == 0, r.stderr[-2000:]
    assert differences(_summary(run), _summary(copy)) == []
    assert len(list((copy / "figures").glob("*.png"))) == len(list((run / "figures").glob("*.png")))


def test_any_rq_the_case_accepts_runs(run: Path, tmp_path: Path) -> None:
    """An Rq that does not survive '%g' formatting (1.2345678 → "1.23457") runs, and the report
    names it exactly. The FE stages are reused from the e2e run (same geometry and FE keys)."""
    import shutil
    out = tmp_path / "odd"
    (out / "stages").mkdir(parents=True)
    for d in ("mesh", "fe"):
        shutil.copytree(run / d, out / d)
        shutil.copy(run / "stages" / f"{d}.json", out / "stages" / f"{d}.json")
    # the quick preset under the file's own keys (a key the file writes wins over the preset, so
    # rq_um is the file's): the same mesh and FE keys as the e2e run, so both stages are reused
    case = tmp_path / "odd.toml"
    case.write_text('name = "odd"\n'
                    '[roughness]\nrq_um = [1.2345678]\nv_rq_um = 1.2345678\n'
                    '[dynamics]\nconfigurations = ["baseline", "v3"]\nlevels = [2.0]\n'
                    '[contact]\nkt_max_passes = 1\n')
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--no-progress"]) == 0
    log = [(e["stage"], e["action"]) for e in read_stage_log(out)]
    assert ("fe", "cached") in log
    s = _summary(out)
    assert list(s["contact_fraction"]) == ["1.2345678"]
    assert "v3-rq1.2345678@L0" in s["peaks"]
    assert "1.2345678" in (out / "report.md").read_text()


def test_energy_balances_at_every_point_of_a_resonator_curve(run: Path) -> None:
    """At every point of a resonator FRF through the top level's peak (most elements slipping or
    opening) the work of the excitation per cycle equals the viscous plus the friction dissipation:
    the invariant of a Galerkin harmonic balance, to the Newton tolerance. H = 3 so that the
    higher harmonics' work counts; viscous work from the modal damping of the linear base."""
    from hbm import HarmonicBalance
    from fe_joint.model.reduced_model import ReducedModel
    from fe_joint.study import contact as ms
    from fe_joint.study.configurations import joint_baseline
    from fe_joint.study.frf import contacts, structure
    case = load_case(preset="quick")
    rm = ReducedModel.load(str(run / "fe" / "reduced_model.h5"))
    setup = ms.interface_setup(rm, case.geometry, case.material, case.roughness)
    joint = joint_baseline(setup, case.contact.k_ref)
    s = _summary(run)
    level, f_peak = s["levels_N"][-1], s["peaks"]["baseline@L2"]["peak_hz"]
    c, _ = contacts(rm, joint, case.contact.mu)
    H = 3
    hb = HarmonicBalance(structure(rm), c, harmonics=H, samples=64, tol=1e-10, krylov_tol=1e-12)
    force = np.zeros(rm.K.shape[0])
    force[rm.excitation_dof] = level
    w = 2 * np.pi * f_peak
    res = hb.frf(0.985 * w, 1.015 * w, force, dof=rm.response_dof, max_points=40)
    G = hb.G
    MPhi = rm.M @ G.Phi
    rel, share = [], []
    for sol in res.solutions:
        X = sol.coefficients
        w_in = np.pi * force @ X[2]
        w_visc = 0.0
        for h in range(1, H + 1):
            eta = MPhi.T @ (X[2 * h - 1] - 1j * X[2 * h])      # modal coordinates of harmonic h
            w_visc += np.pi * h**2 * sol.omega * float(np.sum(G.cvec * np.abs(eta) ** 2))
        w_fric = hb.element_results(sol).energy.sum()
        rel.append(abs(w_in - w_visc - w_fric) / w_in)
        share.append(w_fric / w_in)
    assert len(rel) >= 10
    assert max(rel) <= 1e-6, max(rel)
    assert max(share) > 0.2            # friction carries a real share of the dissipation


def test_warnings_list_the_suspect_results(run: Path) -> None:
    """summary.json's warnings are exactly the unconverged v3 fixed points and the curves with
    unstable points (from the dynamics manifest); no cutoff warning (reduced vs full ≤ 1e-3) and
    no gross-slip one (every level below the estimate); report.md lists them on top."""
    s = _summary(run)
    dyn = json.loads((run / "stages" / "dynamics.json").read_text())["summary"]
    by_kind: dict = {}
    for w in s["warnings"]:
        by_kind.setdefault(w["kind"], []).append(w["subject"])
    assert sorted(by_kind.get("v3-unconverged", [])) == sorted(
        n for n, v in s["v3"].items() if not v["converged"])
    assert sorted(by_kind.get("unstable", [])) == sorted(
        n for n, c in dyn["curves"].items() if c["unstable_points"] > 0)
    assert sorted(by_kind.get("backbone-incomplete", [])) == sorted(
        n for n, b in s["backbones"].items() if not b["complete"])
    assert s["reduced_vs_full_max_rel_error"] < 1e-3 and "cutoff" not in by_kind
    assert max(s["levels_over_macroslip"]) < 1 and "gross-slip" not in by_kind
    head = (run / "report.md").read_text().split("## ")[0]
    assert all(w["message"] in head for w in s["warnings"])


def _copy_run(run: Path, dest: Path) -> Path:
    import shutil
    shutil.copytree(run, dest)
    return dest


def test_damaged_curve_and_new_level_rerun_only_their_jobs(run: Path, tmp_path: Path) -> None:
    """A truncated curve and a level added below the others (every level renumbered, the middle
    one still 15 N): only the new level's curves and the damaged one are computed; every other
    curve is the old one (same wall time recorded), relabelled; the peaks match the old run's."""
    from fe_joint.study.artifacts import load_curves
    out = _copy_run(run, tmp_path / "run")
    (out / "dynamics" / "baseline@L0.npz").write_bytes(
        (run / "dynamics" / "baseline@L0.npz").read_bytes()[:2000])
    case = tmp_path / "case.toml"
    case.write_text(CASE.replace("levels = [2.0, 15.0, 40.0]", "levels = [0.5, 2.0, 15.0, 40.0]"))
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--no-progress"]) == 0
    old = {(k.config, k.rq_um, cr.level): cr for k, cr in load_curves(run / "dynamics").items()}
    new = load_curves(out / "dynamics")
    computed = {k.name for k, cr in new.items()
                if (k.config, k.rq_um, cr.level) not in old
                or old[(k.config, k.rq_um, cr.level)].seconds != cr.seconds}
    assert computed == {"baseline@L0", "v3-rq15@L0", "baseline@L1"}
    a, b = _summary(run), _summary(out)
    for name, p in a["peaks"].items():
        if "@L" in name and name != "baseline@L0":
            head, i = name.rsplit("@L", 1)
            assert b["peaks"][f"{head}@L{int(i) + 1}"]["peak_hz"] == p["peak_hz"], name


def test_damaged_backbone_reruns_that_backbone_only(run: Path, tmp_path: Path) -> None:
    """Backbones are cached by the key of their inputs, as curves are: a truncated backbone file
    reruns the dynamics stage, which recomputes that backbone only (the others keep their
    records, wall time included) and gives it back to 1e-8 (the SNMS peaks)."""
    from fe_joint.study.artifacts import load_backbones
    out = _copy_run(run, tmp_path / "run")
    bb = out / "dynamics" / "backbones"
    (bb / "baseline.npz").write_bytes((run / "dynamics" / "backbones" / "baseline.npz").read_bytes()[:1000])
    case = tmp_path / "case.toml"
    case.write_text(CASE)
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--no-progress"]) == 0
    same = {f.name for f in (run / "dynamics" / "backbones").glob("*.json")
            if f.read_bytes() == (bb / f.name).read_bytes()}
    assert same == {"v3-rq1.json", "v3-rq15.json"}
    a, b = load_backbones(run / "dynamics"), load_backbones(out / "dynamics")
    ka = {k.name: k for k in a}
    kb = {k.name: k for k in b}
    assert set(ka) == set(kb) == {"baseline", "v3-rq1", "v3-rq15"}
    new, old = b[kb["baseline"]], a[ka["baseline"]]
    assert new.seconds != old.seconds
    assert np.allclose(new.snms_hz, old.snms_hz, rtol=1e-8, atol=0)
    assert np.allclose(new.snms_amplitude, old.snms_amplitude, rtol=1e-8, atol=0)


def test_rerun_on_the_same_mesh_writes_the_same_summary_bytes(run: Path, tmp_path: Path) -> None:
    """Determinism on one rank: the fe stage and every stage after it run again (``--force``) on
    the mesh the mesh stage wrote and give bit-identical output: the reduced model's arrays (so
    every FRF job's cache key matches and no curve is recomputed), the contact surfaces and
    summary.json, which holds no wall time, byte for byte. Every curve and every backbone is
    reused from its cache key (a backbone recomputed in another process could land 1e-8 apart:
    CI's machine moved the synthesized peaks of the like-for-like section by 7e-9 when backbones
    were recomputed on every dynamics run)."""
    import hashlib
    from fe_joint.model.reduced_model import ReducedModel
    out = _copy_run(run, tmp_path / "again")
    case = tmp_path / "case.toml"
    case.write_text(CASE)
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--stages", "fe,report",
                 "--force", "--no-progress"]) == 0
    ran = [e["stage"] for e in read_stage_log(out)[len(read_stage_log(run)):] if e["action"] == "ran"]
    assert ran == [s for s in STAGES if s != "mesh"]
    a = ReducedModel.load(str(run / "fe" / "reduced_model.h5"))
    b = ReducedModel.load(str(out / "fe" / "reduced_model.h5"))
    for name in ("K", "M", "C", "preload_normal_force", "preload_gap", "reduced_frequencies"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name

    def digest(p: Path) -> str:
        return hashlib.sha256(p.read_bytes()).hexdigest()
    # every curve and every backbone was reused: the same files
    npz = sorted((run / "dynamics").rglob("*.npz"))
    assert any(f.parent.name == "backbones" for f in npz)
    for f in npz:
        rel = f.relative_to(run)
        assert digest(f) == digest(out / rel), rel
    # ... not recomputed to the same bits: their records (which hold the wall time) are the same
    for f in sorted((run / "dynamics" / "backbones").glob("*.json")):
        assert f.read_bytes() == (out / "dynamics" / "backbones" / f.name).read_bytes(), f.name
    assert (run / "summary.json").read_bytes() == (out / "summary.json").read_bytes()


def test_level_absurdly_beyond_gross_slip_is_rejected(run: Path, tmp_path: Path, capsys) -> None:
    """levels = [1e5] (≈ 500× the gross-slip estimate): exit 2, one line naming dynamics.levels
    and the estimate; no curve computed."""
    out = _copy_run(run, tmp_path / "run")
    case = tmp_path / "case.toml"
    case.write_text(CASE.replace("levels = [2.0, 15.0, 40.0]", "levels = [1e5]"))
    capsys.readouterr()
    assert main(["run", str(case), "--preset", "quick", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "dynamics.levels" in err[0] and "gross-slip estimate" in err[0], err
    assert sorted(p.name for p in (out / "dynamics").iterdir()) == sorted(
        p.name for p in (run / "dynamics").iterdir())


def test_finished_stages_not_recomputed(run: Path) -> None:
    log = [(e["stage"], e["action"]) for e in read_stage_log(run)]
    assert log[0] == ("mesh", "ran")
    assert ("mesh", "cached") in log
    assert [s for s, a in log if a == "ran"] == list(STAGES)   # each stage ran exactly once


def test_zero_roughness_reproduces_fe_pressure(run: Path) -> None:
    s = _summary(run)
    assert s["coupling_rel_error"] <= 1e-6


def test_element_loads_sum_to_bolt_force(run: Path) -> None:
    from fe_joint.study.contact import load_surfaces
    surfaces, _ = load_surfaces(run / "contact" / "surfaces.npz")
    case = load_case(preset="quick")
    for sc in surfaces.values():
        assert sc.n0.sum() == pytest.approx(case.preload.bolt_force, rel=1e-9)
        assert np.all(sc.gap_el[sc.n0 > 0] == 0)


def test_contact_fraction_and_keq_fall_with_rq(run: Path) -> None:
    s = _summary(run)
    cf = s["contact_fraction"]
    assert cf["1"] > cf["15"] > 0
    keq = s["k_eq_vs_rq"]
    assert keq["1"]["kn"] > keq["15"]["kn"] > 0
    assert keq["1"]["kt"] > keq["15"]["kt"] > 0


def test_resonance_falls_with_excitation(run: Path) -> None:
    s = _summary(run)
    peaks = [s["peaks"][f"baseline@L{i}"]["peak_hz"] for i in range(len(s["levels_N"]))]
    assert all(a > b for a, b in zip(peaks, peaks[1:]))
    # more slip, more friction dissipation per unit of response
    e = [s["peaks"][f"baseline@L{i}"]["dissipated"] for i in range(len(s["levels_N"]))]
    assert all(a < b for a, b in zip(e, e[1:]))


def test_tiny_excitation_peak_is_stuck_linear_mode(run: Path) -> None:
    s = _summary(run)
    assert s["linear_peak_rel_error"] <= 1e-3


def test_v3_local_peak_search_matches_full_sweep(run: Path) -> None:
    """Every v3 fixed point searched its peaks locally (pass 0 too: this case has no v2 curve to
    take from a full pass-0 sweep); the converged joint's full FRF has the same peak as the last
    local search: in frequency to 1e-4, in amplitude to the v3 tolerance (1e-3). The top is
    bumpy (corners of the sampled friction law) and the pass's polish and the sweep's refinement
    may end on neighbouring maxima: 2.9e-4 apart in amplitude on Rq 1 µm here (secant predictor,
    session 23), 1.1e-4 on the default model's Rq 1 µm with the tangent one."""
    s = _summary(run)
    assert s["v3"]
    for name, v in s["v3"].items():
        h = v["history"]
        assert len(h) >= 2, name
        assert all(x["search"] == "local" for x in h), (name, [x["local_failed"] for x in h])
        assert h[-1]["sweep_peak_hz"] == pytest.approx(h[-1]["peak_hz"], rel=1e-4), name
        assert h[-1]["sweep_peak_amplitude"] == pytest.approx(h[-1]["peak_amplitude"], rel=1e-3), name
        # the peak the report shows is that full FRF's
        assert s["peaks"][f"{name}@L1"]["peak_hz"] == pytest.approx(h[-1]["sweep_peak_hz"], rel=1e-12)


def test_report_written(run: Path) -> None:
    text = (run / "report.md").read_text()
    for fig in ("frf_configurations", "frf_roughness", "pressure_morphology", "stiffness_maps",
                "status_energy", "hysteresis_loops", "keq_contact_fraction",
                "backbone_frequency", "backbone_damping"):
        assert (run / "figures" / f"{fig}.png").stat().st_size > 1000
        assert f"figures/{fig}.png" in text


def test_backbones_predict_the_forced_peaks(run: Path) -> None:
    """Issue 15: the peak synthesized from each joint's backbone (SNMS + off-resonant background)
    against the forced FRF's polished peak at every level the study swept: frequency within
    0.2 %, amplitude within 5 %, for baseline and v3 on every surface (measured on the quick
    preset: <= 1.8e-4 and <= 6.1e-3)."""
    s = _summary(run)
    bbs = s["backbones"]
    assert sorted(bbs) == ["baseline", "v3-rq1", "v3-rq15"]
    compared, beyond = 0, 0
    for name, v in bbs.items():
        for lvl, r in v["snms_vs_forced"].items():
            if r["forced_hz"] is None:
                continue
            if r["snms_hz"] is None or not np.isfinite(r["snms_hz"]):
                # only a backbone that stopped early (warned about) may miss a peak, and only one
                # beyond its last amplitude
                assert not v["complete"] and r["forced_amplitude"] > v["amplitude_mm"][-1], (name, lvl)
                beyond += 1
                continue
            assert r["snms_hz"] == pytest.approx(r["forced_hz"], rel=2e-3), (name, lvl)
            assert r["snms_amplitude"] == pytest.approx(r["forced_amplitude"], rel=5e-2), (name, lvl)
            # the table's forced peak is the study's curve
            assert r["forced_hz"] == s["peaks"][f"{name}@{lvl}"]["peak_hz"]
            compared += 1
    # baseline and v3 Rq 15 at 3 levels, v3 Rq 1 at L1 (a backbone that stops early, as v1's did
    # when this case had v1, may miss a peak beyond its end: checked above)
    assert compared + beyond == 3 + 3 + 1 and compared >= 6


def test_backbone_files_energy_balance_and_linear_limit(run: Path) -> None:
    """Each stored backbone: the work of the EPMC damping per cycle equals the friction + viscous
    dissipation at every point (Galerkin balance, to the Newton tolerance); its first point is
    the study's stuck mode (dense eigh of the stuck structure, an independent computation) with
    the case's modal damping; the tmdsimpy CSV holds the same numbers; the stored (restricted)
    backbone synthesizes the stored peaks again; zeta doubles inside the range."""
    from hbm import synthesize
    from fe_joint.study.artifacts import load_backbones
    case = load_case(preset="quick")
    s = _summary(run)
    dyn = json.loads((run / "stages" / "dynamics.json").read_text())["summary"]
    bbs = load_backbones(run / "dynamics")
    assert len(bbs) == 3
    for key, br in bbs.items():
        work = br.xi * 2 * np.pi / br.omega * br.kinetic
        diss = br.friction_energy + br.viscous_energy
        assert np.max(np.abs(work / diss - 1)) <= 1e-6, key
        assert br.zeta_energy == pytest.approx(br.zeta, rel=1e-6)
        f_stuck = (s["stuck_frequency_hz"][key.config] if key.config != "v3"
                   else dyn["v3"][key.name]["f_lin"])
        assert br.frequency_hz[0] == pytest.approx(f_stuck, rel=1e-6), key
        assert br.zeta[0] == pytest.approx(case.reduction.damping_ratio, rel=1e-9)
        assert np.all(br.element_status[0] == np.where(br.element_status[0] == 4, 4, 0))
        if br.complete:      # (a backbone that stopped early may end before ζ doubles)
            assert np.isfinite(br.zeta_doubled_amplitude)
        if np.isfinite(br.zeta_doubled_amplitude):
            assert (br.displacement_amplitude[0] < br.zeta_doubled_amplitude
                    < br.displacement_amplitude[-1])
        csv = np.genfromtxt(run / "dynamics" / "backbones" / f"{key.name}.csv", delimiter=",",
                            names=True)
        assert csv.dtype.names == ("modal_amplitude", "displacement_amplitude",
                                   "frequency_rad_per_s", "damping_factor_frac_crit")
        assert np.allclose(csv["frequency_rad_per_s"], br.omega, rtol=1e-11)
        assert np.allclose(csv["damping_factor_frac_crit"], br.zeta, rtol=1e-11)
        bb = br.backbone()
        for i, lv in enumerate(br.levels):
            sr = synthesize(bb, np.array([lv, 0.0]))
            assert sr.in_range == np.isfinite(br.snms_hz[i])
            if sr.in_range:
                assert sr.peak_omega / (2 * np.pi) == pytest.approx(br.snms_hz[i], rel=1e-9)
                assert sr.peak_amplitude == pytest.approx(br.snms_amplitude[i], rel=1e-9)


# the small case of the rank comparison (also scripts/check_ranks.py --small): one configuration
# (baseline; the Rq sweep's v3 fixed point on its one surface always runs, here with one pass),
# one level where the joint slips, one seed, no hardness variant; the pipeline twice (1 and 2
# ranks) inside the MPI phase's time
def _small_case() -> str:
    """scripts/check_ranks.py's small case (one source of it)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "check_ranks", Path(__file__).resolve().parents[1] / "scripts" / "check_ranks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.SMALL_CASE


MPI_CASE = _small_case()
#: what "the same numbers on 1 and 2 ranks" means (README, "In parallel"): FRF peaks to the peak
#: search's resolution (``frf.PEAK_XTOL``, 1e-6 in f; 4x it in amplitude, the slopes of a corner
#: top), backbone frequencies to 1e-7
RANK_PEAK_F_RTOL, RANK_PEAK_A_RTOL = PEAK_XTOL, 4 * PEAK_XTOL
RANK_F_RTOL, RANK_POINTS = 1e-7, 0.05
#: a backbone point's damping ratio on 1 and 2 ranks: a point where the mode's Newton stalls at a
#: kink is accepted at a residual up to ``nonlinear_mode.STAGNATION_FLOOR`` x tol (1e-6), which
#: leaves the damping (the response's small out-of-phase part) less exact than the frequency:
#: session 20 met one such point of the baseline backbone 4.8e-6 apart (its frequency 5.8e-8,
#: every other point's damping within 9e-8), in one of two runs of the same code
RANK_ZETA_RTOL = 1e-5


@pytest.mark.mpi
def test_same_summary_on_one_and_two_ranks(tmp_path_factory) -> None:
    """The small case on 1 rank (COMM_SELF on rank 0) and on 2: every FRF peak within 1e-6 in
    frequency and 4e-6 in amplitude (the peak search's resolution), continuation point counts
    within 5 %, the backbone's frequencies within 1e-7, the contact numbers to round-off. The FE models differ by round-off
    (K 3e-15, M 5e-13, C 7e-11 on the quick mesh: tests/test_fe_mpi.py); the peaks are roots of
    dX/dω solved at strict tolerances, which that round-off cannot move by more."""
    from mpi4py import MPI

    from fe_joint.pipeline.stages import REGISTRY
    comm = MPI.COMM_WORLD
    if comm.size == 1:
        pytest.skip("MPI-only comparison: needs mpirun -n 2 (scripts/test runs it)")
    # PETSc initializes collectively on COMM_WORLD when dolfinx is first imported: every rank
    # imports it before rank 0 runs the serial reference alone
    import dolfinx  # noqa: F401
    d = Path(comm.bcast(str(tmp_path_factory.mktemp("mpi")) if comm.rank == 0 else None, root=0))
    import tomllib
    from fe_joint.case import case_from_dict
    case = case_from_dict(tomllib.loads(MPI_CASE), preset="quick")
    if comm.rank == 0:   # the serial reference, on this rank alone
        run_stages(case, d / "one", STAGES, REGISTRY, comm=MPI.COMM_SELF, progress=False)
    comm.barrier()
    run_stages(case, d / "all", STAGES, REGISTRY, comm=comm, progress=False)
    if comm.rank == 0:
        a, b = _summary(d / "one"), _summary(d / "all")
        assert set(a["peaks"]) == set(b["peaks"]) == {"baseline@L0", "v3-rq15@L0", "check-linear@tiny"}
        for key, p in a["peaks"].items():
            q = b["peaks"][key]
            assert q["peak_hz"] == pytest.approx(p["peak_hz"], rel=RANK_PEAK_F_RTOL), key
            assert q["peak_amplitude"] == pytest.approx(p["peak_amplitude"], rel=RANK_PEAK_A_RTOL), key
            assert abs(q["n_points"] - p["n_points"]) <= RANK_POINTS * max(p["n_points"], q["n_points"]), key
        for key, p in a["backbones"].items():
            q = b["backbones"][key]
            assert q["points"] == p["points"], key
            assert np.allclose(q["frequency_hz"], p["frequency_hz"], rtol=RANK_F_RTOL, atol=0), key
            assert np.allclose(q["zeta"], p["zeta"], rtol=RANK_ZETA_RTOL, atol=0), key
        for rq, v in a["contact_fraction"].items():
            assert b["contact_fraction"][rq] == pytest.approx(v, rel=1e-9)
        for k, v in a["k_eq_vs_rq"].items():
            assert b["k_eq_vs_rq"][k]["kn"] == pytest.approx(v["kn"], rel=1e-9)
        assert b["levels_N"] == a["levels_N"]
