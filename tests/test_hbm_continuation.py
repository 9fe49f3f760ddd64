"""Continuation: fold passing with Hill stability; FRF vs the closed form along a whole curve;
settings validation and the settings=/keywords equivalence; the tangent orientation when the
linear solves switch between LU and GMRES, and at corner folds on the GMRES path."""
import dataclasses

import numpy as np
import pytest

from hbm import (ContinuationSettings, CycleNotClosed, FrictionContacts, HarmonicBalance,
                 LinearStructure)
from hbm.reference import jenkins_frf_h1


def test_softening_fold_passed_and_unstable_branch_marked():
    # preloaded normal contact that opens: stiffness 1 + 3 when closed, 1 when open -> softening
    s = LinearStructure([[1.0]], [[1.0]], [[0.1]])
    c = FrictionContacts(np.array([[[-1, -1, 0], [-1, -1, -1]]]), kt=1.0, kn=3.0, mu=0.5, n0=0.1)
    hb = HarmonicBalance(s, c, harmonics=5, samples=128)
    frf = hb.frf(0.6, 2.6, np.array([0.1]), dof=0, ds_max=0.1)
    assert frf.method == "hill"
    assert abs(frf.omega[-1] - 2.6) <= 1e-12 and frf.omega[0] == 0.6
    tp = frf.turning_points
    assert len(tp) >= 2
    # three coexisting solutions between the folds: the branch goes back in frequency
    assert frf.omega[tp[0]] > frf.omega[tp[-1]] + 0.005
    # Hill: the branch between the first two folds is unstable, the ends are stable
    mid = slice(tp[0] + 1, tp[1] - 1)
    assert np.all(~frf.stable[mid]) and frf.stable[mid].size >= 5
    assert frf.stable[-10:].all() and frf.stable[:5].all()
    # every point on the curve is a converged solution: re-solving at fixed omega from it
    # keeps it (same branch, residual below tolerance)
    k = (tp[0] + tp[1]) // 2
    again = hb.solve(frf.omega[k], np.array([0.1]), guess=frf.solutions[k])
    assert abs(again.amplitude(0) - frf.amplitude[k]) <= 1e-7 * frf.amplitude[k]
    # the contact opens part of the cycle on the upper branch
    assert hb.element_results(frf.solutions[np.argmax(frf.amplitude)]).status[0] == 3


def test_frf_curve_matches_closed_form_h1():
    m, k, cc, kt, fs, F = 1.0, 1.0, 0.02, 1.0, 0.1, 0.1
    s = LinearStructure([[m]], [[k]], [[cc]])
    c = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=kt, kn=1.0, mu=fs, n0=1.0)
    hb = HarmonicBalance(s, c, harmonics=1, samples=1024)
    frf = hb.frf(0.7, 1.8, np.array([F]), dof=0, ds_max=0.3, max_domega=1.1 / 40)
    assert len(frf.omega) >= 20 and frf.stable.all() and not frf.turning_points
    ref = np.array([jenkins_frf_h1(w, m, k, cc, kt, fs, F)[0] for w in frf.omega])
    # sampling error of the AFT at n_t = 1024 is a few 1e-5 (the 1e-5 check at n_t = 4096 is in
    # test_hbm_oscillator); what this checks is that every continuation point is a solution
    assert np.max(np.abs(frf.amplitude - ref) / ref) <= 6e-5
    # the peak is found between the slipping (1) and stuck (sqrt 2) resonances
    wpk = frf.omega[np.argmax(frf.amplitude)]
    assert 1.0 < wpk < np.sqrt(2.0)


def test_lightly_damped_linear_peak_is_resolved():
    """Joint stuck (mu huge), 0.2 % damping: the continuation must not step over the resonance."""
    m1, m2, k, kt = 2.0, 1.0, 50.0, 40.0
    M = np.diag([m1, m2])
    K = k * np.array([[1.0, -1.0], [-1.0, 1.0]])
    s = LinearStructure(M, K, damping_ratio=0.002)
    c = FrictionContacts(np.array([[[0, -1, -1], [1, -1, -1]]]), kt=kt, kn=1.0, mu=1e6, n0=1.0)
    hb = HarmonicBalance(s, c, harmonics=1, samples=32)
    f = np.array([1.0, 0.0])
    wn = np.sqrt((k + kt) * (m1 + m2) / (m1 * m2))
    frf = hb.frf(0.5 * wn, 1.5 * wn, f, dof=0)
    # exact linear FRF (modal damping 0.2 % of the elastic mode, rigid mode undamped)
    lam, Phi = np.linalg.eigh(np.diag(1 / np.sqrt([m1, m2])) @ (K + kt * np.array([[1, -1], [-1, 1]]))
                              @ np.diag(1 / np.sqrt([m1, m2])))
    Phi = np.diag(1 / np.sqrt([m1, m2])) @ Phi
    w = np.linspace(0.5 * wn, 1.5 * wn, 200001)
    H = sum(np.outer(Phi[0, i] * Phi[0, i], 1.0 / (lam[i] - w**2 + 2j * 0.002 * np.sqrt(max(lam[i], 0)) * w))
            for i in range(2))[0]
    assert len(frf.omega) >= 100
    assert abs(frf.amplitude.max() - np.abs(H).max()) <= 0.02 * np.abs(H).max()


def softening_oscillator(harmonics=3, samples=64):
    """1-DOF mass on a preloaded normal contact that opens (stiffness 4 closed, 1 open): folds."""
    s = LinearStructure([[1.0]], [[1.0]], [[0.1]])
    c = FrictionContacts(np.array([[[-1, -1, 0], [-1, -1, -1]]]), kt=1.0, kn=3.0, mu=0.5, n0=0.1)
    return HarmonicBalance(s, c, harmonics=harmonics, samples=samples)


@pytest.mark.parametrize("name, value", [
    ("max_points", 0), ("max_points", 2.5), ("ds", 0.0), ("ds", np.inf), ("ds_max", -0.1),
    ("ds_min", 0.0), ("max_corrector", 0), ("stability", "floquet"), ("max_domega", 0.0),
    ("max_domega", np.nan), ("max_damp", -1.0), ("max_damp", np.inf), ("predictor", "euler")])
def test_settings_validation_names_the_field(name, value):
    with pytest.raises(ValueError, match=rf"ContinuationSettings\.{name} must be"):
        ContinuationSettings(**{name: value})
    # frf's keywords go through the same validation
    with pytest.raises(ValueError, match=rf"ContinuationSettings\.{name} must be"):
        softening_oscillator(1, 16).frf(0.6, 2.6, np.array([0.1]), dof=0, **{name: value})


def test_settings_defaults_frozen_and_one_source_only():
    s = ContinuationSettings(ds=0.04)
    assert s.ds_min == 1e-6 * 0.04 and s.max_domega is None and s.frequency_cap(3.0, 1.0) == 0.02
    assert ContinuationSettings.from_options(ds=None, max_domega=None) == ContinuationSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.ds = 0.1
    hb = softening_oscillator(1, 16)
    with pytest.raises(TypeError, match="not both"):
        hb.frf(0.6, 2.6, np.array([0.1]), dof=0, settings=s, ds_max=0.2)
    with pytest.raises(TypeError, match="ContinuationSettings"):
        hb.frf(0.6, 2.6, np.array([0.1]), dof=0, settings={"ds": 0.04})


def test_settings_and_keywords_give_identical_branches():
    """The same options as keywords or as ContinuationSettings: bitwise the same branch, through
    folds, with guess= and stop= as fe_joint uses them."""
    opts = dict(max_points=400, ds=0.03, ds_max=0.2, ds_min=1e-7, max_corrector=10, stability="fold",
                max_domega=0.02, max_damp=0.2)
    f = np.array([0.1])
    branches = []
    for kw in (opts, {"settings": ContinuationSettings(**opts)}):
        hb = softening_oscillator()
        guess = hb.solve(0.6, 0.9 * f)
        branches.append(hb.frf(0.6, 2.6, f, dof=0, guess=guess, stop=lambda a: len(a) >= 100, **kw))
    a, b = branches
    assert len(a.turning_points) >= 2 and a.method == "fold-parity" and (~a.stable).any()
    assert len(a.omega) == 100           # stop() ended the branch (it reaches 2.6 after 116)
    for name in ("omega", "amplitude", "stable"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert a.turning_points == b.turning_points and a.newton_iterations == b.newton_iterations
    assert np.array_equal(np.stack([s_.contact for s_ in a.solutions]),
                          np.stack([s_.contact for s_ in b.solutions]))


# ------------------------------------------------------------- linear-solver switches mid-branch
class ForcedPath(HarmonicBalance):
    """HarmonicBalance whose Newton systems take the GMRES path where ``gmres(omega)`` is True and
    the dense LU elsewhere, whatever their size: a solver switch at chosen frequencies, as when
    the number of slipping elements crosses ``dense_limit`` on a large model."""

    def __init__(self, s, c, gmres, **kw):
        super().__init__(s, c, **kw)
        self.gmres = gmres

    def _reduced(self, omega, nl, Dg, dense=False, out=None):
        self.dense_limit = -1 if self.gmres(omega) else 10**9
        return super()._reduced(omega, nl, Dg, dense, out)


def alternating(omega: float) -> bool:
    """GMRES and dense LU in alternate frequency bands of 0.025 rad/s (GMRES first)."""
    return int(omega * 40) % 2 == 0


def test_solver_switch_keeps_the_direction_of_travel():
    """Jenkins oscillator slipping from the start, its solves switching between GMRES and the
    dense LU: the branch goes forward to the band end without revisiting a frequency and stays
    on the closed form. (The tangent used to be oriented by a determinant sign taken at the
    start, 0 on the GMRES path, and every dense point after such a start was flipped: the branch
    retraced itself to w -> 0.)"""
    m, k, cc, kt, fs, F = 1.0, 1.0, 0.02, 1.0, 0.1, 0.3
    s = LinearStructure([[m]], [[k]], [[cc]])
    c = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=kt, kn=1.0, mu=fs, n0=1.0)
    for gmres in (lambda w: w < 1.0, alternating):
        hb = ForcedPath(s, c, gmres, harmonics=1, samples=1024)
        assert hb.solve(0.7, np.array([F])).n_nonlinear == 1        # a GMRES start that slips
        frf = hb.frf(0.7, 1.8, np.array([F]), dof=0, ds_max=0.3, max_domega=1.1 / 40)
        assert frf.omega[-1] == 1.8 and np.all(np.diff(frf.omega) > 0) and not frf.turning_points
        assert hb.stats["gmres_iterations"] > 0 and frf.stable.all()
        # every 7th point and the peak (the closed form takes 0.5 s a point)
        pts = np.union1d(np.arange(0, frf.omega.size, 7), [np.argmax(frf.amplitude)])
        ref = np.array([jenkins_frf_h1(w, m, k, cc, kt, fs, F)[0] for w in frf.omega[pts]])
        assert np.max(np.abs(frf.amplitude[pts] - ref) / ref) <= 6e-5


def test_fold_branch_is_the_same_whichever_solver_takes_each_point():
    """Softening oscillator whose contact opens from the start (two folds): with the solves
    switching between GMRES and the dense LU in alternate bands, the branch is the all-dense one
    (same points, folds and fold-parity stability, amplitudes to solver tolerance). Fold parity
    is what the study's large models use; it is the flag the spurious folds of a flipped
    tangent corrupted."""
    f = np.array([0.2])
    runs = {}
    for name, gmres in (("dense", lambda w: False), ("switching", alternating)):
        s, c = softening_oscillator().s, softening_oscillator().c
        hb = ForcedPath(s, c, gmres, harmonics=3, samples=64)
        runs[name] = hb.frf(0.6, 2.6, f, dof=0, ds_max=0.1, stability="fold")
    a, b = runs["dense"], runs["switching"]
    assert len(a.turning_points) == 2 and a.omega[a.turning_points[0]] > a.omega[a.turning_points[1]]
    assert (~a.stable).sum() == 5 and b.omega[-1] == 2.6
    assert a.turning_points == b.turning_points and np.array_equal(a.stable, b.stable)
    assert len(a.omega) == len(b.omega)
    assert np.max(np.abs(a.amplitude - b.amplitude)) <= 1e-8 * a.amplitude.max()
    assert np.max(np.abs(a.omega - b.omega)) <= 1e-8 * a.omega.max()


def test_the_secant_predictor_traces_the_tangent_predictors_branch(monkeypatch):
    """The softening oscillator's two folds with either predictor: the secant one solves for a
    tangent only at the start (none on smooth stretches: one linear solve per point fewer),
    finds the same two turning points (fold parity marks as many points unstable) at the same
    frequencies to the spacing of the points around them, and ends on the same solution."""
    import hbm.continuation as cont
    runs, tangents = {}, []
    tangent = cont._tangent

    def counting(*args, **kwargs):
        tangents.append(1)
        return tangent(*args, **kwargs)
    monkeypatch.setattr(cont, "_tangent", counting)
    for predictor in cont.PREDICTORS:
        tangents.clear()
        hb = softening_oscillator()
        frf = hb.frf(0.6, 2.6, np.array([0.2]), dof=0, ds_max=0.1, stability="fold",
                     predictor=predictor)
        runs[predictor] = (frf, len(tangents), hb.stats["linear_solves"])
    (a, ta, la), (b, tb, lb) = runs["tangent"], runs["secant"]
    assert ta == len(a.omega) and tb == 1 and lb < la - 0.5 * len(b.omega)
    assert len(a.turning_points) == len(b.turning_points) == 2
    assert (~a.stable).sum() == (~b.stable).sum() > 0
    for ia, ib in zip(a.turning_points, b.turning_points):
        spacing = np.abs(np.diff(b.omega[ib - 2:ib + 3])).max()
        assert abs(a.omega[ia] - b.omega[ib]) <= spacing
    assert a.omega[-1] == b.omega[-1] == 2.6
    assert abs(a.amplitude[-1] / b.amplitude[-1] - 1) <= 1e-8


def test_middle_slope_is_the_parabolas_derivative():
    """The secant predictor's turning points use dw/ds at a point from its two neighbours: exact
    for a parabola w(s) through three unevenly spaced points."""
    import hbm.continuation as cont
    w = lambda s: 0.3 - 2.0 * (s - 0.1) ** 2            # noqa: E731 (dw/ds = -4 (s - 0.1))
    s0, s1, s2 = -0.05, 0.02, 0.2
    h1, h2 = s1 - s0, s2 - s1
    got = cont._middle_slope(h1, (w(s1) - w(s0)) / h1, h2, (w(s2) - w(s1)) / h2)
    assert got == pytest.approx(-4.0 * (s1 - 0.1), rel=1e-12)


def test_oriented_determinant_sign_is_a_branch_invariant(monkeypatch):
    """The oriented bordered-determinant sign is the same at every point and corner restart of a
    branch, through folds. Without a solver switch (dense path) the previous point's sign, now
    the reference of each orientation, is therefore the start's, the reference before: such
    branches are bitwise those of the former rule. On the GMRES path the sign is unknown (0)
    except where it was computed exactly (corners, sharp turns), and then it is the dense one.
    The tangent predictor (a sign at every point); the secant one's are tested below."""
    import hbm.continuation as cont
    signs = []
    tangent = cont._tangent

    def recording(*args, **kwargs):
        t, sign = tangent(*args, **kwargs)
        signs.append(sign)
        return t, sign
    monkeypatch.setattr(cont, "_tangent", recording)
    s, c = softening_oscillator().s, softening_oscillator().c
    known = {}
    for name, gmres in (("dense", lambda w: False), ("gmres", lambda w: True)):
        signs.clear()
        frf = ForcedPath(s, c, gmres, harmonics=3, samples=64).frf(0.6, 2.6, np.array([0.2]), dof=0,
                                                                    ds_max=0.1, stability="none",
                                                                    predictor="tangent")
        assert len(frf.turning_points) == 2 and len(signs) >= len(frf.omega)
        known[name] = set(signs[1:]) - {0}      # signs[0]: the start's, before its orientation
        assert len(known[name]) == 1
    assert 0 in signs and known["dense"] == known["gmres"]


@pytest.mark.parametrize("predictor, min_lus", [("tangent", 8), ("secant", 2)])
def test_gmres_path_passes_corner_folds_like_the_dense_path(predictor, min_lus):
    """Mass on an inclined preloaded friction contact (tangential and normal gap both follow x),
    n_t = 32: the branch turns by more than 90 deg at corners of the sampled law (8 tangent
    flips, no fold in frequency). Every solve on the GMRES path, which has no determinant sign,
    must give the dense path's branch: the corner signs are then taken from a dense LU. (With
    t . t_prev > 0 alone the branch went back the way it came and the step fell below ds_min.)
    The secant predictor meets fewer corners head-on (2 restarts against 4), so fewer LUs."""
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, 0], [-1, -1, -1]]]), kt=2.0, kn=2.0, mu=0.3, n0=0.2)
    runs = {}
    for name, gmres in (("dense", lambda w: False), ("gmres", lambda w: True)):
        hb = ForcedPath(s, c, gmres, harmonics=1, samples=32)
        runs[name] = hb.frf(0.4, 2.5, np.array([0.4]), dof=0, stability="none", predictor=predictor)
        runs[name + " LUs"] = hb.stats["sign_factorizations"]
    a, b = runs["dense"], runs["gmres"]
    assert runs["dense LUs"] == 0 and runs["gmres LUs"] >= min_lus
    for r in (a, b):
        assert r.omega[-1] == 2.5 and np.all(np.diff(r.omega) > 0) and not r.turning_points
    # same points; at the corners near the peak the amplitude is sensitive (1e-6 apart there)
    assert len(a.omega) == len(b.omega) and np.max(np.abs(a.omega - b.omega)) <= 1e-6
    assert np.max(np.abs(a.amplitude - b.amplitude) / a.amplitude) <= 1e-5


def test_a_thrashing_branch_goes_on_at_the_tight_tolerance(monkeypatch):
    """The inclined contact's branch turns sharply at closely spaced corners (12 of 20 points,
    n_t = 32), but moves on: over such 20 points it gets at least 0.52 of their path length away
    (any tolerance), so it does not thrash (THRASH_PROGRESS 0.25). Counted as thrashing from
    0.6 on, it goes back THRASH_POINTS points and on from there at ``tight_tol``: every point
    from there meets it (residuals up to 10 tol at kinks, ``HarmonicBalance.converged``), the
    points before the loose tolerance only, and it ends where the branch traced at the tight
    tolerance throughout ends."""
    from hbm import continuation as cont
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, 0], [-1, -1, -1]]]), kt=2.0, kn=2.0, mu=0.3, n0=0.2)
    f, tight = np.array([0.4]), (1e-11, 1e-12)
    hb = HarmonicBalance(s, c, harmonics=1, samples=32, tol=1e-4)
    assert hb.frf(0.4, 2.5, f, dof=0, stability="none", tight_tol=tight).tightened_at == -1
    assert hb.tol == 1e-4
    ref = HarmonicBalance(s, c, harmonics=1, samples=32, tol=tight[0], krylov_tol=tight[1])
    ref = ref.frf(0.4, 2.5, f, dof=0, stability="none")
    monkeypatch.setattr(cont, "THRASH_PROGRESS", 0.6)
    frf = hb.frf(0.4, 2.5, f, dof=0, stability="none", tight_tol=tight)
    k = frf.tightened_at
    assert cont.THRASH_POINTS <= k < len(frf.omega) - 10 and (hb.tol, hb.krylov_tol) == tight
    res = np.array([p.residual for p in frf.solutions])
    assert res[k:].max() <= 10 * tight[0] and res[:k].max() > 1e3 * tight[0]
    assert frf.omega[-1] == ref.omega[-1] == 2.5
    assert abs(frf.amplitude[-1] / ref.amplitude[-1] - 1) <= 1e-9
    with pytest.raises(ValueError, match=r"ContinuationSettings\.tight_tol must be"):
        ContinuationSettings(tight_tol=(1e-7, 1.0))


def test_a_step_below_ds_min_goes_back_and_on_at_the_tight_tolerance(monkeypatch):
    """Where no step passes at the loose tolerance (every corrector between 1.0 and 1.02 rad/s
    fails while the solver's tol is the loose one), the branch raises below ds_min without
    ``tight_tol``; with it, it goes back THRASH_POINTS points, solves that point again at the
    tight tolerance and passes, ending where the tight branch ends."""
    from hbm import ConvergenceError
    from hbm import continuation as cont
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, 0], [-1, -1, -1]]]), kt=2.0, kn=2.0, mu=0.3, n0=0.2)
    f, loose, tight = np.array([0.4]), 1e-4, (1e-11, 1e-12)
    real = cont._correct

    def blocked(hb, force, sc, Yp, t, max_corrector):
        U, w = sc.unscale(Yp)
        if hb.tol == loose and 1.0 < w < 1.02:
            return cont._Correction(False, U, w, None, 0)
        return real(hb, force, sc, Yp, t, max_corrector)
    monkeypatch.setattr(cont, "_correct", blocked)
    # the steps zigzag at 1.0 until one lands on the branch traced more than RETRACE_SEGMENTS
    # points back (or ds falls below ds_min first)
    with pytest.raises(ConvergenceError, match="ds_min|turned back onto its branch"):
        HarmonicBalance(s, c, harmonics=1, samples=32, tol=loose).frf(0.4, 2.5, f, dof=0,
                                                                      stability="none")
    hb = HarmonicBalance(s, c, harmonics=1, samples=32, tol=loose)
    frf = hb.frf(0.4, 2.5, f, dof=0, stability="none", tight_tol=tight)
    k = frf.tightened_at
    assert k >= 1 and frf.omega[k] < 1.0 and (hb.tol, hb.krylov_tol) == tight
    assert np.all(frf.omega[:k] < 1.0) and np.all(np.diff(frf.omega) > 0)
    res = np.array([p.residual for p in frf.solutions])
    assert res[k:].max() <= 10 * tight[0] and res[:k].max() > 1e3 * tight[0]
    ref = HarmonicBalance(s, c, harmonics=1, samples=32, tol=tight[0], krylov_tol=tight[1])
    ref = ref.frf(0.4, 2.5, f, dof=0, stability="none")
    assert frf.omega[-1] == ref.omega[-1] == 2.5
    assert abs(frf.amplitude[-1] / ref.amplitude[-1] - 1) <= 1e-9


@pytest.mark.parametrize("predictor, min_restarts", [("tangent", 4), ("secant", 2)])
def test_carried_sign_is_the_exact_sign_at_every_corner(monkeypatch, predictor, min_restarts):
    """The inclined contact's branch on the GMRES path: at every corner restart, the
    determinant sign the restart orients its tangent by equals the sign a dense LU gives at the
    current point. With the tangent predictor it is the sign carried along the branch from the
    last exact one (what the former rule computed there: 23 sign LUs on this branch, 14 now), at
    the first restart too: a branch that starts with a small reduced system takes its sign at
    the start (``START_SIGN_SIZE``). The secant predictor forgets the sign at a sharp turn (a
    corner may lie within the step): the restart after one finds it again by a dense LU where
    the turn beyond the corner is sharp (here at the first of its two restarts)."""
    import hbm.continuation as cont
    checks = []
    restart = cont._Branch._corner_restart

    def checked(self, Y, Yp, failed):
        ev = cont._evaluate(self.hb, self.force, self.U, self.w)
        _, fresh = cont._tangent(self.hb, self.force, self.sc, self.w, ev, self.t, None,
                                 exact_sign=True)
        self.hb.stats["sign_factorizations"] -= 1          # the check's LU is not the branch's
        carried = self.ref_sign
        out = restart(self, Y, Yp, failed)
        checks.append((carried, self.ref_sign, fresh))
        return out
    monkeypatch.setattr(cont._Branch, "_corner_restart", checked)
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, 0], [-1, -1, -1]]]), kt=2.0, kn=2.0, mu=0.3, n0=0.2)
    hb = ForcedPath(s, c, lambda w: True, harmonics=1, samples=32)
    frf = hb.frf(0.4, 2.5, np.array([0.4]), dof=0, stability="none", predictor=predictor)
    assert frf.omega[-1] == 2.5 and len(checks) >= min_restarts
    # the sign a restart had (0: none needed, its turn was small, ``_small_turn``) is the exact one
    assert all(used in (0, fresh) and fresh != 0 for _, used, fresh in checks)
    assert any(used == fresh for _, used, fresh in checks)
    if predictor == "tangent":
        # a sign is known at every restart, the first included: no LU at the current point
        assert all(carried == fresh for carried, _, fresh in checks)


def test_a_stalled_corrector_gives_up_early(monkeypatch):
    """The inclined contact's branch on the GMRES path: a corrector that meets no point on its
    hyperplane (corner folds) gives up at its CORRECTOR_STALLS-th line search without decrease,
    not after max_corrector iterations, and every corrector that converged got there with at
    most one such line search (the creeping rule, tested below, off)."""
    import hbm.continuation as cont
    monkeypatch.setattr(cont, "SLOW_STEPS", 10**6)
    runs = []
    search, correct = cont._line_search, cont._correct

    def counting(*args, **kwargs):
        out = search(*args, **kwargs)
        runs[-1][1].append(out[4])
        return out

    def recording(*args, **kwargs):
        runs.append([None, []])
        runs[-1][0] = correct(*args, **kwargs)
        return runs[-1][0]
    monkeypatch.setattr(cont, "_line_search", counting)
    monkeypatch.setattr(cont, "_correct", recording)
    frf, settings = _inclined_gmres_frf()
    assert frf.omega[-1] == 2.5
    failed = [(corr, ls) for corr, ls in runs if not corr.ok]
    stalled = [(corr, ls) for corr, ls in failed if ls.count(False) == cont.CORRECTOR_STALLS]
    assert len(stalled) >= 3
    assert all(corr.it < settings.max_corrector and not ls[-1] for corr, ls in stalled)
    assert all(ls.count(False) < cont.CORRECTOR_STALLS for corr, ls in runs if corr.ok)


def _inclined_gmres_frf():
    """The inclined contact's FRF (ω 0.4 … 2.5, force 0.4, H = 1, 32 samples) on the GMRES path,
    without stability, with the tangent predictor (whose steps run head-on into the corners, the
    failed correctors these tests look at; the secant's meet 2 restarts, no stall): (FRFResult,
    its ContinuationSettings)."""
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, 0], [-1, -1, -1]]]), kt=2.0, kn=2.0, mu=0.3, n0=0.2)
    settings = ContinuationSettings(stability="none", predictor="tangent")
    return (ForcedPath(s, c, lambda w: True, harmonics=1, samples=32).frf(
        0.4, 2.5, np.array([0.4]), dof=0, settings=settings), settings)


def _inclined_branch(monkeypatch, slow_steps: int):
    """The inclined contact's branch on the GMRES path with the creeping rule's SLOW_STEPS set:
    (FRFResult, [(converged?, iterations, [(||R||, tolerance) per iteration])] per corrector)."""
    import hbm.continuation as cont
    monkeypatch.setattr(cont, "SLOW_STEPS", slow_steps)
    runs, norms = [], []
    correct, converged = cont._correct, HarmonicBalance.converged

    def conv(hb, r, scale, step):         # called once per iteration from the 2nd on
        norms.append((r, scale * hb.tol))
        return converged(hb, r, scale, step)

    def recording(*args):
        norms.clear()
        out = correct(*args)
        runs.append((out.ok, out.it, list(norms)))
        return out
    monkeypatch.setattr(HarmonicBalance, "converged", conv)
    monkeypatch.setattr(cont, "_correct", recording)
    frf, _ = _inclined_gmres_frf()
    return frf, runs


def test_a_creeping_corrector_gives_up_early(monkeypatch):
    """A corrector whose residual, above SLOW_ABOVE x the tolerance, falls by less than
    SLOW_RATIO in SLOW_STEPS iterations in a row gives up there: the inclined contact's branch
    reaches the band end with fewer corrector iterations than without the rule, the correctors
    that stopped so had crept (from the recorded residuals), and none that converged had."""
    import hbm.continuation as cont
    off, runs_off = _inclined_branch(monkeypatch, 10**6)
    on, runs_on = _inclined_branch(monkeypatch, 2)
    assert on.omega[-1] == off.omega[-1] == 2.5

    def creeping(norms):
        """Iterations (from the 2nd) at which the last SLOW_STEPS residual ratios crept."""
        r = [n for n, _ in norms]
        out = []
        for i in range(len(r)):
            ok = [j >= 1 and r[j] > cont.SLOW_ABOVE * norms[j][1] and r[j] > cont.SLOW_RATIO * r[j - 1]
                  for j in range(i - 1, i + 1)]
            if all(ok):
                out.append(i)
        return out
    slow = [(it, norms) for ok, it, norms in runs_on if not ok and creeping(norms)]
    assert len(slow) >= 2
    # a creeping corrector stops at the first iteration where the rule holds
    assert all(creeping(norms)[0] == len(norms) - 1 for it, norms in slow)
    assert not any(creeping(norms) for ok, it, norms in runs_on if ok)
    failed_its = [sum(it for ok, it, _ in runs if not ok) for runs in (runs_off, runs_on)]
    assert failed_its[1] < failed_its[0]

class FlakyContacts(FrictionContacts):
    """Contacts whose march 'does not close' at every ``every``-th new point (as an element far
    from the branch can on a continuation's trial point): CycleNotClosed is raised instead. As
    the real march, it is deterministic: a point once evaluated (or refused) is again."""

    every = 20

    def evaluate(self, u, *args, **kwargs):
        seen = self.__dict__.setdefault("seen", {})
        key = np.asarray(u).tobytes()
        if key not in seen:
            self.calls = getattr(self, "calls", 0) + 1
            seen[key] = self.calls % self.every == 0 and self.calls > 1
            self.raised = getattr(self, "raised", 0) + seen[key]
        if seen[key]:
            raise CycleNotClosed("friction cycle did not close in 200 periods", 3.9e-3)
        return super().evaluate(u, *args, **kwargs)


def test_a_march_that_does_not_close_shortens_the_step_not_the_curve():
    """A trial point whose friction march does not close (CycleNotClosed, raised by the residual
    evaluation) is a rejected trial: the continuation halves its step and carries on. The curve
    still ends at the band's end on the closed form. (On the resonator's quick preset one such
    trial at the top level stopped the whole run with exit 3.)"""
    m, k, cc, kt, fs, F = 1.0, 1.0, 0.02, 1.0, 0.1, 0.3
    s = LinearStructure([[m]], [[k]], [[cc]])
    c = FlakyContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=kt, kn=1.0, mu=fs, n0=1.0)
    hb = HarmonicBalance(s, c, harmonics=1, samples=1024)
    frf = hb.frf(0.7, 1.8, np.array([F]), dof=0, ds_max=0.3, max_domega=1.1 / 40)
    assert c.raised >= 5
    assert frf.omega[-1] == 1.8 and np.all(np.diff(frf.omega) > 0)
    pts = np.union1d(np.arange(0, frf.omega.size, 7), [np.argmax(frf.amplitude)])
    ref = np.array([jenkins_frf_h1(w, m, k, cc, kt, fs, F)[0] for w in frf.omega[pts]])
    assert np.max(np.abs(frf.amplitude[pts] - ref) / ref) <= 6e-5


def test_a_march_that_does_not_close_is_a_rejected_trial_of_the_backbone():
    """The same for the nonlinear mode (EPMC): with every 20th new point refused, the backbone
    is the one computed without failures (ω to 1e-8, ζ to 1e-6), not a stalled one."""
    s = LinearStructure([[1.0]], [[1.0]], damping_ratio=0.01)
    dofs = np.array([[[0, -1, -1], [-1, -1, -1]]])
    ref = HarmonicBalance(s, FrictionContacts(dofs, kt=1.0, kn=1.0, mu=0.1, n0=1.0), harmonics=1,
                          samples=256).nonlinear_mode(0, (0.05, 5.0), dof=0, n_points=12)
    c = FlakyContacts(dofs, kt=1.0, kn=1.0, mu=0.1, n0=1.0)
    c.every = 4
    bb = HarmonicBalance(s, c, harmonics=1, samples=256).nonlinear_mode(0, (0.05, 5.0), dof=0,
                                                                        n_points=12)
    assert c.raised >= 3 and bb.complete
    # the same points to the Newton tolerance (different iterates reach them)
    assert np.allclose(bb.omega, ref.omega, rtol=1e-8, atol=0)
    assert np.allclose(bb.zeta, ref.zeta, rtol=1e-6, atol=0)


def test_a_corner_restart_onto_a_far_point_is_refused(monkeypatch):
    """A corner restart is held to the step bounds of a plain step (frequency within
    3 max_domega, amplitude within max_damp): once, a failed corrector is followed by a
    'restart' that lands on a converged point beyond the band end (as v2's top-level sweep of
    the quick model did on 2 ranks next to its peak, which cut 42 points off the curve). The
    step is halved instead, and the curve is the one traced without the fault."""
    from hbm import continuation as cn
    s = LinearStructure([[1.0]], [[1.0]], [[0.1]])
    c = FrictionContacts(np.array([[[-1, -1, 0], [-1, -1, -1]]]), kt=1.0, kn=3.0, mu=0.5, n0=0.1)
    hb = HarmonicBalance(s, c, harmonics=3, samples=64)
    f = np.array([0.1])
    ref = hb.frf(0.6, 2.6, f, dof=0, ds_max=0.1, stability="none")
    far = hb.solve(2.7, f)
    real_correct, calls = cn._correct, {"n": 0}

    def failing_once(hb_, force, sc, Yp, t, max_corrector):
        calls["n"] += 1
        corr = real_correct(hb_, force, sc, Yp, t, max_corrector)
        return corr._replace(ok=False) if calls["n"] == 20 else corr

    def restart_far(self, Y, Yp, failed):
        U = self.hb.from_contact(far.contact)
        return cn._Correction(True, U, 2.7, cn._evaluate(self.hb, self.force, U, 2.7), 1), True
    monkeypatch.setattr(cn, "_correct", failing_once)
    monkeypatch.setattr(cn._Branch, "_corner_restart", restart_far)
    frf = hb.frf(0.6, 2.6, f, dof=0, ds_max=0.1, stability="none")
    assert calls["n"] > 20
    cap = ContinuationSettings(ds_max=0.1).frequency_cap(0.6, 2.6)
    assert np.abs(np.diff(frf.omega)).max() <= 3 * cap
    # the whole curve (its points placed differently after the halved step): both folds, the
    # same end, the top to the spacing of the points
    assert abs(frf.omega[-1] - 2.6) < 1e-12 and len(frf.turning_points) >= 2
    assert abs(len(frf.omega) - len(ref.omega)) <= 3
    assert np.isclose(frf.amplitude.max(), ref.amplitude.max(), rtol=1e-2)


def _line_branch(n: int):
    """A branch's stand-in for the retrace checks: n points along U from (U, w) = (0, 1) to
    (n - 1, 1 + 0.1 (n - 1)), the current point last, unit scaling; and a corrected point
    (U, w) -> _Correction."""
    from types import SimpleNamespace

    from hbm import continuation as cn
    pts = [(float(u), 1.0 + 0.1 * u) for u in range(n)]
    path = cn._Path()
    for u, w in pts:
        path.append(np.array([[u]]), w)
    br = SimpleNamespace(sols=pts, path=path, sc=cn._Scaling(1.0, 1.0, (1, 1)))
    return br, (lambda u, w: cn._Correction(True, np.array([[u]]), w, None, 1))


def test_a_point_on_the_branch_already_traced_is_a_retrace():
    """``_Branch._retraces``: a corrected point on a segment of the branch before the current
    point is a retrace (the step went back); a point ahead, and one where the branch turns back
    in frequency but goes on in the response (a fold's Z), is not."""
    from hbm import continuation as cn
    # a branch along U from (U, w) = (0, 1) to (4, 1.4), then current at (5, 1.5)
    br, corr = _line_branch(6)
    retraces = lambda c: cn._Branch._retraces(br, c)     # noqa: E731
    assert retraces(corr(2.5, 1.25)) and retraces(corr(1.02, 1.1))
    assert not retraces(corr(6.0, 1.6))                  # ahead
    assert not retraces(corr(6.0, 1.45))                 # back in ω, on in U: a fold
    assert not retraces(corr(4.5, 1.45))                 # the current segment itself is not checked


def test_a_point_on_the_branch_traced_long_before_is_a_turn_back():
    """``_Branch._turned_back``: a corrected point on a segment that ends more than
    RETRACE_SEGMENTS points before the current one means the branch went back onto itself (a
    crawl of many small steps at a corner hides it from ``_retraces``' window); a point ahead, a
    fold's Z (the same frequency, another response) and a step back onto the last segments
    (``_retraces``' case) are not. ``_Path.truncate`` keeps the points and segments in step."""
    from hbm import continuation as cn
    # a branch along U from (U, w) = (0, 1) to (30, 4), the current point last
    br, corr = _line_branch(31)
    path = br.path
    back = lambda c: cn._Branch._turned_back(br, c)      # noqa: E731
    window = lambda c: cn._Branch._retraces(br, c)       # noqa: E731
    far = corr(12.5, 2.25)
    assert back(far) and not window(far)
    near = corr(27.5, 3.75)                              # on the last segments: _retraces' case
    assert window(near) and not back(near)
    assert not back(corr(31.0, 4.1))                     # ahead
    assert not back(corr(31.0, 2.25))                    # a fold's Z: that frequency, another U
    path.truncate(13)
    assert len(path.rows) == len(path.w) == 13 and len(path.du) == 12
    assert not path.retraces(np.array([[12.5]]), 2.25, br.sc, 0, 13)   # no segment 12 now
    assert path.retraces(np.array([[11.5]]), 2.15, br.sc, 0, 13)


def test_a_corner_restart_with_a_small_turn_takes_no_lu(monkeypatch):
    """``_Branch._small_turn``: on the GMRES path (no determinant sign) a corner restart whose
    tangent at the predictor turned by less than acos(SHARP_TURN) restarts along it, oriented
    with t . t_prev > 0, without a dense LU; a sharper turn, a sign from the dense path, or a
    system on the dense path leaves the orientation to the dense LU (None)."""
    from types import SimpleNamespace

    from hbm import continuation as cn
    t = np.array([1.0, 0.0])
    answers = []

    def tangent(*args, **kwargs):
        assert not kwargs.get("exact_sign")
        return answers.pop(0)
    monkeypatch.setattr(cn, "_tangent", tangent)
    hb = SimpleNamespace(stats={"unsigned_restarts": 0}, nH=3, dense_limit=10)
    br = SimpleNamespace(hb=hb, force=None, sc=None, t=t)
    ev = SimpleNamespace(nl=np.arange(2))                  # 18 unknowns: the GMRES path
    small = lambda: cn._Branch._small_turn(br, 1.0, ev)    # noqa: E731
    turn = lambda c: (np.array([c, np.sqrt(1 - c * c)]), 0)         # noqa: E731
    answers[:] = [turn(0.95)]
    assert np.array_equal(small(), turn(0.95)[0]) and hb.stats["unsigned_restarts"] == 1
    answers[:] = [turn(0.5), (turn(0.99)[0], 1)]
    assert small() is None and small() is None and not answers
    hb.dense_limit = 18
    answers[:] = [turn(0.99)]
    assert small() is None and answers                     # the dense path: no tangent asked
    assert hb.stats["unsigned_restarts"] == 1


def test_a_branch_starting_small_on_the_gmres_path_takes_its_sign_there(monkeypatch):
    """A Jenkins oscillator slipping from the start, every solve on the GMRES path: its branch
    takes the determinant sign at the start by one dense LU (a reduced system within
    ``START_SIGN_SIZE``), the sign the dense path finds there; above that size it starts with
    none (0), as before."""
    from hbm import continuation as cn
    s = LinearStructure([[1.0]], [[1.0]], [[0.02]])
    c = FrictionContacts(np.array([[[0, -1, -1], [-1, -1, -1]]]), kt=1.0, kn=1.0, mu=0.1, n0=1.0)
    settings = ContinuationSettings(ds_max=0.3)
    f = np.array([0.3])
    signs = {}
    for name, gmres in (("gmres", lambda w: True), ("dense", lambda w: False)):
        hb = ForcedPath(s, c, gmres, harmonics=1, samples=256)
        br = cn._Branch(hb, f, 0, 0.7, 1.8, settings)
        assert br.sols[0].n_nonlinear == 1
        signs[name] = (br.ref_sign, hb.stats["sign_factorizations"])
    assert signs["gmres"][0] == signs["dense"][0] != 0
    assert signs["gmres"][1] == 1 and signs["dense"][1] == 0
    monkeypatch.setattr(cn, "START_SIGN_SIZE", 8)        # the reduced system has 9 unknowns
    hb = ForcedPath(s, c, lambda w: True, harmonics=1, samples=256)
    assert cn._Branch(hb, f, 0, 0.7, 1.8, settings).ref_sign == 0
    assert hb.stats["sign_factorizations"] == 0


def test_a_singular_system_shortens_the_step_and_keeps_gmres(monkeypatch):
    """A corrector's bordered system that is singular (GMRES fails on it and the fallback LU meets
    a zero pivot: a non-finite step): the step is shortened without a corner restart from there,
    and the solves after it stay on GMRES (no ``DENSE_AFTER_FALLBACK`` LUs, which took 60 of
    125 s of a top-level sweep on the default model). The branch is the one without the fault."""
    import hbm.continuation as cont
    import hbm.harmonic_balance as hbmod
    from hbm import ConvergenceError
    f = np.array([0.2])
    s, c = softening_oscillator().s, softening_oscillator().c
    ref = ForcedPath(s, c, lambda w: True, harmonics=3, samples=64).frf(
        0.6, 2.6, f, dof=0, ds_max=0.1, stability="none")
    hb = ForcedPath(s, c, lambda w: True, harmonics=3, samples=64)
    calls, pending, restarts = [0], [False], []
    krylov, lu = hb._krylov, hbmod.lu_solve_sign

    def failing(*args, **kwargs):
        calls[0] += 1
        if calls[0] in (60, 61):              # a corrector's system, and (GMRES again) the next
            pending[0] = True
            raise ConvergenceError("GMRES did not converge (test)", 1.0)
        return krylov(*args, **kwargs)

    def singular(*args, **kwargs):
        Z, sign = lu(*args, **kwargs)
        if pending[0]:
            pending[0] = False
            Z = np.full_like(Z, np.nan)
        return Z, sign
    restart = cont._Branch._corner_restart

    def counted(self, *args):
        restarts.append(self.w)
        return restart(self, *args)
    monkeypatch.setattr(hb, "_krylov", failing)
    monkeypatch.setattr(hbmod, "lu_solve_sign", singular)
    monkeypatch.setattr(cont._Branch, "_corner_restart", counted)
    frf = hb.frf(0.6, 2.6, f, dof=0, ds_max=0.1, stability="none")
    assert calls[0] > 61 and hb.stats["dense_fallbacks"] == 2
    assert hb.stats["dense_after_fallback"] == 0 and not restarts
    assert frf.omega[-1] == ref.omega[-1] == 2.6
    assert abs(frf.amplitude[-1] / ref.amplitude[-1] - 1) <= 1e-8
    assert len(frf.turning_points) == len(ref.turning_points) == 2
