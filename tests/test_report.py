"""The report on a tiny synthetic run folder written with the real writers.

Six friction elements, two excitation levels, two surfaces (Rq 1 and 5 µm); baseline and v3 on
the comparison surface (Rq 5) at both levels, no v3 fixed point on Rq 1 (its k_eq then comes from
the surface's v2 stiffness). Every expected number is computed here from the arrays written.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fe_joint.case import case_from_dict
from fe_joint.model.reduced_model import ReducedModel
from fe_joint.study.artifacts import CurveKey
from fe_joint.study.contact import SurfaceContact, save_surfaces
from fe_joint.study.frf import CurveResult

REPO = Path(__file__).resolve().parents[1]
FIGURES = ("frf_configurations", "frf_roughness", "pressure_morphology", "stiffness_maps",
           "status_energy", "hysteresis_loops", "keq_contact_fraction")
CASE = {"name": "tiny",
        "roughness": {"rq_um": [1.0, 5.0], "v_rq_um": 5.0, "grid": 16, "patch": 4},
        "contact": {"k_ref": 12345.678},   # not a power of two: Σ k A / Σ A is not k exactly
        "dynamics": {"configurations": ["baseline", "v3"], "levels": [1.0, 3.0]}}
LEVELS = [1.0, 3.0]
MACROSLIP = 10.0
NE, NT, GRID = 6, 8, 8

# element centres (mm) on the overlap, outside the 8.5 mm hole; areas (mm²); FE preload (N)
XY = np.array([[-7.0, -6.0], [-5.0, 5.0], [0.0, 7.5], [6.0, 0.5], [8.0, -8.0], [-8.5, 0.0]])
AREA = np.array([1.0, 2.0, 1.5, 0.5, 3.0, 2.5])
N0_FE = np.array([100.0, 250.0, 0.0, 80.0, 40.0, 30.0])


def _reduced_model() -> ReducedModel:
    """A reduced model with the pair data the report reads; K, M only shaped right."""
    n = 2 * 3 * NE + 3
    frame = np.repeat(np.eye(3)[None], NE, axis=0)
    return ReducedModel(
        K=np.eye(n), M=np.eye(n), C=np.zeros((n, n)), damping_ratio=1e-3,
        dof_labels=[f"dof{i}" for i in range(n)], pair_xyz=np.c_[XY, np.zeros(NE)], pair_area=AREA,
        pair_frame=frame, pair_dofs=np.arange(6 * NE).reshape(NE, 2, 3), preload_normal_force=N0_FE,
        preload_pressure=N0_FE / AREA, preload_gap=np.where(N0_FE > 0, 0.0, 2e-3),
        preload_status=(N0_FE > 0).astype(int), excitation_dof=n - 3, response_dof=n - 3,
        full_frequencies=np.array([0.0, 250.0]), reduced_frequencies=np.array([0.0, 250.1]),
        n_boundary=n)


def _surface(rq: float, rng: np.random.Generator) -> SurfaceContact:
    """A surface whose rough loads leave element 2 (and for Rq 5 also element 5) unloaded."""
    n0 = N0_FE * rng.uniform(0.5, 1.5, NE)
    if rq == 5.0:
        n0[5] = 0.0
    kn = np.where(n0 > 0, rng.uniform(1e3, 5e4, NE), 0.0)
    pressure = rng.uniform(0.0, 300.0, (GRID, GRID)) * (rng.random((GRID, GRID)) < 0.3)
    return SurfaceContact(
        rq_um=rq, z=rng.normal(0, rq * 1e-3, (GRID, GRID)), pressure=pressure,
        gap=rng.uniform(0, 1e-3, (GRID, GRID)), contact_fraction=float(np.mean(pressure > 0)),
        iterations=7, n0=n0, gap_el=np.where(n0 > 0, 0.0, 1e-3), pressure_el=n0 / AREA,
        contact_fraction_el=rng.uniform(0, 0.5, NE), kn=kn, kt_mindlin=0.8 * kn, load_scale=1.01,
        seconds={"global": 0.1, "patches_normal": 0.2})


def _curve(key: CurveKey, level: float, f0: float, rng: np.random.Generator) -> CurveResult:
    """A resonance curve around f0 (Hz) with random element states; the peak is its maximum."""
    omega = np.linspace(f0 - 5, f0 + 5, 41)
    amp = level * 1e-3 / np.sqrt((1 - (omega / f0) ** 2) ** 2 + 1e-4)
    k = int(np.argmax(amp))
    phase = np.linspace(0, 2 * np.pi, NT, endpoint=False)
    elem_u = rng.uniform(1e-4, 1e-3, (NE, 1)) * np.cos(phase)
    status = rng.integers(0, 5, NE)
    status[0] = 1                                       # at least one element to draw a loop of
    return CurveResult(
        level=level, omega_hz=omega, amplitude=amp,
        stable=np.arange(len(omega)) != k + 3, peak_hz=float(omega[k]), peak_amplitude=float(amp[k]),
        status=status, energy=rng.uniform(0, 1e-3, NE), mean_normal=N0_FE.copy(),
        q_amp=rng.uniform(0, 10, (NE, 2)), loop_u=elem_u.mean(axis=0), loop_T=50 * np.sin(phase),
        elem_u=elem_u, elem_T=5 * np.sin(phase) * np.ones((NE, 1)), seconds=1.25,
        newton_iterations=12, n_points=len(omega), n_active=int(np.sum(status < 4)),
        n_nonlinear=int(np.sum((status > 0) & (status < 4))),
        # one curve per level handed over to a tighter tolerance at a fold (2 Hz below its peak)
        sweep_tol=1e-7 if key.level_index == 1 else 1e-6,
        handover_hz=float(omega[k] - 2) if key.level_index == 1 else float("nan"), **key.to_fields())


def _manifest(folder: Path, stage: str, seconds: float, summary: dict) -> None:
    (folder / "stages" / f"{stage}.json").write_text(
        json.dumps({"stage": stage, "key": "0" * 16, "seconds": seconds, "summary": summary}))


def _write_manifests(run: Path) -> None:
    """The five stage manifests the report reads (what the stages would have summarized)."""
    _manifest(run, "mesh", 1.5, {"n_nodes": 40, "n_cells": 60, "n_dofs": 120, "n_pairs": NE})
    _manifest(run, "fe", 2.5, {"full_elastic_hz": [250.0, 900.0], "max_rel_freq_error": 4e-4,
                               "timings": {"total_s": 2.0}})
    _manifest(run, "contact", 0.5, {"coupling_rel_error": 3e-11, "surfaces": {
        "1": {"seconds": {"global": 0.1}}, "5": {"seconds": {"global": 0.2}}}})
    _manifest(run, "dynamics", 9.0, {
        "levels": LEVELS, "level_info": {"macroslip": MACROSLIP},
        "f_lin": {"baseline": 251.0, "v1": 249.0, "v2": 245.0}, "linear_peak_rel_error": 2e-6,
        "queue": {"seconds": 8.0, "busy": [0.95, 0.5]}})
    _manifest(run, "speed", 4.0, {"tables": ["grid"], "skipped": False,
                                  "queue": {"seconds": 3.5, "busy": [1.0, 0.75]}})


def make_run(run: Path) -> dict:
    """Write a synthetic run folder; returns what was written (for the expected numbers)."""
    rng = np.random.default_rng(7)
    for d in ("stages", "fe", "contact", "dynamics", "speed"):
        (run / d).mkdir(parents=True)
    _reduced_model().save(str(run / "fe" / "reduced_model.h5"))
    surfaces = {rq: _surface(rq, rng) for rq in (1.0, 5.0)}
    c = np.arange(GRID) - (GRID - 1) / 2
    hole = np.hypot(*np.meshgrid(c, c, indexing="ij")) < GRID / 5       # the bolt hole, masked
    p_s = rng.uniform(0, 200, (GRID, GRID)) * (rng.random((GRID, GRID)) < 0.8) * ~hole
    extra = {"kn_smooth": rng.uniform(2e4, 9e4, NE), "p_s": p_s, "mask": ~hole}
    save_surfaces(run / "contact" / "surfaces.npz", surfaces, extra)
    curves = {}
    for i, lv in enumerate(LEVELS):
        for key, f0 in ((CurveKey("baseline", i), 250.0), (CurveKey("v3", i, 5.0), 244.0)):
            curves[key] = _curve(key, lv, f0 - i, rng)
            curves[key].save(run / "dynamics" / f"{key.name}.npz")
    kv3 = {"kn": surfaces[5.0].kn * 1.1, "kt": surfaces[5.0].kt_mindlin * 0.9}
    np.savez(run / "dynamics" / "v3-rq5.arrays.npz", **kv3)
    history = [{"pass": p, "peak_hz": 244.0 + 0.1 * p, "kt_eq": 1e4 + p, "search": "local",
                "points": 9, "seconds": 1.0, "relaxation": 1.0} for p in range(3)]
    (run / "dynamics" / "v3-rq5.json").write_text(json.dumps(
        {"job": {"name": "v3-rq5"}, "history": history, "converged": True, "rq_um": 5.0}))
    speed = {"grid": [{"grid": 32, "error": 0.01, "time [s]": 0.5}]}
    (run / "speed" / "speed_error.json").write_text(json.dumps(speed))
    _write_manifests(run)
    return {"surfaces": surfaces, "extra": extra, "curves": curves, "kv3": kv3, "history": history,
            "speed": speed}


def hand_k_eq(k, area=AREA) -> float:
    """Σ k_i A_i / Σ A_i by an exact-rounding sum over the elements."""
    return math.fsum(float(a) * float(b) for a, b in zip(k, area)) / math.fsum(area)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    from fe_joint.report import write_report
    run = tmp_path_factory.mktemp("run")
    written = make_run(run)
    case = case_from_dict(json.loads(json.dumps(CASE)))
    return run, written, write_report(run, case)


def test_every_figure_and_text_written(report):
    run, _, summary = report
    for name in FIGURES:
        png = run / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    md = (run / "report.md").read_text()
    for name in FIGURES:
        assert f"figures/{name}.png" in md
    assert json.loads((run / "summary.json").read_text()) == json.loads(json.dumps(summary, default=float))


def test_figures_shared_by_two_ranks_are_the_figures_of_one(report, tmp_path):
    """draw_figures' shares of 2 ranks are disjoint and together draw what one rank draws."""
    from fe_joint.report.data import load_report_data
    from fe_joint.report.figures import draw_figures
    run = report[0]
    data = load_report_data(run, case_from_dict(json.loads(json.dumps(CASE))))
    one = draw_figures(data, tmp_path / "one")
    shares = [draw_figures(data, tmp_path / "two", r, 2) for r in (0, 1)]
    assert shares[0] and shares[1]
    assert not {p.name for p in shares[0]} & {p.name for p in shares[1]}
    assert sorted(p.name for p in shares[0] + shares[1]) == sorted(p.name for p in one)
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == sorted(p.name for p in one)


def test_figure_ranks_deal_every_figure_once_and_fewer_to_rank_0():
    """On 2 ranks rank 0 draws one figure in RANK0_CYCLE (it writes the summary too); on 3 each
    other rank draws RANK0_CYCLE - 1 times as many as rank 0; one rank draws all."""
    from fe_joint.report.figures import RANK0_CYCLE, figure_ranks
    two = figure_ranks(16, 2)
    assert two.count(0) == 16 // RANK0_CYCLE and two.count(1) == 16 - 16 // RANK0_CYCLE
    cycle = 1 + 2 * (RANK0_CYCLE - 1)
    three = figure_ranks(3 * cycle, 3)
    assert [three.count(r) for r in range(3)] == [3, 3 * (RANK0_CYCLE - 1), 3 * (RANK0_CYCLE - 1)]
    assert figure_ranks(5, 1) == [0] * 5


def test_k_eq_against_hand_sums(report):
    _, w, s = report
    sv, k_ref = w["surfaces"][5.0], CASE["contact"]["k_ref"]
    expected = {
        "baseline": (hand_k_eq([k_ref] * NE),) * 2,
        "smooth-ms": (hand_k_eq(w["extra"]["kn_smooth"]),) * 2,
        # v1: k_ref on the elements the rough surface loads, 0 elsewhere
        "v1": (k_ref * math.fsum(AREA[sv.n0 > 0]) / math.fsum(AREA),) * 2,
        "v2": (hand_k_eq(sv.kn), hand_k_eq(sv.kt_mindlin)),
        "v3": (hand_k_eq(w["kv3"]["kn"]), hand_k_eq(w["kv3"]["kt"])),
    }
    assert list(s["k_eq"]) == list(expected)
    for name, (kn, kt) in expected.items():
        assert s["k_eq"][name]["kn"] == pytest.approx(kn, rel=1e-14), name
        assert s["k_eq"][name]["kt"] == pytest.approx(kt, rel=1e-14), name
    s1 = w["surfaces"][1.0]   # no v3 fixed point on Rq 1: its v2 start
    assert s["k_eq_vs_rq"]["1"]["kn"] == pytest.approx(hand_k_eq(s1.kn), rel=1e-14)
    assert s["k_eq_vs_rq"]["1"]["kt"] == pytest.approx(hand_k_eq(s1.kt_mindlin), rel=1e-14)
    assert s["k_eq_vs_rq"]["5"] == s["k_eq"]["v3"]


def test_contact_numbers(report):
    _, w, s = report
    sf = w["surfaces"]
    assert s["contact_fraction"] == {"1": np.mean(sf[1.0].pressure > 0), "5": np.mean(sf[5.0].pressure > 0)}
    kn_s = w["extra"]["kn_smooth"]
    assert s["kn_smooth_mean"] == pytest.approx(math.fsum(kn_s) / NE, rel=1e-14)
    assert s["kn_smooth_max"] == max(kn_s)
    assert s["coupling_rel_error"] == 3e-11


def test_contact_area_on_three_nominal_areas(report):
    """Real area / usable, / whole overlap (the paper's) and / FE-loaded, counted by hand."""
    _, w, s = report
    mask, p_s = w["extra"]["mask"], w["extra"]["p_s"]
    for rq, sc in w["surfaces"].items():
        c = s["contact_area"]["1" if rq == 1.0 else "5"]
        real = np.sum((sc.pressure > 0) & mask)
        assert c["fraction_usable"] == pytest.approx(real / mask.sum(), rel=1e-12)
        assert c["fraction_overlap"] == pytest.approx(real / GRID ** 2, rel=1e-12)
        assert c["fraction_fe_loaded"] == pytest.approx(real / np.sum((p_s > 0) & mask), rel=1e-12)
        assert c["peak_pressure_MPa"] == sc.pressure.max()


def test_peaks_equal_the_curves(report):
    _, w, s = report
    assert set(s["peaks"]) == {"baseline@L0", "baseline@L1", "v3-rq5@L0", "v3-rq5@L1"}
    for key, cr in w["curves"].items():
        p = s["peaks"][key.name]
        k = int(np.argmax(cr.amplitude))
        assert (p["peak_hz"], p["peak_amplitude"]) == (cr.omega_hz[k], cr.amplitude[k])
        assert p["level"] == LEVELS[key.level_index]
        assert p["dissipated"] == pytest.approx(math.fsum(cr.energy), rel=1e-14)
        assert (p["n_points"], p["n_active"], p["n_nonlinear"]) == (41, np.sum(cr.status < 4),
                                                                    np.sum((cr.status > 0) & (cr.status < 4)))


def test_levels_v3_timings_speed(report):
    run, w, s = report
    assert s["levels_N"] == LEVELS
    assert s["levels_over_macroslip"] == pytest.approx([0.1, 0.3], rel=1e-15)
    assert s["macroslip_estimate_N"] == MACROSLIP
    assert s["stuck_frequency_hz"]["baseline"] == 251.0
    assert s["first_elastic_hz_full_free"] == 250.0
    assert s["mesh"] == {"n_nodes": 40, "n_cells": 60, "n_dofs": 120, "n_pairs": NE}
    # the history without its wall times: those are in timings.json, never in summary.json
    no_time = [{k: v for k, v in x.items() if k != "seconds"} for x in w["history"]]
    assert s["v3"] == {"v3-rq5": {"converged": True, "passes": 3, "history": no_time}}
    t = json.loads((run / "timings.json").read_text())
    assert t["stages"] == {"mesh": 1.5, "fe": 2.5, "contact": 0.5, "dynamics": 9.0, "speed": 4.0}
    assert t["contact"] == {"1": {"global": 0.1}, "5": {"global": 0.2}}
    assert t["v3"] == {"v3-rq5": [x.get("seconds") for x in w["history"]]}
    assert t["curves"] == {k.name: cr.seconds for k, cr in w["curves"].items()}
    assert t["speed_vs_error"] == w["speed"]
    assert "speed_vs_error" not in s and "timings_s" not in s
    # the dynamics stage's job queue: its wall time and each rank's busy share, in the cost table
    assert t["queues"] == {"dynamics": {"seconds": 8.0, "busy": [0.95, 0.5]},
                           "speed": {"seconds": 3.5, "busy": [1.0, 0.75]}}
    md = (run / "report.md").read_text()
    assert "| dynamics | 9.0 | 95 % / 50 % of 8.0 s |" in md
    assert "| speed | 4.0 | 100 % / 75 % of 3.5 s |" in md


def test_summary_holds_no_wall_time(report):
    """No key of summary.json is a wall time (compare.TIMING_KEYS), so two runs that compute the
    same numbers write the same bytes; the report's cost table reads timings.json."""
    from fe_joint.report.compare import TIMING_KEYS
    run, w, s = report

    def keys(x):
        if isinstance(x, dict):
            for k, v in x.items():
                yield k
                yield from keys(v)
        elif isinstance(x, list):
            for v in x:
                yield from keys(v)
    assert not TIMING_KEYS & set(keys(s))
    md = (run / "report.md").read_text()
    t = json.loads((run / "timings.json").read_text())
    handed = 0
    for name, sec in t["curves"].items():
        p = s["peaks"][name]
        tol = "1e-06" if p["handover_hz"] is None else f"1e-07 from {p['peak_hz'] - 2:.2f} Hz"
        handed += p["handover_hz"] is not None
        assert f"| {name} | {p['n_points']} | {sec:.1f} | {tol}" in md
    assert handed >= 1


BLOCKED_RUN = """
import json, sys
from pathlib import Path

BLOCKED = {"dolfinx", "petsc4py", "slepc4py", "ufl", "basix", "ffcx"}

class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ImportError(f"blocked for this test: {name}")
        return None

sys.meta_path.insert(0, Blocker())
from fe_joint.case import case_from_dict
from fe_joint.report import write_report
summary = write_report(Path(sys.argv[1]), case_from_dict(json.loads(sys.argv[2])))
assert not BLOCKED & {m.partition(".")[0] for m in sys.modules}
print(json.dumps(sorted(summary)))
"""


def test_report_without_fe_packages(report, tmp_path):
    """The report needs no dolfinx, PETSc or SLEPc: importing any of them fails in this process."""
    run = tmp_path / "run"
    shutil.copytree(report[0], run)
    shutil.rmtree(run / "figures")
    (run / "summary.json").unlink()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
           "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, "-c", BLOCKED_RUN, str(run), json.dumps(CASE)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "k_eq" in json.loads(res.stdout.splitlines()[-1])
    assert all((run / "figures" / f"{n}.png").exists() for n in FIGURES)
    assert (run / "summary.json").read_text() == (report[0] / "summary.json").read_text()


def test_texts_differ_by_their_printed_numbers() -> None:
    """compare.differences: two texts that differ only in a printed number differ by that
    number's relative difference; texts whose words differ, by inf."""
    import math

    from fe_joint.report.compare import differences
    a = {"f": ["L2 baseline 1.874e-03 / 602 µm vs 824.4 µm", "agree"]}
    b = {"f": ["L2 baseline 1.874e-03 / 601.9 µm vs 824.4 µm", "disagree"]}
    (r0, p0, _, _), (r1, p1, _, _) = differences(a, b)
    assert (p0, p1) == ("/f[0]", "/f[1]")
    assert r0 == pytest.approx(0.1 / 602, rel=1e-12) and math.isinf(r1)
    assert differences({"t": "X 1.5e-3 mm"}, {"t": "X 1.5e-3 µm"})[0][0] == math.inf


def test_cost_table_names_the_stages_rank_0_ran_alone() -> None:
    """A stage that ran on one rank of a run on two (``runner.SOLO_STAGES``) says so in the
    cost table; on a serial run, or for a stage on every rank, nothing is added."""
    from fe_joint.report.markdown import _alone
    two = {"provenance": {"stages": {"fe": {"ranks": 1}, "dynamics": {"ranks": 2}, "report": {"ranks": "?"}}}}
    assert _alone(two, "fe").startswith("rank 0 alone")
    assert _alone(two, "dynamics") == "" and _alone(two, "report") == ""
    one = {"provenance": {"stages": {"fe": {"ranks": 1}, "dynamics": {"ranks": 1}}}}
    assert _alone(one, "fe") == "" and _alone({}, "fe") == ""
