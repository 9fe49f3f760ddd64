"""The local peak search of the v3 fixed point and its relaxation, against full sweeps and exact
fixed points."""
from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import time

import numpy as np
import pytest

from fe_joint.study.frf import SweepSettings, frf_with_peak, peak_near
from fe_joint.model.joint import JointModel, stuck_modes
from fe_joint.study.fixed_point import _aitken


def _two_grounded_masses():
    """Masses A (DOFs 0–2) and B (3–5) on ground springs, joined by one friction element.

    The joint is stiff against the ground springs, so the in-phase x mode (A and B together)
    loads it little while the relative mode loads it fully; the excitation on A in x drives both.
    """
    m1, m2, k1, k2 = 2e-3, 3e-3, 4e3, 9e3
    M = np.diag([m1] * 3 + [m2] * 3)
    K = np.diag([k1] * 3 + [k2] * 3)
    return SimpleNamespace(M=M, K=K, pair_dofs=np.array([[[0, 1, 2], [3, 4, 5]]]),
                           damping_ratio=5e-3, excitation_dof=0, response_dof=0)


#: μ = 0.5, band 0.8–1.1, H = 1, 32 samples, 400 points at most
SETTINGS = SweepSettings(harmonics=1, samples=32, band=(0.8, 1.1), max_points=400, mu=0.5)


def _joint(kt: float) -> JointModel:
    return JointModel("t", n0=np.array([30.0]), gap=np.zeros(1), kn=np.array([4e4]),
                      kt=np.array([kt]), area=np.array([1.0]))


def _sweep(rm, joint, level):
    f = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency
    return frf_with_peak(rm, joint, level, f, SETTINGS)


@pytest.mark.parametrize("change", [1.0, 1.03, 0.97])
def test_local_peak_matches_full_sweep(change: float) -> None:
    """From the peak of one joint, peak_near finds the peak of a slightly changed joint: the same
    as a full sweep of that joint."""
    rm = _two_grounded_masses()
    level = 2.0
    first, state = _sweep(rm, _joint(2e3), level)
    assert first.n_nonlinear == 1          # the element slips at the peak: a nonlinear peak
    joint = _joint(2e3 * change)
    ref, _ = _sweep(rm, joint, level)
    loc, state2 = peak_near(rm, joint, level, first.peak_hz * (1 + 1e-3), state, SETTINGS)
    assert loc.n_points < ref.n_points / 3
    # one element's stick–slip peak is a flat top at n_t = 32: the amplitude stays within 1e-5
    # over ±0.1 Hz, so the parabolic polish of either search stops up to 1e-4 apart in frequency
    # (6.3e-5 at change = 1.03) with amplitudes within 3e-6; the v3 tolerance is 1e-3
    assert loc.peak_hz == pytest.approx(ref.peak_hz, rel=1e-4)
    assert loc.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=2e-5)
    assert state2.shape == state.shape
    # without the golden-section search (the v3 passes): the polished peak, within the flat
    # top's spread of the refined one (measured up to 3.3e-4 in frequency and 2.0e-5 in
    # amplitude: the top is flat to 1e-5 over ±0.1 Hz; the v3 tolerance is 1e-3) and below it
    # (the refined peak is the maximum)
    pol, _ = peak_near(rm, joint, level, first.peak_hz * (1 + 1e-3), state, SETTINGS, refine=False)
    assert pol.peak_hz == pytest.approx(loc.peak_hz, rel=5e-4)
    assert pol.peak_amplitude == pytest.approx(loc.peak_amplitude, rel=5e-5)
    assert pol.peak_amplitude <= loc.peak_amplitude * (1 + 1e-12)


def test_local_peak_from_below_the_peak() -> None:
    """Started below the peak the search turns round and still finds it."""
    rm = _two_grounded_masses()
    ref, state = _sweep(rm, _joint(2e3), 2.0)
    loc, _ = peak_near(rm, _joint(2e3), 2.0, ref.peak_hz * (1 - 4e-3), state, SETTINGS)
    assert loc.peak_hz == pytest.approx(ref.peak_hz, rel=2e-5)


def test_pass0_peak_from_the_stuck_frequency_without_a_state() -> None:
    """A v3 pass 0 off the comparison surface (``_find_peak(full_first=False)``): the local search
    from just above the stuck frequency, from rest, finds the full sweep's peak in a third of its
    points; with ``full_first`` it is the sweep itself. (Here the peak lies 0.16 % above the
    lowest stuck mode, so the search also has to turn round; on the resonator friction lowers it.)"""
    from fe_joint.study.fixed_point import _find_peak
    rm = _two_grounded_masses()
    joint = _joint(2e3)
    lin = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint)
    inp = SimpleNamespace(rm=rm, settings=SETTINGS)
    ref, _ = _sweep(rm, joint, 2.0)
    loc, state, how, why = _find_peak(inp, joint, 2.0, lin, None, None, None, full_first=False)
    assert (how, why) == ("local", None) and state.shape[0] == 1
    assert loc.n_points < ref.n_points / 3
    # polished, not refined: within the flat top's spread (see test_local_peak_matches_full_sweep)
    assert loc.peak_hz == pytest.approx(ref.peak_hz, rel=5e-4)
    assert loc.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=5e-5)
    full, _, how, _ = _find_peak(inp, joint, 2.0, lin, None, None, None, full_first=True)
    assert how == "sweep" and full.n_points == ref.n_points and full.peak_hz == ref.peak_hz


def test_local_peak_without_a_peak_raises() -> None:
    """A linear joint far from its resonance: no peak within the window → an error, not a point."""
    from fe_joint.study.frf import SweepIncomplete
    rm = _two_grounded_masses()
    _, state = _sweep(rm, _joint(2e3), 2.0)
    f = stuck_modes(rm.K, rm.M, rm.pair_dofs, _joint(2e3)).frequency
    with pytest.raises(SweepIncomplete):
        peak_near(rm, _joint(2e3), 2.0, 0.5 * f, state, SETTINGS, max_points=30)


def test_aitken_solves_linear_fixed_point_in_two_updates() -> None:
    """On an affine map x ← A x + b with A = a I the secant factor is exact: the second relaxed
    update lands on the fixed point, for an oscillating (a < 0) and a creeping (a > 0) map
    (factor 1/(1 − a) = 0.56 and 1.43, inside the clipping bounds)."""
    b = np.array([1.0, -2.0, 0.5])
    for a in (-0.8, 0.3):
        xs = b / (1 - a)
        x = np.zeros(3)
        r_prev, w = None, 1.0
        for _ in range(2):
            r = a * x + b - x
            w = _aitken(x, r, r_prev, w)
            r_prev = r
            x = x + w * r
        assert np.abs(x - xs).max() <= 1e-12 * np.abs(xs).max(), a
        # the plain iteration after the same two updates is still far off
        assert np.abs((a * (a * 0 + b) + b) - xs).max() > 0.1


def test_failed_fast_sweep_is_retried_with_strict_tolerances(monkeypatch) -> None:
    """A sweep that fails with the fast tolerances is rerun once with hbm's strict ones; a second
    failure is reported, not hidden. The curve records the tolerance its sweep ended at."""
    import fe_joint.study.frf as dyn
    from fe_joint.study.frf import SweepIncomplete, frf
    rm = _two_grounded_masses()
    f = stuck_modes(rm.K, rm.M, rm.pair_dofs, _joint(2e3)).frequency
    ref = frf(rm, _joint(2e3), 2.0, f, SETTINGS)
    assert ref.sweep_tol == dyn.SWEEP_TOLERANCES[0][0] and np.isnan(ref.handover_hz)
    # a sweep handed over to THRASH_TOLERANCES at its 4th point (as hbm's continuation does
    # where it thrashes at a fold) records that tolerance and the point's frequency
    real_frf, seen = dyn.HarmonicBalance.frf, []

    def handed_over(hb, *args, **kwargs):
        assert kwargs["settings"].tight_tol == dyn.THRASH_TOLERANCES
        res = real_frf(hb, *args, **kwargs)
        hb.tol, hb.krylov_tol = dyn.THRASH_TOLERANCES
        seen.append(res.omega[3] / (2 * np.pi))
        return dataclasses.replace(res, tightened_at=3)
    with monkeypatch.context() as m:
        m.setattr(dyn.HarmonicBalance, "frf", handed_over)
        cr = frf(rm, _joint(2e3), 2.0, f, SETTINGS)
    assert cr.sweep_tol == dyn.THRASH_TOLERANCES[0] and cr.handover_hz == seen[0]
    tols = []
    real = dyn._sweep

    def flaky(*args):
        tols.append(args[-1])
        if len(tols) == 1:
            time.sleep(0.5)                  # the failed fast sweep's time
            raise SweepIncomplete("lost at a fold")
        return real(*args)
    monkeypatch.setattr(dyn, "_sweep", flaky)
    cr = frf(rm, _joint(2e3), 2.0, f, SETTINGS)
    assert tols == list(dyn.SWEEP_TOLERANCES) and tols[1] == (1e-9, 1e-11)
    assert cr.peak_hz == pytest.approx(ref.peak_hz, rel=2e-5)   # strict vs fast: same peak
    assert cr.seconds >= 0.5                 # the curve's time counts the failed sweep too
    assert cr.sweep_tol == 1e-9

    def broken(*args):
        raise SweepIncomplete("lost at a fold")
    monkeypatch.setattr(dyn, "_sweep", broken)
    with pytest.raises(SweepIncomplete):
        frf(rm, _joint(2e3), 2.0, f, SETTINGS)


def test_refined_peak_does_not_depend_on_a_failed_strict_solve(monkeypatch) -> None:
    """The peak is found whatever the path: when some of the peak search's tight solves fail
    (ConvergenceError), they are repeated at hbm's strict tolerances and the peak is the same as
    with none failing (before: the refinement stopped and returned the polished start, which
    depends on the continuation's points). The reference is the same sweep without failures;
    both are the maximum, so they agree far below the polish's scatter."""
    from hbm import ConvergenceError, HarmonicBalance
    from fe_joint.study import frf as F
    rm = _two_grounded_masses()
    joint = _joint(2e3)
    ref, _ = _sweep(rm, joint, 2.0)
    solve = HarmonicBalance.solve
    calls = {"n": 0, "failed": 0}

    def flaky(self, omega, force, guess=None):
        if self.tol == F.PEAK_TOLERANCES[0]:           # a tight solve: every other one fails
            calls["n"] += 1
            if calls["n"] % 2 == 0:
                calls["failed"] += 1
                raise ConvergenceError("Newton did not converge (test)", 1e-6)
        return solve(self, omega, force, guess)
    monkeypatch.setattr(HarmonicBalance, "solve", flaky)
    # the polished start alone (what a failed refinement used to return) is farther off
    polished = {}
    polish = F._polish_peak

    def keep(*a, **kw):
        s = polish(*a, **kw)
        polished["f"] = s.omega / (2 * np.pi)
        return s
    monkeypatch.setattr(F, "_polish_peak", keep)
    got, _ = _sweep(rm, joint, 2.0)
    assert got.peak_hz == pytest.approx(ref.peak_hz, rel=1e-8)
    assert got.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=1e-8)
    assert abs(polished["f"] - ref.peak_hz) > 100 * abs(got.peak_hz - ref.peak_hz)
    assert calls["failed"] >= 3


def _in_peak_search(monkeypatch, fake) -> None:
    """Replace ``HarmonicBalance.solve`` by ``fake(hb, omega, force, guess, solve)`` (``solve``
    the real one) inside ``frf._refine_peak`` only; elsewhere the real solve runs."""
    from hbm import HarmonicBalance
    from fe_joint.study import frf as F
    solve, refine, inside = HarmonicBalance.solve, F._refine_peak, [False]

    def in_peak(*a, **kw):
        inside[0] = True
        try:
            return refine(*a, **kw)
        finally:
            inside[0] = False

    def patched(self, omega, force, guess=None):
        if not inside[0]:
            return solve(self, omega, force, guess)
        return fake(self, omega, force, guess, solve)
    monkeypatch.setattr(F, "_refine_peak", in_peak)
    monkeypatch.setattr(HarmonicBalance, "solve", patched)


def test_a_stalled_tight_solve_gives_its_best_iterate_without_looser_solves(monkeypatch) -> None:
    """A tight solve of the peak search that stalls (ConvergenceError carrying Newton's best
    iterate) at an iterate meeting the sweep's tolerance gives that iterate: no looser solve is
    run from the same start (it would retrace the same iterations). Here every other tight solve
    'stalls' at its converged solution: the peak is the one without stalls, and no solve ran at
    the looser tolerances."""
    from hbm import ConvergenceError
    from fe_joint.study import frf as F
    rm = _two_grounded_masses()
    joint = _joint(2e3)
    ref, _ = _sweep(rm, joint, 2.0)
    calls = {"tight": 0, "stalled": 0, "looser": 0}

    def stalling(self, omega, force, guess, solve):
        if self.tol != F.PEAK_TOLERANCES[0]:
            calls["looser"] += 1
            return solve(self, omega, force, guess)
        calls["tight"] += 1
        s = solve(self, omega, force, guess)
        if calls["tight"] % 2 == 0:
            calls["stalled"] += 1
            raise ConvergenceError("Newton stalled (test)", s.residual, best=s)
        return s
    _in_peak_search(monkeypatch, stalling)
    got, _ = _sweep(rm, joint, 2.0)
    assert got.peak_hz == pytest.approx(ref.peak_hz, rel=1e-10)
    assert got.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=1e-10)
    assert calls["stalled"] >= 3 and calls["looser"] == 0


def test_a_top_with_kinks_is_searched_at_the_kink_tolerances(monkeypatch) -> None:
    """Where the peak search's tight solves stall above hbm's strict tolerance (kinks of the
    sampled friction law), after KINK_POINTS such points the rest are solved at KINK_TOLERANCES
    only: no further tight solve is tried. The peak is the same as without stalls, to what those
    tolerances allow."""
    import copy

    from hbm import ConvergenceError
    from fe_joint.study import frf as F
    rm = _two_grounded_masses()
    joint = _joint(2e3)
    ref, _ = _sweep(rm, joint, 2.0)
    calls = {"tight": 0, "kink": 0}

    def kinked(self, omega, force, guess, solve):
        if (self.tol, self.krylov_tol) == F.KINK_TOLERANCES:
            calls["kink"] += 1
            return solve(self, omega, force, guess)
        calls["tight"] += 1
        best = copy.copy(solve(self, omega, force, guess))
        best.residual = 1e-8             # a stall above the strict tolerance, below the kink one
        raise ConvergenceError("Newton stalled (test)", best.residual, best=best)
    _in_peak_search(monkeypatch, kinked)
    got, _ = _sweep(rm, joint, 2.0)
    assert calls["tight"] == F.KINK_POINTS and calls["kink"] >= 10
    # this top is smooth and flat (X″ω²/X ≈ −400): with amplitudes exact to ε ≈ 1e-7 the golden
    # section stops within √(2ε/400) ≈ 2e-5 of the maximum (measured 1.0e-6), the amplitude
    # within ε of it (measured 5.8e-8 above: a noisy sample)
    assert got.peak_hz == pytest.approx(ref.peak_hz, rel=2e-5)
    assert got.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=2e-7)


def test_speed_tables_measure_the_frf_peak() -> None:
    """The harmonics/samples speed-against-error rows are the FRF peak (a local peak search from
    the study curve's peak and its contact harmonics, speed_error.curve_reference), not a
    cold-start solve at the peak frequency (which landed on the lower branch of the resonator's
    fold): at the study's own H and n_t the row equals the full sweep's polished peak; each row
    equals a full sweep's peak at its own H and n_t; the last row is the reference (0 error)."""
    from fe_joint.study import frf as F
    from fe_joint.study import speed_error as se
    rm, joint, level = _two_grounded_masses(), _joint(2e4), 5.0
    cr, contact = _sweep(rm, joint, level)
    assert cr.peak_contact.shape == (1, 3, 3) and np.array_equal(cr.peak_contact, contact)
    t = se.hbm_knobs(rm, joint, SETTINGS, cr, harmonics=(1, 3), samples=(16, 32), h_fixed=1)
    rows = t[se.SAMPLES_TABLE]
    same = rows[-1]                                   # H = 1, 32 samples: the sweep's settings
    assert (same["harmonics"], same["samples"]) == (1, 32)
    # the row's search and the sweep's start from different points: equal to the search's
    # resolution (measured 1.4e-7 in f with PEAK_XTOL = 1e-6 and the secant local branch)
    assert abs(same["peak [Hz]"] / cr.peak_hz - 1) <= F.PEAK_XTOL
    assert abs(same["amplitude [µm]"] / (1e3 * cr.peak_amplitude) - 1) <= 4 * F.PEAK_XTOL
    assert same["f error vs finest [%]"] == 0.0 and rows[0]["amplitude error vs finest [%]"] > 0
    hr = t[se.HARMONICS_TABLE]
    assert [r["harmonics"] for r in hr] == [1, 3] and all(3 <= r["points"] < 80 for r in hr)
    # H = 3 with 256 samples, started from the H = 1 peak (padded with zeros): a sweep's peak
    f3 = stuck_modes(rm.K, rm.M, rm.pair_dofs, joint).frequency
    sweep3, _ = frf_with_peak(rm, joint, level, f3, SweepSettings(3, 256, (0.8, 1.1), 400, 0.5))
    # equal to the search's resolution (F.PEAK_XTOL): the row and the sweep search from starts
    # on either side of the peak
    assert abs(hr[1]["peak [Hz]"] / sweep3.peak_hz - 1) <= F.PEAK_XTOL
    assert abs(hr[1]["amplitude [µm]"] / (1e3 * sweep3.peak_amplitude) - 1) <= 1e-6
    assert abs(hr[1]["peak [Hz]"] / same["peak [Hz]"] - 1) > 10 * F.PEAK_XTOL   # H matters here


def test_reference_of_a_curve_saved_without_its_peak_contact_says_so() -> None:
    """A curve written before CurveResult.peak_contact (its default, (0, 3, 0)) gives a
    reference without a warm start and with a note; one with it gives the curve's own fields."""
    from dataclasses import replace as dc_replace

    from fe_joint.study import speed_error as se
    rm, joint, level = _two_grounded_masses(), _joint(2e4), 5.0
    cr, contact = _sweep(rm, joint, level)
    ref = se.curve_reference(cr)
    assert ref["harmonics"] == SETTINGS.harmonics and ref["samples"] == SETTINGS.samples
    assert np.array_equal(ref["guess"], contact) and ref["points"] == cr.n_points
    assert ref["peak [Hz]"] == cr.peak_hz and ref["amplitude [µm]"] == 1e3 * cr.peak_amplitude
    old = se.curve_reference(dc_replace(cr, peak_contact=np.zeros((0, 3, 0))))
    assert old["guess"] is None and "no contact harmonics" in old["note"]
    row = se.hbm_row(rm, joint, level, SETTINGS, old, 1, 64)
    assert row["points"] == 0 and np.isnan(row["peak [Hz]"]) and "no reference" in row["note"]


def test_speed_row_without_a_reference_says_so() -> None:
    """A row whose reference sweep failed is 'not found', with no search (and no sweep)."""
    from fe_joint.study import speed_error as se
    rm, joint = _two_grounded_masses(), _joint(2e4)
    row = se.hbm_row(rm, joint, 5.0, SETTINGS, {"peak [Hz]": float("nan"), "guess": None}, 3, 64)
    assert row["points"] == 0 and np.isnan(row["peak [Hz]"]) and "no reference" in row["note"]
    g = np.arange(2 * 3 * 3.0).reshape(2, 3, 3)
    assert np.array_equal(se.with_harmonics(g, 2)[..., :3], g)
    assert not se.with_harmonics(g, 2)[..., 3:].any()
    assert np.array_equal(se.with_harmonics(se.with_harmonics(g, 2), 1), g)


def test_element_count_rows_are_the_models_own_peaks() -> None:
    """The element-count table (speed_error.mesh_rows): each row is its model's own FRF peak, found
    by the study's sweep with the band relative to the model's stuck frequency; the last row (the
    case's mesh) is the study's curve itself. Here the 'coarse' model is the same structure with
    a 4 % stiffer joint (its stuck frequency and peak move): its row equals that joint's
    full-sweep peak, its stuck frequency error is the stuck modes' own difference, and the
    reference row has zero errors."""
    from fe_joint.study.speed_error import mesh_rows
    rm = _two_grounded_masses()
    rm.n_pairs, rm.n_dofs, rm.preload_status = 1, 6, np.array([1])
    level = 5.0
    case_joint, coarse_joint = _joint(2e4), _joint(2e4 * 1.04)
    ref, _ = _sweep(rm, case_joint, level)
    coarse, _ = _sweep(rm, coarse_joint, level)
    rows = mesh_rows([(4.0, rm, 1.0, coarse_joint), (2.8, rm, 2.0, case_joint)], SETTINGS, ref)
    assert rows[1]["HBM time [s]"] == ref.seconds and rows[1]["points"] == ref.n_points
    assert [r["lap mesh [mm]"] for r in rows] == [4.0, 2.8] and rows[0]["elements"] == 1
    for r, cr in zip(rows, (coarse, ref)):
        assert abs(r["peak [Hz]"] / cr.peak_hz - 1) <= 1e-7
        assert abs(r["amplitude [µm]"] / (1e3 * cr.peak_amplitude) - 1) <= 1e-6
    f = [stuck_modes(rm.K, rm.M, rm.pair_dofs, j).frequency for j in (coarse_joint, case_joint)]
    assert rows[0]["stuck error vs case mesh [%]"] == pytest.approx(100 * abs(f[0] - f[1]) / f[1], rel=1e-12)
    assert rows[0]["stuck error vs case mesh [%]"] > 0.01
    assert rows[1]["f error vs case mesh [%]"] == 0.0 and rows[1]["stuck error vs case mesh [%]"] == 0.0


def test_speed_rows_as_queue_jobs_give_the_sequential_tables(tmp_path) -> None:
    """The speed stage deals its rows to the MPI job queue: rows run in any order, written and
    read back, assemble into the tables of the sequential functions (hbm_knobs, mesh_rows), the
    costly rows are dealt first, and rows on disk under another stage key are not reused."""
    from fe_joint.study import speed_error as se
    from fe_joint.study.queue import run_jobs
    rm = _two_grounded_masses()
    rm.n_pairs, rm.n_dofs, rm.preload_status = 1, 6, np.array([1])
    level = 5.0
    case_joint, coarse_joint = _joint(2e4), _joint(2e4 * 1.04)
    ref, _ = _sweep(rm, case_joint, level)
    models = [(4.0, rm, 1.0, coarse_joint), (2.8, rm, 2.0, case_joint)]
    knobs = se.knob_grid((1, 3), (16, 32), h_fixed=1)
    seq = {**se.hbm_knobs(rm, case_joint, SETTINGS, ref, harmonics=(1, 3), samples=(16, 32),
                          h_fixed=1),
           se.MESH_TABLE: se.mesh_rows(models, SETTINGS, ref)}
    jobs = se.speed_jobs([], knobs, len(models), (1, 32))
    # the reference first (the harmonics and samples rows wait for it), then the coarser mesh's
    # row (it builds its FE model), then the costliest search
    assert jobs[:3] == [se.SpeedJob("reference", 0, harmonics=1, samples=32),
                        se.SpeedJob("mesh", 0, model=0, builds_model=True),
                        se.SpeedJob("harmonics", 1, harmonics=3, samples=256)]
    assert [j.builds_model for j in jobs if j.table == "mesh"] == [True, False]
    # one search per (model, H, n_t): the case mesh's row is the reference's sweep
    searches = [(j.model if j.table == "mesh" else -1, j.harmonics or 1, j.samples or 32)
                for j in jobs if j.table not in ("bem", "reference") and not j.peak_of]
    assert len(searches) == len(set(searches)) == 5
    assert [j.peak_of for j in jobs if j.table == "mesh"] == ["", se.REFERENCE]
    assert {j.name for j in jobs if j.needs_reference} == {"samples-0", "samples-1", "harmonics-0",
                                                           "harmonics-1"}
    reference = {}

    def run(job):          # as the speed stage's
        if job.peak_of:
            return se.own_fields(job, models)
        if job.table == "mesh":
            return se.mesh_row(models[job.model], level, SETTINGS)
        if job.table == "reference":
            return se.curve_reference(ref)
        return se.hbm_row(rm, case_joint, level, SETTINGS, reference, job.harmonics, job.samples)

    stale = se.SpeedJob("samples", 0, harmonics=1, samples=16)
    se.write_row(tmp_path, stale, {"peak [Hz]": -1.0}, key="another case")
    assert se.read_rows(tmp_path, jobs, "k") == {}
    older = tmp_path / "samples-1.json"       # a row of the previous version (a sweep)
    j1 = next(j for j in jobs if j.name == "samples-1")
    older.write_text(json.dumps({"key": "k", "job": dataclasses.asdict(j1), "row": {}}))
    assert se.read_rows(tmp_path, jobs, "k") == {}
    older.unlink()
    def run_reading(job):  # as the stage's: the first row that needs the reference reads it
        if job.needs_reference and not reference:
            reference.update(se.read_reference(tmp_path, se.read_rows(tmp_path, jobs, "k")))
            assert reference["guess"].shape == (1, 3, 3)
        return run(job)
    run_jobs(run_reading, lambda f, j, r: se.write_row(f, j, r, "k"), jobs[::-1], tmp_path,
             skip_done=False, after=lambda j: {se.REFERENCE} if j.needs_reference else set())
    assert reference
    got = se.assemble_tables(jobs, se.read_rows(tmp_path, jobs, "k"), 3)
    assert list(got) == [se.HARMONICS_TABLE, se.SAMPLES_TABLE, se.MESH_TABLE]
    for title, rows in seq.items():
        assert len(got[title]) == len(rows)
        for a, b in zip(got[title], rows):
            for k in ("peak [Hz]", "amplitude [µm]", "points") + tuple(x for x in b if "error" in x):
                assert a[k] == pytest.approx(b[k], rel=1e-12, abs=1e-12), (title, k)


def _peak_solver(rm, joint, level):
    """The sweep's HarmonicBalance (fast tolerances, as _refine_peak gets it) and the force."""
    from fe_joint.study import frf as F
    return F._setup(rm, joint, level, SETTINGS)[:2]


def _tight_amplitudes(hb, force, freqs_hz, guess):
    """Amplitudes at the given frequencies, solved at the peak search's tight tolerances."""
    from fe_joint.study import frf as F
    own = hb.tol, hb.krylov_tol
    hb.tol, hb.krylov_tol = F.PEAK_TOLERANCES
    out = []
    try:
        for f in freqs_hz:
            guess = hb.solve(2 * np.pi * f, force, guess=guess)
            out.append(guess.amplitude(0))
    finally:
        hb.tol, hb.krylov_tol = own
    return np.array(out), guess


def test_corner_peak_is_the_flanks_intersection_from_any_start() -> None:
    """A resonance peak that is a corner of the sampled friction law (one element, H = 1, 32
    samples, k_t = 2e4, 5 N: the amplitude is linear on either side, slopes ≈ +3.8 and −3.7 in
    dX/X over dω/ω) is located at the intersection of its two flanks, from starts 1e-4 below to
    1e-4 above it, to the search's resolution ``PEAK_XTOL`` in frequency. The reference is
    independent of the search: straight
    fitted through tight solves on each flank (5e-7 … 5e-6 from the corner). The previous
    refinement (Newton on a central difference, h = 1e-5) put this peak 1.6e-7 above the corner
    with an amplitude 5.9e-7 low: the root of X(ω(1+h)) = X(ω(1−h)) lies h(a − b)/(a + b) from
    a corner of slopes a, −b."""
    from fe_joint.study import frf as F
    rm, joint, level = _two_grounded_masses(), _joint(2e4), 5.0
    ref, _ = _sweep(rm, joint, level)
    hb, force = _peak_solver(rm, joint, level)
    f0 = ref.peak_hz
    start = hb.solve(2 * np.pi * f0, force)
    r = np.linspace(5e-7, 5e-6, 6)
    xl, _ = _tight_amplitudes(hb, force, f0 * (1 - r), start)
    xr, _ = _tight_amplitudes(hb, force, f0 * (1 + r), start)
    # each flank is smooth (nearly straight: curvature 1e-8 of the slope over 1e-5): quadratics
    # through 6 points fit it to the solves' noise (3e-13 measured)
    pl, pr = np.polyfit(-r, xl / xl[0], 2), np.polyfit(r, xr / xl[0], 2)
    assert np.abs(np.polyval(pl, -r) - xl / xl[0]).max() < 1e-11
    assert np.abs(np.polyval(pr, r) - xr / xl[0]).max() < 1e-11
    assert pl[1] > 3 and pr[1] < -3                   # a corner: slopes +3.8 and -3.7
    roots = np.roots(pl - pr)
    rc = float(roots[np.argmin(np.abs(roots))].real)   # the corner, relative to f0
    f_corner, x_corner = f0 * (1 + rc), np.polyval(pl, rc) * xl[0]
    assert abs(rc) < 1e-7                             # the sweep's own peak is that corner
    found = []
    for s in (-1e-4, -3e-5, -2e-6, 5e-6, 4e-5, 1e-4):
        sol = hb.solve(2 * np.pi * f0 * (1 + s), force, guess=start)
        peak = F._refine_peak(hb, force, 0, sol)
        found.append((peak.omega / (2 * np.pi), peak.amplitude(0)))
        assert (hb.tol, hb.krylov_tol) == F.SWEEP_TOLERANCES[0]      # restored
    f, x = np.array(found).T
    # to the search's resolution F.PEAK_XTOL in frequency (measured 5.5e-8 at 1e-6; 1e-10 at
    # 1e-9), and in amplitude to the flanks' slopes (< 4) times it (measured 2.0e-7)
    assert np.abs(f / f_corner - 1).max() < F.PEAK_XTOL, f / f_corner - 1
    assert np.abs(x / x_corner - 1).max() < 4 * F.PEAK_XTOL, x / x_corner - 1
    assert np.ptp(f) / f_corner < F.PEAK_XTOL


def test_smooth_peak_is_the_parabolas_vertex_from_any_start() -> None:
    """A smooth peak (k_t = 2e3, 2 N: the element slips over a part of the cycle at every point
    near the maximum; flat, X″ω²/X ≈ −400) is located at the same frequency from starts 5e-5
    below to 3e-5 above it, to 1e-10 (measured 5e-13): the golden section's maximum is replaced
    by the vertex of the parabola through X(ω(1 ± 1e-5)), whose position does not depend on
    where the golden section stopped. The reference is independent: the vertex of a parabola
    fitted through tight solves within ±1e-6 of the peak; the located peak is 8.5e-9 from it,
    the 1e-5 stencil's bias h²X‴/(6X″) (2e-8 allowed). The golden section alone stops within
    √(ε/c) of the maximum for noise ε (3e-8 on the quick model's baseline at the middle level)."""
    from fe_joint.study import frf as F
    rm, joint, level = _two_grounded_masses(), _joint(2e3), 2.0
    ref, _ = _sweep(rm, joint, level)
    hb, force = _peak_solver(rm, joint, level)
    f0 = ref.peak_hz
    start = hb.solve(2 * np.pi * f0, force)
    r = np.linspace(-1e-6, 1e-6, 9)
    x, _ = _tight_amplitudes(hb, force, f0 * (1 + r), start)
    c = np.polyfit(r, x / x.max() - 1, 2)
    assert c[0] < 0
    f_vertex = f0 * (1 - c[1] / (2 * c[0]))
    found = []
    for s in (-5e-5, -1e-5, 3e-6, 3e-5):
        sol = hb.solve(2 * np.pi * f0 * (1 + s), force, guess=start)
        peak = F._refine_peak(hb, force, 0, sol)
        found.append(peak.omega / (2 * np.pi))
    f = np.array(found)
    assert np.ptp(f) / f_vertex < 1e-10, f / f_vertex - 1
    assert np.abs(f / f_vertex - 1).max() < 2e-8, f / f_vertex - 1


def test_interpolated_starts_save_newton_iterations_for_the_same_peak(monkeypatch) -> None:
    """The peak search's solves start from the contact harmonics interpolated between the
    nearest solutions on either side: on the corner and the smooth peak of the one-element
    model the search ends on the same peak as from the nearest solution (to 1e-12) with fewer
    Newton iterations (counted as Jacobians)."""
    from fe_joint.study import frf as F
    for kt, level in ((2e4, 5.0), (2e3, 2.0)):
        rm, joint = _two_grounded_masses(), _joint(kt)
        ref, _ = _sweep(rm, joint, level)
        got = {}
        for interpolated in (False, True):
            monkeypatch.setattr(F, "INTERPOLATED_START", interpolated)
            hb, force = _peak_solver(rm, joint, level)
            start = hb.solve(2 * np.pi * ref.peak_hz * (1 + 3e-5), force)
            n0 = hb.stats["jacobians"]
            peak = F._refine_peak(hb, force, 0, start)
            got[interpolated] = (peak.omega, peak.amplitude(0), hb.stats["jacobians"] - n0)
        (w0, x0, n_near), (w1, x1, n_interp) = got[False], got[True]
        assert w1 == pytest.approx(w0, rel=1e-12) and x1 == pytest.approx(x0, rel=1e-12), kt
        # 42 against 53 (k_t = 2e4) and 48 (2e3) with PEAK_XTOL = 1e-6; 65 against 87 at 1e-9
        assert n_interp < n_near, (kt, n_interp, n_near)


def test_a_top_the_sweep_stepped_over_is_resampled_not_traced(monkeypatch) -> None:
    """Where the sweep's steps next to its largest point exceed PEAK_GAP, the two steps are
    resampled by fixed-frequency solves (SCAN_SUBDIVISIONS per step, no continuation): the
    peak equals the one found from the finely traced branch (the scan turned off) to the
    search's resolution (``PEAK_XTOL``), no
    branch is traced, and the resampled points are sorted and include the sweep's three."""
    from fe_joint.study import frf as F
    calls = {"local": 0, "scan": []}
    local, scan = F._local_branch, F._scan_top

    def counted_local(*a, **kw):
        calls["local"] += 1
        return local(*a, **kw)

    def kept_scan(*a, **kw):
        out = scan(*a, **kw)
        calls["scan"].append((a[3], a[4], out))
        return out
    monkeypatch.setattr(F, "_local_branch", counted_local)
    monkeypatch.setattr(F, "_scan_top", kept_scan)
    rm = _two_grounded_masses()
    for kt, level in ((2e4, 5.0), (2e3, 5.0)):
        calls["local"], calls["scan"] = 0, []
        cr, _ = _sweep(rm, _joint(kt), level)
        [(res, k, out)] = calls["scan"]
        assert out is not None and calls["local"] == 0, kt
        branch, kb, _ = out
        n = 2 * F.SCAN_SUBDIVISIONS + 1
        assert len(branch.omega) == n and np.all(np.diff(branch.omega) > 0)
        assert set(res.omega[k - 1:k + 2]) <= set(branch.omega)
        assert branch.amplitude[kb] >= res.amplitude[k]
        monkeypatch.setattr(F, "_scan_top", lambda *a, **kw: None)
        traced, _ = _sweep(rm, _joint(kt), level)
        monkeypatch.setattr(F, "_scan_top", kept_scan)
        assert calls["local"] == 1, kt
        # the two searches start from different points: equal to the search's resolution
        # (measured 1.1e-8 in f, 3.9e-8 in amplitude with PEAK_XTOL = 1e-6; 4e-14 at 1e-9)
        assert cr.peak_hz == pytest.approx(traced.peak_hz, rel=F.PEAK_XTOL), kt
        assert cr.peak_amplitude == pytest.approx(traced.peak_amplitude, rel=4 * F.PEAK_XTOL), kt


def test_the_validated_structure_is_kept_per_reduced_model():
    # ``frf.structure``: one validated LinearStructure per reduced model (by identity) for the
    # last two models, equal to a fresh one; a third model evicts the oldest
    from fe_joint.study import frf as frf_
    from hbm import LinearStructure
    frf_._STRUCTURES.clear()
    rms = [SimpleNamespace(M=np.diag([1.0, 2.0 + i]), K=np.array([[3.0, -1.0], [-1.0, 2.0]]),
                           damping_ratio=0.01) for i in range(3)]
    s0 = frf_.structure(rms[0])
    assert frf_.structure(rms[0]) is s0
    fresh = LinearStructure(rms[0].M, rms[0].K, damping_ratio=0.01)
    assert np.array_equal(s0.M, fresh.M) and np.array_equal(s0.K, fresh.K)
    s1 = frf_.structure(rms[1])
    assert s1 is not s0 and frf_.structure(rms[0]) is s0 and np.array_equal(s1.M, rms[1].M)
    frf_.structure(rms[2])                       # evicts the least recently used: rms[1]
    assert frf_.structure(rms[0]) is s0 and frf_.structure(rms[1]) is not s1
