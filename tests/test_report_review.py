"""The reviewer's parts of the report: Findings (verdicts computed from the numbers), the parameter
and provenance tables, Table 1, the per-element XDMF files, the stuck FRF and the new figures.

Built on test_report's synthetic run (six elements, baseline and v3 on Rq 5 µm at two levels);
each expected number is computed here from the arrays written, or from an independent path.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from fe_joint.case import case_from_dict
from fe_joint.report import findings as fd
from fe_joint.report.data import load_report_data
from test_report import AREA, CASE, N0_FE, NE, make_run

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from fe_joint.report import write_report
    out = tmp_path_factory.mktemp("review")
    written = make_run(out)
    case = case_from_dict(json.loads(json.dumps(CASE)))
    summary = write_report(out, case)
    data = load_report_data(out, case)
    return out, written, data, summary


def _by_ref(items, ref: str, topic: str):
    return next(f for f in items if f.ref == ref and f.topic == topic)


# --- Findings ----------------------------------------------------------------------------------

def test_findings_written_with_every_claim(run):
    out, _, _, s = run
    t = json.loads((out / "timings.json").read_text())
    # the cost claims read wall times: their numbers (and verdicts) are in timings.json, so that
    # summary.json is the same bytes for the same inputs
    every = s["findings"] + t["findings"]
    assert ([f["ref"] for f in s["findings"]]
            == [c(run[2], s).ref for c in fd.CLAIMS if c not in fd.COST_CLAIMS])
    assert [f["ref"] for f in t["findings"]] == ["Table 2", "Table 3"]
    assert all(f["verdict"] in (fd.AGREE, fd.DISAGREE, fd.NOT_COMPARABLE) for f in every)
    md = (out / "report.md").read_text()
    # after the warnings and before the mesh line: near the top
    assert md.index("## Findings") < md.index("Mesh:") < md.index("## Excitation levels")
    for f in every:
        assert f"**{f['ref']}, {f['topic']}: {f['verdict']}.**" in md
    # the fixture has no v1/v2/smooth-ms: those claims cannot be tested
    assert _by_ref(fd.findings(run[2], s), "Table 1", "the configurations").verdict == fd.NOT_COMPARABLE


def test_damping_verdict_follows_the_numbers(run):
    """Figs. 16–18: the multiscale joint more damped and lower → agree; the other way → disagree."""
    _, _, data, s = run
    s = copy.deepcopy(s)
    for i in (0, 1):
        b, m = s["peaks"][f"baseline@L{i}"], s["peaks"][f"v3-rq5@L{i}"]
        b["zeta_fric"], m["zeta_fric"] = 1e-3, 2e-3
        b["peak_amplitude"], m["peak_amplitude"] = 0.5, 0.4
    f = fd.fig16_damping(data, s)
    assert f.verdict == fd.AGREE
    assert "baseline 1.000e-03 / 500 µm vs v3-rq5 2.000e-03 / 400 µm" in f.ours
    for i in (0, 1):
        s["peaks"][f"v3-rq5@L{i}"]["zeta_fric"] = 0.5e-3
        s["peaks"][f"v3-rq5@L{i}"]["peak_amplitude"] = 0.6
    assert fd.fig16_damping(data, s).verdict == fd.DISAGREE


def test_contact_area_verdicts(run):
    """Fig. 20: the trend flips with the numbers; the absolute values are compared only on the
    paper's 256² grid, within 25 %."""
    _, _, data, s = run
    s = copy.deepcopy(s)
    s["contact_area"]["1"]["fraction_overlap"], s["contact_area"]["5"]["fraction_overlap"] = 0.2, 0.1
    assert fd.fig20_trend(data, s).verdict == fd.AGREE
    s["contact_area"]["5"]["fraction_overlap"] = 0.3
    assert fd.fig20_trend(data, s).verdict == fd.DISAGREE
    assert fd.fig20_values(data, s).verdict == fd.NOT_COMPARABLE       # 16² grid
    rough = dataclasses.replace(data.case.roughness, grid=256)
    d256 = dataclasses.replace(data, case=dataclasses.replace(data.case, roughness=rough))
    s.pop("seeds", None)
    s["contact_area"]["1"]["fraction_overlap"] = 0.221 * 1.2                 # +20 %: close
    f = fd.fig20_values(d256, s)
    assert f.verdict == fd.AGREE and "26.52 %" in f.ours and "+20.00 %" in f.ours
    s["contact_area"]["1"]["fraction_overlap"] = 0.221 * 1.3                 # +30 %: not
    assert fd.fig20_values(d256, s).verdict == fd.DISAGREE


def test_stiffness_verdicts(run):
    """Fig. 15 ordering, Fig. 14 local k_t/k_n spread and Fig. 8 smooth-ms k_n, each flipped."""
    _, w, data, s = run
    s = copy.deepcopy(s)
    s["k_eq"].update({"v1": {"kn": 9e3, "kt": 9e3}, "v2": {"kn": 5e3, "kt": 4e3}})
    s["k_eq"]["baseline"] = {"kn": 1.2e4, "kt": 1.2e4}
    s["k_eq"]["v3"] = {"kn": 4e3, "kt": 3e3}
    assert fd.fig15(data, s).verdict == fd.AGREE
    s["k_eq"]["v1"]["kn"] = 3e3
    assert fd.fig15(data, s).verdict == fd.DISAGREE
    mindlin = 2 * (1 - 0.3) / (2 - 0.3)
    kn = w["kv3"]["kn"]
    exact = dataclasses.replace(data, v3_arrays={5.0: {"kn": kn, "kt": mindlin * kn}})
    f = fd.fig14(exact, s)
    assert f.verdict == fd.DISAGREE and f"median {mindlin:.4f}" in f.ours
    scatter = mindlin * np.linspace(0.8, 1.2, NE)
    spread = dataclasses.replace(data, v3_arrays={5.0: {"kn": kn, "kt": scatter * kn}})
    assert fd.fig14(spread, s).verdict == fd.AGREE
    # smooth-ms k_n: following the pressure with mean k_ref → agree; uniform 2 k_ref → disagree
    k_ref, p = data.case.contact.k_ref, data.rm.preload_pressure
    follow = dict(data.extra, kn_smooth=k_ref * p / p[p > 0].mean())
    s["kn_smooth_mean"] = float(np.mean(follow["kn_smooth"]))
    s["kn_smooth_max"] = float(np.max(follow["kn_smooth"]))
    assert fd.fig8(dataclasses.replace(data, extra=follow), s).verdict == fd.AGREE
    flat = dict(data.extra, kn_smooth=np.where(p > 0, 2 * k_ref, 0.0))
    s["kn_smooth_mean"] = float(np.mean(flat["kn_smooth"]))
    f = fd.fig8(dataclasses.replace(data, extra=flat), s)
    assert f.verdict == fd.DISAGREE and "flat-punch" in f.why


# --- parameters, provenance, Table 1 -------------------------------------------------------------

def test_parameter_table_shows_the_case(run):
    out, _, data, _ = run
    from fe_joint.report.provenance import parameters
    rows = {p.key: p.value for p in parameters(data)}
    assert rows["contact.mu"] == "0.6"
    assert rows["contact.k_ref"] == f"{12345.678:.4g}"
    assert rows["roughness.grid"] == "16²" and rows["roughness.patch"] == "4²"
    assert rows["roughness.rq_um"] == "1, 5" and rows["roughness.v_rq_um"] == "5"
    assert rows["dynamics.levels"] == "1, 3 (case)"
    assert rows["(middle level)"] == "L1 = 3"
    assert rows["dynamics.harmonics"] == "3" and rows["dynamics.samples"] == "128"
    md = (out / "report.md").read_text()
    assert "| reference stiffness k_ref (baseline k_n = k_t) | 1.235e+04 | N/mm³ |" in md


def test_provenance_from_manifests_and_outside_git(run, tmp_path):
    from fe_joint.pipeline.environment import git_describe, run_environment
    from fe_joint.report.provenance import NOT_RECORDED, provenance
    _, _, data, s = run
    assert git_describe(tmp_path) == "unknown"          # not a checkout
    p = provenance(data)                                 # the fixture recorded no environment
    assert p["commit_source"] == "report" and p["ranks"] == NOT_RECORDED
    assert p["versions"]["numpy"] == NOT_RECORDED
    env = run_environment(None)
    assert env["ranks"] == 1 and env["packages"]["numpy"] == np.__version__
    assert ("dolfinx" in env["packages"]) == ("dolfinx" in sys.modules)   # never imported here
    e_fe = dict(env, commit="abc1234", packages={**env["packages"], "dolfinx": "0.5.2"}, ranks=2)
    d2 = dataclasses.replace(data, environments={"fe": e_fe, "dynamics": dict(e_fe)})
    p2 = provenance(d2)
    assert (p2["commit"], p2["commit_source"], p2["ranks"]) == ("abc1234", "run", "2")
    assert p2["versions"]["dolfinx"] == "0.5.2"


def test_runner_records_the_environment(tmp_path):
    """A stage manifest carries the commit, ranks and versions of the process that ran it."""
    from fe_joint.pipeline.environment import git_describe
    from fe_joint.pipeline.runner import read_manifest, run_stages
    case = case_from_dict({"name": "env"})
    run_stages(case, tmp_path, ("mesh",), {"mesh": lambda ctx: {"n": 1}}, progress=False)
    env = read_manifest(tmp_path, "mesh")["environment"]
    assert env["ranks"] == 1 and env["commit"] == git_describe()
    assert env["packages"]["numpy"] == np.__version__


def test_table1_counts(run):
    from fe_joint.report.table1 import table1_rows
    _, w, data, _ = run
    rows = {r["config"]: r for r in table1_rows(data)}
    assert list(rows) == ["baseline", "v3"]
    assert rows["baseline"]["loaded"] == int(np.sum(N0_FE > 0)) == 5
    assert rows["baseline"]["active"] == NE                      # k_ref on every pair
    n0 = w["surfaces"][5.0].n0
    assert rows["v3"]["loaded"] == int(np.sum(n0 > 0))
    assert rows["v3"]["active"] == int(np.sum((w["kv3"]["kn"] > 0) & (w["kv3"]["kt"] > 0)))
    assert rows["v3"]["sum_n0"] == pytest.approx(math.fsum(n0), rel=1e-14)


# --- per-element XDMF ----------------------------------------------------------------------------

def _read_xdmf(path):
    root = ET.parse(path).getroot()
    grid = root.find("Domain/Grid")
    fields = {}
    with h5py.File(path.with_suffix(".h5"), "r") as f:
        for att in grid.findall("Attribute"):
            item = att.find("DataItem")
            h5name, loc = item.text.strip().split(":")
            assert h5name == path.with_suffix(".h5").name
            assert item.get("Dimensions") == str(NE) and att.get("Center") == "Node"
            fields[att.get("Name")] = f[loc][()]
        geo = f[grid.find("Geometry/DataItem").text.split(":")[1]][()]
    return root, grid, fields, geo


def test_xdmf_round_trip(run):
    out, w, data, _ = run
    files = sorted((out / "paraview").glob("*.xdmf"))
    assert [f.stem for f in files] == sorted(k.name for k in w["curves"])
    k_ref = CASE["contact"]["k_ref"]
    for key, cr in w["curves"].items():
        path = out / "paraview" / f"{key.name}.xdmf"
        root, grid, f, geo = _read_xdmf(path)
        assert root.tag == "Xdmf" and root.get("Version") == "3.0"
        topo = grid.find("Topology")
        assert topo.get("TopologyType") == "Polyvertex" and topo.get("NumberOfElements") == str(NE)
        assert np.array_equal(geo[:, :2], data.xy) and geo.shape == (NE, 3)
        assert np.array_equal(f["status"], cr.status) and np.array_equal(f["energy"], cr.energy)
        assert np.allclose(f["energy_per_area"], cr.energy / AREA, rtol=1e-15)
        if key.config == "baseline":
            n0, kn, kt = N0_FE, np.full(NE, k_ref), np.full(NE, k_ref)
        else:
            n0, kn, kt = w["surfaces"][5.0].n0, w["kv3"]["kn"], w["kv3"]["kt"]
        assert np.array_equal(f["N0"], n0) and np.array_equal(f["kn"], kn) and np.array_equal(f["kt"], kt)
        # slip of element e by hand: w = u − T / (k_t A), half its range; 0 if open or k = 0
        for e in range(NE):
            wv = cr.elem_u[e] - cr.elem_T[e] / (kt[e] * AREA[e]) if kt[e] > 0 else 0 * cr.elem_u[e]
            expect = 0.0 if cr.status[e] == 4 or kn[e] == 0 or kt[e] == 0 else 0.5 * (wv.max() - wv.min())
            assert f["slip_amplitude"][e] == pytest.approx(expect, rel=1e-12, abs=0)
        assert f["u_amplitude"] == pytest.approx(0.5 * np.ptp(cr.elem_u, axis=1), rel=1e-14)


def test_xdmf_read_by_meshio(run):
    meshio = pytest.importorskip("meshio")
    out, w, data, _ = run
    key, cr = next(iter(w["curves"].items()))
    m = meshio.read(out / "paraview" / f"{key.name}.xdmf")
    assert m.points.shape == (NE, 3) and np.array_equal(m.points[:, :2], data.xy)
    assert m.cells[0].type == "vertex" and len(m.cells[0].data) == NE
    assert np.array_equal(m.point_data["status"], cr.status)
    assert np.array_equal(m.point_data["energy"], cr.energy)


def test_report_links_the_xdmf_files(run):
    out, w, _, _ = run
    md = (out / "report.md").read_text()
    for key in w["curves"]:
        assert f"(paraview/{key.name}.xdmf)" in md


# --- stuck FRF and figures -------------------------------------------------------------------------

def _two_pair_model(seed: int, n: int):
    """A random SPD model of n DOFs with two pairs (DOFs 0-11), one loaded: (rm-like, joint,
    stuck K_s, its modal damping C with ζ = 2e-3)."""
    from fe_joint.model.joint import JointModel, stuck_stiffness
    from fe_joint.model.reduced_model import modal_damping_matrix
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    K = A @ A.T + n * np.eye(n)
    M = np.diag(rng.uniform(1e-3, 2e-3, n))
    pd = np.arange(12).reshape(2, 2, 3)
    rm = type("RM", (), dict(K=K, M=M, pair_dofs=pd, damping_ratio=2e-3, excitation_dof=0,
                             response_dof=5))()
    joint = JointModel("j", n0=np.array([10.0, 0.0]), gap=np.zeros(2), kn=np.array([3e3, 1e3]),
                       kt=np.array([2e3, 1e3]), area=np.array([1.0, 2.0]))
    Ks = stuck_stiffness(K, pd, joint)
    return rm, joint, Ks, modal_damping_matrix(Ks, M, 2e-3)[0]


def test_stuck_receptance_against_a_direct_solve():
    """Modal superposition against (K_s − ω²M + iωC)⁻¹ with C = M Φ diag(2ζω) Φᵀ M of the stuck
    structure, solved directly on a small two-body model with two pairs."""
    from fe_joint.report.linear_frf import stuck_receptance
    n = 12
    rm, joint, Ks, C = _two_pair_model(3, n)
    M = rm.M
    f = np.linspace(50, 400, 7)
    direct = np.array([np.linalg.solve(Ks - (2 * np.pi * x) ** 2 * M + 2j * np.pi * x * C, np.eye(n)[0])[5]
                       for x in f])
    assert np.allclose(stuck_receptance(rm, joint, f), direct, rtol=1e-9, atol=0)


def test_stuck_receptance_damps_every_elastic_mode_of_a_free_free_model():
    """A free–free chain whose stiffest spring puts its highest mode 1e5 times above its first
    elastic one (as a Craig–Bampton model's boundary DOFs do): every elastic mode gets ζ, the
    rigid one none, against the direct solve with C = M Φ diag(2ζω) Φᵀ M. (The rigid modes were
    those below 1e-4 of the highest frequency: the default model's first two elastic modes, at
    247 and 540 Hz, were undamped in the report's stuck FRFs until session 24.)"""
    from fe_joint.model.joint import JointModel
    from fe_joint.model.reduced_model import modal_damping_matrix
    from fe_joint.report.linear_frf import StuckReceptance
    n = 12
    k = np.full(n - 1, 1e3)
    k[5] = 1e11
    K = np.zeros((n, n))
    for i, ki in enumerate(k):
        K[i:i + 2, i:i + 2] += ki * np.array([[1.0, -1.0], [-1.0, 1.0]])
    M = np.eye(n) * 1e-3
    rm = type("RM", (), dict(K=K, M=M, pair_dofs=np.arange(12).reshape(2, 2, 3),
                             damping_ratio=2e-3, excitation_dof=0, response_dof=9))()
    joint = JointModel("j", n0=np.zeros(2), gap=np.zeros(2), kn=np.ones(2), kt=np.ones(2),
                       area=np.ones(2))                  # nothing loaded: K_s = K
    w2 = np.linalg.eigvalsh(K / 1e-3)
    assert np.sqrt(w2[-1] / w2[1]) > 1e4
    C, _ = modal_damping_matrix(K, M, 2e-3)
    f = np.sqrt(w2[1:4]) / (2 * np.pi)                  # at the first three elastic modes
    direct = np.array([np.linalg.solve(K - (2 * np.pi * x) ** 2 * M + 2j * np.pi * x * C, np.eye(n)[0])[9]
                       for x in f])
    r = StuckReceptance(rm, joint)
    assert np.count_nonzero(r.zeta == 0.0) == 1
    # 1e-4: the 1e8 stiffness contrast costs both solutions digits (they differ by 3.5e-5 of |X|
    # at the first resonance); an undamped mode would be off by 100 %
    assert np.allclose(r(f), direct, rtol=1e-4, atol=0)


def test_stuck_receptance_of_kept_modes_and_static_residual(monkeypatch):
    """A model above ALL_MODES_UP_TO DOFs keeps its lowest KEPT_MODES modes and the others'
    static response: exact at 0 Hz against the direct solve, and off by the discarded modes'
    dynamic part, (f / f_kept+1)² of them, below the kept modes."""
    from fe_joint.report import linear_frf
    n = 16
    rm, joint, Ks, C = _two_pair_model(5, n)
    M = rm.M
    monkeypatch.setattr(linear_frf, "ALL_MODES_UP_TO", 10)
    monkeypatch.setattr(linear_frf, "KEPT_MODES", 6)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(M, Ks)).real)
    f7 = np.sqrt(w2[6]) / (2 * np.pi)
    f = np.array([0.0, 0.05, 0.1, 0.2]) * f7
    direct = np.array([np.linalg.solve(Ks - (2 * np.pi * x) ** 2 * M + 2j * np.pi * x * C, np.eye(n)[0])[5]
                       for x in f])
    got = linear_frf.StuckReceptance(rm, joint)(f)
    assert got[0] == pytest.approx(direct[0], rel=1e-10)
    static = linear_frf.StuckReceptance(rm, joint).static
    assert static != 0.0
    for x, g, d in zip(f[1:], got[1:], direct[1:]):
        assert abs(g - d) <= 2 * (x / f7) ** 2 * abs(static)


def test_stuck_receptance_cache_and_parts_from_another_rank(monkeypatch):
    """The receptances are cached by model and springs (the FRF figures ask once per panel); parts
    computed on another rank (``share_eigenproblems``) are served as if computed here; another
    joint's springs miss the cache."""
    import scipy.linalg as sla

    from fe_joint.model.joint import JointModel
    from fe_joint.report import linear_frf
    rng = np.random.default_rng(4)
    n = 12
    A = rng.normal(size=(n, n))
    rm = type("RM", (), dict(K=A @ A.T + n * np.eye(n), M=np.diag(rng.uniform(1e-3, 2e-3, n)),
                             pair_dofs=np.arange(12).reshape(2, 2, 3), damping_ratio=2e-3,
                             excitation_dof=0, response_dof=5))()

    def joint(kn):
        return JointModel("j", n0=np.array([10.0, 0.0]), gap=np.zeros(2), kn=np.array([kn, 1e3]),
                          kt=np.array([2e3, 1e3]), area=np.array([1.0, 2.0]))
    calls = []
    eigh = sla.eigh
    monkeypatch.setattr(linear_frf.sla, "eigh", lambda *a, **k: calls.append(1) or eigh(*a, **k))
    f = np.linspace(50, 400, 5)
    first = linear_frf.StuckReceptance(rm, joint(3e3))(f)
    again = linear_frf.StuckReceptance(rm, joint(3e3))(f)
    assert len(calls) == 1 and np.array_equal(first, again)
    fake = (np.array([4.0, 9.0]), np.array([2.0, 3.0]), np.array([0.0, 0.1]), np.array([1.0, -1.0]),
            0.0)
    linear_frf.StuckReceptance.from_parts(rm, joint(5e3), fake)
    got = linear_frf.StuckReceptance(rm, joint(5e3))(np.array([0.0]))
    assert len(calls) == 1 and got[0] == pytest.approx(1.0 / 4.0 - 1.0 / 9.0)
    linear_frf.StuckReceptance(rm, joint(7e3))
    assert len(calls) == 2


def test_new_figures_drawn_and_linked(run):
    out, _, _, _ = run
    md = (out / "report.md").read_text()
    for name in ("fig13_heights", "fig17_all_configurations", "fig21_levels", "fig22_loops_rq",
                 "ratio_maps_v3_v2"):
        assert (out / "figures" / f"{name}.png").read_bytes()[:8] == PNG, name
        assert f"figures/{name}.png" in md
    # no smooth-ms in the fixture: no Fig. 12 counterpart, and no link to a missing file
    assert not (out / "figures" / "fig12_smooth_maps.png").exists()
    assert "fig12_smooth_maps" not in md


def test_zone_verdict_follows_the_status_map(run):
    """Fig. 12: stuck inside, slipping further out, open at the edge → agree, with the mean
    radii of the groups computed here; the reverse map → disagree."""
    from test_report import XY
    _, _, data, s = run
    r = np.hypot(XY[:, 0], XY[:, 1])
    order = np.argsort(r)
    ordered = np.empty(NE, int)
    ordered[order] = [0, 0, 1, 1, 1, 3]                # radii ascending: stuck, slipping, opening
    curves = dict(data.curves)
    for k in [k for k in curves if k.config == "baseline"]:
        curves[k] = dataclasses.replace(curves[k], status=ordered)
    f = fd.fig12(dataclasses.replace(data, curves=curves), s)
    assert f.verdict == fd.AGREE
    assert f"stuck {np.mean(r[order[:2]]):.2f} mm, slipping {np.mean(r[order[2:5]]):.2f} mm, " \
           f"opening {r[order[5]]:.2f} mm" in f.ours
    rev = np.empty(NE, int)
    rev[order] = [3, 1, 1, 1, 0, 0]
    for k in [k for k in curves if k.config == "baseline"]:
        curves[k] = dataclasses.replace(curves[k], status=rev)
    assert fd.fig12(dataclasses.replace(data, curves=curves), s).verdict == fd.DISAGREE


def test_provenance_times_ignore_the_report_stage(run):
    """The stage-log times are those of the computing stages: the report's own entry (logged after
    report.md is written) does not change a rebuilt report."""
    from fe_joint.report.provenance import provenance
    _, _, data, _ = run
    log = [{"stage": "mesh", "action": "ran", "time": "T1"}, {"stage": "dynamics", "action": "ran", "time": "T2"},
           {"stage": "report", "action": "ran", "time": "T3"}, {"stage": "fe", "action": "cached", "time": "T4"}]
    p = provenance(dataclasses.replace(data, stage_log=log))
    assert (p["started"], p["finished"]) == ("T1", "T2")


def test_timed_trends_fall_beyond_the_noise():
    """The cost claims read wall times: a trend falls when no step rises by more than
    TIMING_NOISE and the whole falls by more (two runs of one code: 0.36 → 0.12 → 0.12 and
    0.54 → 0.14 → 0.14 s both fall); a clear rise or a fall within the noise does not."""
    assert fd.TIMING_NOISE == 0.1
    assert fd._falls_timed([0.54, 0.20, 0.14, 0.14]) and fd._falls_timed([0.36, 0.17, 0.12, 0.125])
    assert not fd._falls_timed([32.9, 22.1, 20.1, 25.1])        # rises by 25 % at the end
    assert not fd._falls_timed([1.0, 0.95, 0.97])               # falls by 3 % only
    assert not fd._falls_timed([1.0])
