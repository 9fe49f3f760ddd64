"""Tangential partial-slip contact with Coulomb friction along a quasi-static load path.

With identical bodies (β = 0) the normal pressure p of the normal solution is held fixed. For one
load increment from a previous state with accumulated slip field s⁰ the traction q (2 components per
cell) and the rigid tangential shift δ satisfy, with the slip s = δ − K_t*q,

    stick:  |q_i| < μ p_i  and  s_i = s⁰_i              (no slip during the increment)
    slip:   |q_i| = μ p_i  and  s_i − s⁰_i = λ_i q_i/|q_i|, λ_i ≥ 0   (slip along the traction)
    force:  A Σ q_i = Q                                                   (force control)

which is the minimum of ½ qᵀK_t q + qᵀs⁰ over the disks |q_i| ≤ μ p_i with the force constraint
(δ is its Lagrange multiplier). It is solved with a Polonsky–Keer-type constrained conjugate
gradient on the stick set, projected-gradient moves of the slip cells, projection on the disks and a
uniform force correction on the stick set (restarted from its best iterate with a halved slip step if
it stalls or diverges). Entries it has not finished after a few hundred iterations (typically almost
all cells slipping just below μP with a 2D slip-direction field) are completed by an accelerated
projected gradient (FISTA with adaptive restart, exact projection on disks ∩ force constraint), which
converges for every instance of this convex problem. The history enters only through s⁰, so loading,
unloading and reloading (Mindlin–Deresiewicz) follow from successive increments.

Stopping criterion: the pressure-weighted mean of the KKT displacement residual (|g| on stick cells,
the part of g not opposed to q on slip cells, g = K_t*q + s⁰ − δ) divided by the displacement scale
max(|δ|, max|K_t*q|), and the force mismatch |AΣq − Q|/(μP), both < tol.

Gross slip: a force with |Q| ≥ μP leaves no stick zone. ``on_gross_slip='raise'`` (default)
raises GrossSlipError before any iteration; ``'full_slip'`` returns the documented full-slip state
q = μ p Q/|Q| everywhere, stick all False, shift = nan, ``gross_slip=True`` (the rigid shift is
undefined); later steps continue from that traction with the shift measured from the last finite one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConvergenceError, GrossSlipError, finite_array, positive_scalar
from .halfspace import ElasticHalfSpace
from .normal import NormalSolution

_AX = (-2, -1)
_DEBUG = False  # set True to print the per-iteration error (development aid)


@dataclass
class TangentialState:
    """State after one tangential load step.

    Attributes:
        traction: (2, nx, ny) shear traction (q_x, q_y) in MPa.
        shift: (2,) rigid relative tangential displacement δ in mm (nan in a full-slip state).
        stick: (nx, ny) bool, loaded cells that did not slip during this step.
        slip: (nx, ny) bool, loaded cells at the Coulomb limit that slipped.
        force: (2,) total tangential force A Σ q in N.
        slip_field: (2, nx, ny) accumulated slip s = δ − K_t*q in mm (the history variable).
        iterations: iterations used.
        residual: final error measure.
        gross_slip: True for the full-slip state of ``on_gross_slip='full_slip'``.
    """

    traction: np.ndarray
    shift: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    force: np.ndarray
    slip_field: np.ndarray
    iterations: int
    residual: float
    gross_slip: bool = False

    @property
    def stick_fraction(self) -> float:
        """Stuck area / loaded (p > 0) area."""
        n = self.stick.sum() + self.slip.sum()
        return float(self.stick.sum() / n) if n else 0.0


def _project(q: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Project tractions (B, 2, nx, ny) on the disks |q| ≤ R (B, nx, ny)."""
    n = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2)
    f = np.where(n > R, R / np.where(n > 0, n, 1.0), 1.0)
    return q * f[:, None]


def _force_correct(q, R, S, loaded, Q, A, n_pass: int = 3):
    """Restore A Σ q = Q by a uniform shift on the stick set (then project), a few passes."""
    for _ in range(n_pass):
        dQ = Q - A * q.sum(axis=_AX)                        # (B, 2)
        nS = S.sum(axis=_AX)                                 # (B,)
        w = np.where((nS > 0)[:, None, None], S, loaded).astype(float)
        w /= np.maximum(w.sum(axis=_AX, keepdims=True), 1.0)
        q = _project(q + (dQ / A)[:, :, None, None] * w[:, None], R)
        qn = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2)
        S = loaded & (qn < R * (1 - 1e-10))
    return q


@np.errstate(over="ignore", invalid="ignore")  # diverging entries are caught and restarted
def pk_tangential_batch(apply_kt, R: np.ndarray, s_prev: np.ndarray, q0: np.ndarray, Q: np.ndarray,
                        cell_area: float, *, tol: float = 1e-8, max_iter: int = 2000,
                        raise_on_fail: bool = True, omega: np.ndarray | None = None) -> dict:
    """Batched partial-slip increment (internal; inputs already validated, |Q| < μP).

    Args:
        apply_kt: callable (B, 2, nx, ny) traction → (B, 2, nx, ny) tangential displacement.
        R: (B, nx, ny) Coulomb radii μ p (MPa).
        s_prev: (B, 2, nx, ny) accumulated slip before the increment (mm).
        q0: (B, 2, nx, ny) traction before the increment (warm start).
        Q: (B, 2) target forces (N).
        cell_area: mm².
        tol, max_iter: see module docstring.

    Returns:
        dict with traction, displacement, shift (B, 2), stick, iterations (B,), residual (B,).

    Raises:
        ConvergenceError: some entry not converged after max_iter iterations.
    """
    B = R.shape[0]
    A = cell_area
    loaded = R > 0
    muP = R.sum(axis=_AX) * A                                # (B,)
    fscale = np.where(muP > 0, muP, 1.0)
    q = _project(np.where(loaded[:, None], q0, 0.0), R)
    qn = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2)
    q = _force_correct(q, R, loaded & (qn < R * (1 - 1e-10)), loaded, Q, A)
    u = apply_kt(q)
    delta = np.zeros((B, 2))
    t = np.zeros_like(q)
    G_old = np.ones(B)
    use_beta = np.zeros(B, dtype=bool)
    active = np.ones(B, dtype=bool)
    err = np.full(B, np.inf)
    iters = np.zeros(B, dtype=int)
    Rw = R.sum(axis=_AX)
    Rw = np.where(Rw > 0, Rw, 1.0)
    # safeguard: slip-cell moves use the CG step times omega; a diverging entry restarts from its
    # best iterate with omega halved (the degenerate stick/slip boundary at a load reversal can
    # otherwise make the projected moves of the slip cells oscillate)
    omega = np.ones(B) if omega is None else np.asarray(omega, float).copy()
    best_err = np.full(B, np.inf)
    best_q = q.copy()
    stall = np.zeros(B, dtype=int)
    tau_self = 0.5 / abs(apply_kt(_unit(q.shape[2:]))[0, 0, 0, 0])
    for it in range(max_iter + 1):
        e, delta_new, parts = _kkt_error(q, u, s_prev, R, Rw, Q, A, fscale)
        delta = np.where(active[:, None], delta_new, delta)
        S, SL, nS, g = parts["S"], parts["SL"], parts["nS"], parts["g"]
        err = np.where(active, e, err)
        active &= ~(err < tol)
        if _DEBUG:
            print(it, err, omega, S.sum(axis=_AX), SL.sum(axis=_AX), delta[0])
        if not active.any() or it == max_iter:
            break
        improved = active & (err < 0.999 * best_err)
        best_err = np.where(improved, err, best_err)
        best_q = np.where(improved[:, None, None, None], q, best_q)
        stall = np.where(improved, 0, stall + 1)
        diverged = active & ((err > 100.0 * best_err) | (stall > 40) | ~np.isfinite(err)) & (omega > 1e-4)
        stall = np.where(diverged, 0, stall)
        if diverged.any():
            omega = np.where(diverged, 0.5 * omega, omega)
            q = np.where(diverged[:, None, None, None], best_q, q)
            use_beta &= ~diverged
            u = apply_kt(q)
            continue
        iters += active
        # --- CG direction on the stick set (zero mean there: force-free) ---
        G = np.where(S[:, None], g * g, 0.0).sum(axis=(1, 2, 3))
        beta = np.where(use_beta, G / np.where(G_old > 0, G_old, 1.0), 0.0)
        beta = np.where(beta < 1e4, beta, 0.0)  # a vanishing previous gradient: restart, don't blow up
        t = np.where(S[:, None], g + beta[:, None, None, None] * t, 0.0)
        G_old = np.where(active, G, G_old)
        r = apply_kt(t)
        r = r - (np.where(S[:, None], r, 0.0).sum(axis=_AX) / np.maximum(nS, 1)[:, None])[:, :, None, None]
        num = np.where(S[:, None], g * t, 0.0).sum(axis=(1, 2, 3))
        den = np.where(S[:, None], r * t, 0.0).sum(axis=(1, 2, 3))
        # no usable CG step (no stick cell, or a single one whose zero-mean gradient vanishes):
        # move the slip cells with a step at the self-compliance scale instead
        tau = np.where((den > 0) & (num > 0), num / np.where(den > 0, den, 1.0), tau_self)
        # slip cells: projected-gradient move (releases cells into stick, rotates the slip direction)
        step = np.where(S[:, None], t, np.where(SL[:, None], omega[:, None, None, None] * g, 0.0))
        q_new = _project(q - tau[:, None, None, None] * step, R)
        if _DEBUG:
            m = loaded[0]
            print('  tau', tau, num, den, beta, 'g', g[0][:, m], 'q', q[0][:, m], 'R', R[0][m], 'step', step[0][:, m], 'qnew', q_new[0][:, m])
        qn_new = np.sqrt(q_new[:, 0] ** 2 + q_new[:, 1] ** 2)
        S_new = loaded & (qn_new < R * (1 - 1e-10))
        changed = np.any(S_new != S, axis=_AX)
        q_new = _force_correct(q_new, R, S_new, loaded, Q, A)
        use_beta = np.where(active, ~changed, use_beta)
        q = np.where(active[:, None, None, None], q_new, q)
        u = apply_kt(q)
    if active.any() and raise_on_fail:
        raise ConvergenceError(
            f"solve_tangential: {int(active.sum())} of {B} problems not converged to tol={tol:g}",
            float(np.max(err[active])), int(iters.max()))
    qn = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2)
    stick = loaded & (qn < R * (1 - 1e-10))
    return {"traction": q, "displacement": u, "shift": delta, "stick": stick,
            "iterations": iters, "residual": err, "converged": ~active, "omega": omega}


def _kkt_error(q, u, s_prev, R, Rw, Q, A, fscale):
    """KKT error of an iterate (see module docstring).

    Returns:
        (err (B,), δ (B, 2), parts) with parts = dict of the stick/slip masks S, SL, their count nS,
        the gradient g = K*q + s⁰ − δ, the unit traction direction qhat and g·qhat (gq).
    """
    g = u + s_prev
    qn = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2)
    S = (R > 0) & (qn < R * (1 - 1e-10))
    SL = (R > 0) & ~S
    nS = S.sum(axis=_AX)
    gbar = np.where(S[:, None], g, 0.0).sum(axis=_AX) / np.maximum(nS, 1)[:, None]
    # no stick cell (transient near μP): the R-weighted mean over the loaded cells, so that the
    # cells lagging behind the rigid shift are released back into stick
    gall = (R[:, None] * g).sum(axis=_AX) / Rw[:, None]
    delta = np.where((nS > 0)[:, None], gbar, gall)
    g = g - delta[:, :, None, None]
    qhat = q / np.where(qn > 0, qn, 1.0)[:, None]
    gq = (g * qhat).sum(axis=1)
    gt = g[:, 1] * qhat[:, 0] - g[:, 0] * qhat[:, 1]
    gabs = np.sqrt(gq * gq + gt * gt)
    res = np.where(S, gabs, np.where(SL, np.where(gq <= 0, np.abs(gt), gabs), 0.0))
    scale = np.maximum(np.maximum(np.abs(delta).max(axis=1), np.abs(u).max(axis=(1, 2, 3))), 1e-300)
    e1 = (R * res).sum(axis=_AX) / (Rw * scale)
    e3 = np.sqrt(((A * q.sum(axis=_AX) - Q) ** 2).sum(axis=1)) / fscale
    return np.maximum(e1, e3), delta, {"S": S, "SL": SL, "nS": nS, "g": g, "qhat": qhat, "gq": gq}


def _project_force(y, R, Q, A, lam, ftol: float = 1e-11):
    """Project y (B, 2, nx, ny) on {|q_i| ≤ R_i} ∩ {A Σ q = Q}: q = proj_disks(y − λ), λ (B, 2) by
    safeguarded Newton on the 2-vector force equation (monotone), warm-started from ``lam``."""
    loaded = R > 0
    fs = np.maximum(R.sum(axis=_AX) * A, 1e-300)
    lam = lam.copy()

    def F(l, sel):
        q = _project(np.where(loaded[sel, None], y[sel] - l[:, :, None, None], 0.0), R[sel])
        return q, A * q.sum(axis=_AX) - Q[sel]

    q, f = F(lam, slice(None))
    fn = np.sqrt((f * f).sum(axis=1)) / fs
    for _ in range(50):
        open_ = np.nonzero(fn >= ftol)[0]
        if open_.size == 0:
            break
        v = y[open_] - lam[open_, :, None, None]
        Ro, lo = R[open_], loaded[open_]
        vn = np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2)
        inside = lo & (vn <= Ro)
        bnd = lo & ~inside
        inv = np.where(bnd, 1.0 / np.where(vn > 0, vn, 1.0), 0.0)
        r = Ro * inv
        nx_, ny_ = v[:, 0] * inv, v[:, 1] * inv
        # dF/dλ = −A Σ D_i, D = I inside, (R/|v|)(I − n nᵀ) on the boundary
        n_in = inside.sum(axis=_AX)
        j00 = n_in + (r * (1 - nx_ * nx_)).sum(axis=_AX)
        j11 = n_in + (r * (1 - ny_ * ny_)).sum(axis=_AX)
        j01 = -(r * nx_ * ny_).sum(axis=_AX)
        det = j00 * j11 - j01 * j01
        ok = det > 1e-14 * np.maximum(j00 + j11, 1e-300) ** 2
        d = np.where(ok, det, 1.0)
        fo = f[open_]
        step = np.stack([(j11 * fo[:, 0] - j01 * fo[:, 1]) / d, (j00 * fo[:, 1] - j01 * fo[:, 0]) / d], axis=1) / A
        # singular Jacobian (every cell on its disk, aligned): move along F scaled by the cell count
        step = np.where(ok[:, None], step, fo / (A * np.maximum(lo.sum(axis=_AX), 1))[:, None])
        t = np.ones(open_.size)
        todo = np.ones(open_.size, dtype=bool)
        for _ in range(20):  # backtracking on |F|, only for the entries still failing
            sel = open_[todo]
            lt = lam[sel] + t[todo, None] * step[todo]
            qt, ft = F(lt, sel)
            fnt = np.sqrt((ft * ft).sum(axis=1)) / fs[sel]
            good = fnt < fn[sel] * (1 - 1e-4 * t[todo]) + 1e-300
            gi = np.nonzero(todo)[0][good]
            lam[open_[gi]] = lt[good]
            q[open_[gi]] = qt[good]
            f[open_[gi]] = ft[good]
            fn[open_[gi]] = fnt[good]
            todo[gi] = False
            if not todo.any():
                break
            t = np.where(todo, 0.5 * t, t)
        if todo.any():  # no decrease at all: at round-off level, stop these entries
            fn[open_[todo]] = 0.0
    return q, lam


def fista_tangential_batch(apply_kt, lipschitz: float, R, s_prev, q0, Q, cell_area, *, tol: float = 1e-6,
                           max_iter: int = 5000, raise_on_fail: bool = True, check_every: int = 5) -> dict:
    """Accelerated projected gradient (FISTA with adaptive restart) for the same increment problem.

    Slower than the CG on regular problems but convergent for every convex instance: used as the
    fallback for entries the CG does not finish (e.g. almost all cells slipping just below μP with a
    2D slip-direction field). Step 1/L with L the largest eigenvalue of the tangential operator.
    """
    B = R.shape[0]
    A = cell_area
    Rw = R.sum(axis=_AX)
    Rw = np.where(Rw > 0, Rw, 1.0)
    fscale = np.where(R.sum(axis=_AX) > 0, R.sum(axis=_AX) * A, 1.0)
    lam = np.zeros((B, 2))
    x, lam = _project_force(q0, R, Q, A, lam)
    y = x.copy()
    t = np.ones(B)
    active = np.ones(B, dtype=bool)
    err = np.full(B, np.inf)
    iters = np.zeros(B, dtype=int)
    step = 1.0 / lipschitz
    for it in range(max_iter + 1):
        if it % check_every == 0 or it == max_iter:
            ux = apply_kt(x)
            e, delta, _ = _kkt_error(x, ux, s_prev, R, Rw, Q, A, fscale)
            err = np.where(active, e, err)
            active &= ~(err < tol)
            if not active.any() or it == max_iter:
                break
        iters += active
        grad = apply_kt(y) + s_prev
        x_new, lam = _project_force(y - step * grad, R, Q, A, lam)
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        dx = x_new - x
        restart = ((y - x_new) * dx).sum(axis=(1, 2, 3)) > 0
        mom = np.where(restart, 0.0, (t - 1.0) / t_new)
        y_new = x_new + mom[:, None, None, None] * dx
        t = np.where(restart, 1.0, t_new)
        a4 = active[:, None, None, None]
        x = np.where(a4, x_new, x)
        y = np.where(a4, y_new, y)
    if active.any() and raise_on_fail:
        raise ConvergenceError(
            f"solve_tangential: {int(active.sum())} of {B} problems not converged to tol={tol:g}",
            float(np.max(err[active])), int(iters.max()))
    ux = apply_kt(x)
    e, delta, parts = _kkt_error(x, ux, s_prev, R, Rw, Q, A, fscale)
    S = parts["S"]
    return {"traction": x, "displacement": ux, "shift": delta, "stick": S, "iterations": iters,
            "residual": e, "converged": ~active, "omega": np.ones(B)}


def pk_tangential_compacting(apply_kt, R, s_prev, q0, Q, cell_area, *, tol: float = 1e-6,
                             max_iter: int = 3000, chunk: int = 40, lipschitz: float | None = None,
                             cg_iter: int = 40) -> dict:
    """Batched increment solve: CG rounds that drop converged entries, then a FISTA fallback.

    A batch of patches converges very unevenly (median ~10, a slow tail of hundreds of iterations);
    restarting the unconverged rest (warm-started from its current traction) on a smaller batch
    makes the FFTs of the slow tail cheap. Entries still open after ``cg_iter`` CG iterations are
    finished by ``fista_tangential_batch`` (needs ``lipschitz``) within ``max_iter`` in total.
    Same arguments and result keys as ``pk_tangential_batch``.
    """
    B = R.shape[0]
    out = None
    idx = np.arange(B)
    done_it = 0
    n_it = chunk
    while True:
        use_cg = done_it < cg_iter or lipschitz is None
        n_it = min(n_it, max_iter - done_it)
        if use_cg:
            res = pk_tangential_batch(apply_kt, R[idx], s_prev[idx],
                                      q0[idx] if out is None else out["traction"][idx], Q[idx], cell_area,
                                      tol=tol, max_iter=n_it, raise_on_fail=False,
                                      omega=None if out is None else out["omega"][idx])
        else:
            n_it = max_iter - done_it
            res = fista_tangential_batch(apply_kt, lipschitz, R[idx], s_prev[idx], out["traction"][idx],
                                         Q[idx], cell_area, tol=tol, max_iter=n_it, raise_on_fail=False)
        if out is None:
            out = {k: v.copy() for k, v in res.items()}
        else:
            for k, v in res.items():
                out[k][idx] = v if k != "iterations" else out[k][idx] + v
        done_it += n_it
        n_it = 3 * chunk  # later rounds long enough for the stall safeguard to act
        conv = res["converged"]
        if conv.all():
            return out
        if done_it >= max_iter:
            raise ConvergenceError(
                f"solve_tangential: {int((~conv).sum())} of {B} problems not converged to tol={tol:g}",
                float(np.max(res["residual"][~conv])), done_it)
        idx = idx[~conv]


def _unit(shape):
    e = np.zeros((1, 2) + tuple(shape))
    e[0, 0, 0, 0] = 1.0
    return e


def solve_tangential(hs: ElasticHalfSpace, ns: NormalSolution, mu: float, forces, *,
                     initial: TangentialState | None = None, tol: float = 1e-6, max_iter: int = 3000,
                     on_gross_slip: str = "raise") -> list[TangentialState]:
    """Quasi-static Coulomb partial slip along a tangential force path (force control).

    Args:
        hs: the half-space used for ``ns``.
        ns: normal solution; its pressure is held fixed (β = 0).
        mu: friction coefficient (≥ 0).
        forces: sequence of (Q_x, Q_y) total tangential forces in N, one per load step, applied in
            order from the ``initial`` state (default: virgin, q = 0, no slip).
        initial: state to continue the history from (its traction and slip field).
        tol: tolerance of the KKT error (module docstring), in (0, 1).
        max_iter: iterations per step; exceeding it raises ConvergenceError with the residual.
        on_gross_slip: 'raise' (GrossSlipError when |Q| ≥ μP) or 'full_slip' (documented state).

    Returns:
        list of TangentialState, one per step.
    """
    if not isinstance(hs, ElasticHalfSpace):
        raise ValueError(f"hs: expected an ElasticHalfSpace, got {type(hs).__name__}")
    if not isinstance(ns, NormalSolution) or ns.pressure.shape != hs.grid.shape:
        raise ValueError("ns: expected the NormalSolution of a solve on the same grid")
    mu = positive_scalar("mu", mu, allow_zero=True)
    F = finite_array("forces", forces, (None, 2))
    tol = positive_scalar("tol", tol, upper=1.0, upper_open=True)
    if on_gross_slip not in ("raise", "full_slip"):
        raise ValueError(f"on_gross_slip: must be 'raise' or 'full_slip', got {on_gross_slip!r}")
    grid = hs.grid
    A = grid.cell_area
    R = mu * ns.pressure
    muP = float(R.sum() * A)
    if initial is None:
        q = np.zeros((2,) + grid.shape)
        s = np.zeros((2,) + grid.shape)
        shift_ref = np.zeros(2)
    else:
        q = finite_array("initial.traction", initial.traction, (2,) + grid.shape).copy()
        s = finite_array("initial.slip_field", initial.slip_field, (2,) + grid.shape).copy()
        shift_ref = np.asarray(initial.shift, float)
        if not np.all(np.isfinite(shift_ref)):
            shift_ref = np.zeros(2)
    out = []
    loaded = R > 0
    for Qk in F:
        if np.hypot(*Qk) >= muP * (1 - 1e-9):
            if on_gross_slip == "raise":
                raise GrossSlipError(
                    f"forces: |Q| = {np.hypot(*Qk):.6g} N reaches the Coulomb limit mu*P = {muP:.6g} N "
                    "(gross slip, no stick zone); use on_gross_slip='full_slip' for the sliding state")
            qdir = Qk / max(np.hypot(*Qk), 1e-300)
            q = R[None] * qdir[:, None, None]
            u = hs.tangential_displacement(q)
            s = shift_ref[:, None, None] - u  # slip field referred to the last finite shift
            out.append(TangentialState(q, np.full(2, np.nan), np.zeros(grid.shape, bool), loaded.copy(),
                                       q.sum(axis=_AX) * A, s, 0, 0.0, gross_slip=True))
            continue
        res = pk_tangential_compacting(hs._apply_tangential, R[None], s[None], q[None], Qk[None], A,
                                       tol=tol, max_iter=int(max_iter), lipschitz=hs.tangential_lipschitz,
                                       cg_iter=min(400, int(max_iter)))  # single solves: CG longer
        q = res["traction"][0]
        shift = res["shift"][0]
        s = shift[:, None, None] - res["displacement"][0]
        shift_ref = shift
        stick = res["stick"][0]
        out.append(TangentialState(q, shift.copy(), stick, loaded & ~stick, q.sum(axis=_AX) * A, s.copy(),
                                   int(res["iterations"][0]), float(res["residual"][0])))
    return out
