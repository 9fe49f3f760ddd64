"""Nonlinear modes by the Extended Periodic Motion Concept (EPMC, Krack 2015), condensed on the contacts.

Problem
-------
The autonomous system M q'' + (C - xi M) q' + K q + f(q, q') = 0 has a periodic solution of
frequency w for the right artificial damping xi: the negative damping -xi M q' feeds back exactly
the energy that C and the friction dissipate per cycle. ``(w(a), xi(a))`` along the amplitude a is
the nonlinear mode; zeta = xi / (2 w) is its damping ratio (for a linear structure with modal
damping it is the modal damping ratio, exactly).

Condensed formulation (the forced solver's unknowns)
---------------------------------------------------
As in ``harmonic_balance`` the unknowns are the harmonics U of the contact relative displacements,
written about the linear base (contacts closed at rest stuck), g = F_nl(U) - k0 U. In the base's
mass-normalized modes the damping term only shifts the modal damping, c_k -> c_k - xi (Phi^T M Phi
= I), so the receptance with xi is the forced one with shifted modal factors. At the linear limit
(every element stuck, g = 0) that receptance is singular at harmonic 1 for the mode of interest j:
the motion is the free mode and carries no force. So mode j at harmonic 1 is taken out of the
receptance and its coordinate is imposed:

* amplitude and phase normalisation: eta_j,1 = a, real (eta_j(t) = a cos(w t) + higher harmonics;
  the sine coefficient of the mode's first harmonic is 0);
* contact balance:  R(U, w, xi) = U - a psi_j e_cos + G~(w, xi) g(U) = 0, with G~ the receptance
  with damping c - xi and without mode j at harmonic 1 (psi_j = B phi_j, e_cos the cos row);
* the two real equations of mode j at harmonic 1, which fix w and xi:
      r(U, w, xi) = (lam_j - w^2 + i w (c_j - xi)) a + psi_j^T g_1 = 0,   g_1 = g_a1 - i g_b1.

Unknowns U (n_H x n_c), w, xi; equations n_H n_c + 2. Stuck and open-all-cycle elements have
dg/dU = 0 as in the forced solver, so each Newton step is the forced solver's reduced linear
solve on the nonlinear elements only. On the dense path (LU) it has three right-hand sides
(-R, -dR/dw, -dR/dxi), then a 2 x 2 solve for (dw, dxi) (block elimination); on the GMRES path
one run on the system bordered by w and xi (``HarmonicBalance.linsolve_bordered``), which took
3414 GMRES iterations on the default model's baseline backbone where the three right-hand
sides took 9722 (the same Newton iterations).
The Jacobian is analytic: the AFT part is the friction elements' exact Jacobian, the w and xi
derivatives of the modal factors are in closed form.

Needs modal damping diagonal in the linear base's modes (``damping_ratio``, proportional C, or
none); a coupled damping matrix raises ValueError.

Energy and damping definitions
------------------------------
With the modal coordinates eta_h of the kept modes (complex, per harmonic h):

* K = sum_h 1/2 (h w)^2 |eta_h|^2: the kinetic-energy measure (the peak kinetic energy of a
  single-harmonic motion; 2x the cycle-mean kinetic energy in general);
* work of the negative damping per cycle: W_xi = xi (2 pi / w) K;
* dissipation per cycle: friction W_f (work of the retained force harmonics on the contact
  motion, ``HarmonicBalance.element_results(...).energy``) + viscous W_v = pi w sum_h h^2 eta_h^H C_m eta_h;
* energy-based damping ratio zeta_E = (W_f + W_v) / (2 pi * 2 K) (= W / (4 pi E_kin,max), the usual
  definition). The balance W_xi = W_f + W_v holds at every converged point (Galerkin), hence
  zeta_E = zeta; the tests check it to 1e-8.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import ConvergenceError, CycleNotClosed
from .harmonic_balance import KRYLOV_FORCING, STALL_BELOW, STALL_ITERATIONS, Solution
from .structure import Receptance


class _ModeReceptance(Receptance):
    """The base receptance with modal damping c - xi and mode j removed at harmonic 1."""

    def __init__(self, base: Receptance, j: int) -> None:
        self.__dict__.update(base.__dict__)        # shares the base's arrays (no copies)
        self.j = int(j)
        self.xi = 0.0

    def _full(self, h: int, omega: float) -> np.ndarray:
        w = h * omega
        d = self.lam - w * w + 1j * w * (self.cvec - self.xi)
        if h == 1:
            d[self.j] = 1.0            # removed by the callers (zero at the linear mode itself)
        return 1.0 / d

    def modal(self, h: int, omega: float) -> np.ndarray:
        if h == 0:
            return Receptance.modal(self, 0, omega)
        L = self._full(h, omega)
        if h == 1:
            L[self.j] = 0.0
        return L

    def dmodal(self, h: int, omega: float, wrt: str) -> np.ndarray:
        """d(modal factor)/d(omega) or d/d(xi) (wrt "omega" | "xi"), (m,) complex."""
        if h == 0:
            return np.zeros(self.lam.size, dtype=complex)
        L = self._full(h, omega)
        dD = (-2.0 * h * h * omega + 1j * h * (self.cvec - self.xi)) if wrt == "omega" \
            else np.full(L.size, -1j * h * omega)
        out = -L * L * dD
        if h == 1:
            out[self.j] = 0.0
        return out


@dataclass
class LinearBackground:
    """The off-resonant part of the linear base's receptance at one DOF: every kept mode except
    the mode of interest, plus the static residual flexibility of the discarded modes.

    The single-nonlinear-mode synthesis adds its (linear) response to the mode's own, with its
    phase (``synthesis.synthesize``): H_bg(W)[dof, :] f = sum_{k != j} row_k (Phi_k . f) /
    (lam_k - W^2 + i W c_k) + static . f. Rigid-body modes (lam = 0) are kept: at W > 0 they are
    the mass line of a free-free structure.

    Attributes:
        lam: (m,) eigenvalues of the linear base's kept modes, (rad/s)^2.
        c: (m,) their modal damping coefficients (2 zeta_k omega_k), 1/s.
        row: (m,) mode shapes at the DOF, Phi[dof, k], with the mode of interest set to 0.
        Phi: (n, m) mass-normalized mode shapes (for the projection Phi^T f of a force), or the
            rows of the forced DOFs only (:meth:`restrict`).
        static: (n,) row ``dof`` of the static residual flexibility (zeros when every mode is
            kept), mm/N; restricted like Phi.
    """

    lam: np.ndarray
    c: np.ndarray
    row: np.ndarray
    Phi: np.ndarray = field(repr=False)
    static: np.ndarray = field(repr=False)

    def response(self, omega, force) -> np.ndarray:
        """Complex first-harmonic response at the DOF to force cos(W t), x = Re(X e^{iWt}).

        Args:
            omega: excitation frequency W, rad/s (scalar or array).
            force: (n,) force amplitude, N (the rows of ``Phi``).

        Returns:
            X, complex, mm, shaped like ``omega``.
        """
        F = np.asarray(force)
        wgt = self.row * (self.Phi.T @ F)
        W = np.asarray(omega, dtype=float)[..., None]
        return np.sum(wgt / (self.lam - W * W + 1j * W * self.c), axis=-1) + self.static @ F

    def restrict(self, dofs) -> "LinearBackground":
        """The same background for forces on ``dofs`` only (the rows kept for a stored backbone)."""
        d = np.asarray(dofs, dtype=int)
        return LinearBackground(self.lam, self.c, self.row, self.Phi[d], self.static[d])


@dataclass
class Backbone:
    """A nonlinear mode sampled along the amplitude (p points).

    Attributes:
        mode: elastic mode index of the linear base that was continued.
        dof: response DOF of ``displacement_amplitude``.
        modal_amplitude: (p,) imposed first-harmonic coordinate a of the mass-normalized linear
            mode (the continuation parameter), mm·t^0.5.
        mass_amplitude: (p,) ||eta_1||, the mass norm sqrt(q_1^H M q_1) of the first harmonic over
            the kept modes (Krack's and tmdsimpy's "modal amplitude"; = modal_amplitude while
            the mode keeps its linear shape), mm·t^0.5.
        displacement_amplitude: (p,) first-harmonic amplitude at ``dof``, mm.
        omega: (p,) frequency, rad/s.
        xi: (p,) EPMC artificial damping, 1/s.
        zeta: (p,) xi / (2 omega).
        zeta_energy: (p,) (friction + viscous energy per cycle) / (2 pi * 2 kinetic), module docstring.
        xi_viscous: (p,) viscous part of xi, Re(psi^H C_m psi) with psi = eta_1 / ||eta_1|| (what
            the synthesis scales with the excitation frequency), 1/s.
        friction_energy, viscous_energy: (p,) energy dissipated per cycle, N·mm.
        kinetic: (p,) sum_h (h w)^2 |eta_h|^2 / 2, N·mm.
        element_status: (p, ne) as ``ElementResults.status``.
        element_energy: (p, ne) friction energy per cycle per element, N·mm.
        shape: (p, n) complex first-harmonic shape Phi eta_1 / ||eta_1|| (mass-normalized,
            convention x = Re(shape e^{i w t})), for the force projection of the synthesis.
        contact: (p, ne, 3, 2H+1) contact harmonics (restarts, post-processing), mm.
        residual: (p,) final relative residual; iterations: (p,) Newton iterations.
        linear_omega, linear_zeta: the linear base mode's frequency (rad/s) and modal damping ratio.
        onset_amplitude: modal amplitude up to which w and xi are the linear mode's (first steady
            slip, separation or closure, ``NonlinearModeProblem.onset_amplitude``); when it lies inside
            the requested range it is one of the points (n_points + 1 points then).
        wall_time: seconds.
        displacement: (p,) complex first-harmonic response at ``dof`` (x = Re(X e^{i w t}), in
            the phase of ``shape``), mm; its modulus is ``displacement_amplitude``.
        background: the linear base's off-resonant receptance at ``dof``
            (:class:`LinearBackground`), added by the synthesis.
        complete: False when the continuation stopped before a1 (``partial=True``); the points
            are then those up to the last converged amplitude, and ``stop_reason`` says why.
    """

    mode: int
    dof: int
    modal_amplitude: np.ndarray
    mass_amplitude: np.ndarray
    displacement_amplitude: np.ndarray
    omega: np.ndarray
    xi: np.ndarray
    zeta: np.ndarray
    zeta_energy: np.ndarray
    xi_viscous: np.ndarray
    friction_energy: np.ndarray
    viscous_energy: np.ndarray
    kinetic: np.ndarray
    element_status: np.ndarray
    element_energy: np.ndarray
    shape: np.ndarray = field(repr=False)
    contact: np.ndarray = field(repr=False)
    residual: np.ndarray = field(repr=False)
    iterations: np.ndarray = field(repr=False)
    linear_omega: float = float("nan")
    linear_zeta: float = float("nan")
    onset_amplitude: float = float("inf")
    wall_time: float = 0.0
    complete: bool = True
    stop_reason: str = ""
    displacement: np.ndarray | None = field(default=None, repr=False)
    background: LinearBackground | None = field(default=None, repr=False)

    def restrict(self, dofs) -> "Backbone":
        """A copy whose ``shape`` (and background) keep only the columns ``dofs`` (``dof`` must be
        one of them and is renumbered): enough to synthesize forces on those DOFs, small to store."""
        d = [int(x) for x in dofs]
        if self.dof not in d:
            raise ValueError(f"dofs must contain the backbone's dof {self.dof}, got {d}")
        return replace(self, shape=self.shape[:, d], dof=d.index(self.dof),
                       background=None if self.background is None else self.background.restrict(d))

    @property
    def xi_work(self) -> np.ndarray:
        """Work of the negative damping xi M q' per cycle, xi (2 pi / w) K, N·mm."""
        return self.xi * 2.0 * np.pi / self.omega * self.kinetic


#: A Newton iterate at which no step along the Newton direction lowers the residual any more,
#: with a residual below STAGNATION_FLOOR x tol, is accepted as the solution. The friction march
#: makes the residual piecewise smooth: its switches (a sample's stick/slip/open decision) leave
#: a floor of round-off size times the kink, and a strict tol (1e-9) can sit below it. The quick
#: resonator's v1 backbone stalled there (residual 2e-8 after 8 step halvings, at 0.0152 modal
#: amplitude; v1 on v2's elements at 0.0125) instead of reaching gross slip. The floor grows with
#: the contact stiffness: the default model's layer joint (k_n 10 x the patch value) stalled at
#: 1.5e-7 … 3.3e-7 near a modal amplitude of 0.023 and its backbone ended there, missing the SNMS
#: peaks at the two upper levels. 1000 x 1e-9 = 1e-6 (the point's residual is kept in
#: ``Backbone.residual``) moves a synthesized peak by ~1e-6, far below what it is compared with.
STAGNATION_FLOOR = 1000.0
#: A Newton run whose best residual is below STAGNATION_FLOOR x tol returns it once the residual
#: has not halved in this many iterations: it is accepted anyway (above), and the stiff layer
#: joint's top points crept on at 1e-8 … 1e-7 for 8-12 more iterations (0.6-0.9 s each) before
#: the forced Newton's stall rule (STALL_ITERATIONS) ended them.
FLOOR_STALL_ITERATIONS = 3

#: The backbone steps over an output amplitude after this many failed Newton runs in a row that
#: stalled near convergence (residual <= STALL_BELOW: a kink of the sampled friction law), not
#: after ``max_halvings``: shorter steps towards the same amplitude stall on the same kink. The
#: default model's stiff layer joint met one at 0.0233 in one run (its top amplitude, and so its
#: output amplitudes, follow the smooth-ms forced peak): nine failed runs at 1e-6 … 1e-7, 20-30 s
#: each, made its backbone take 386 s instead of 151 s.
KINK_STALLS = 2
#: A failed Newton run at an output amplitude whose last converged point (reached by halved
#: steps towards it) lies within this fraction of the output step below it (in log amplitude,
#: three halvings): that point is the output point instead. A kink of the sampled friction law at
#: the output amplitude itself made Newton fail there again and again: the default model's stiff
#: layer joint met one at 0.0233 in every run (its output amplitudes follow the smooth-ms forced
#: peak), 4-8 failed runs of up to 20 GMRES-heavy iterations, 13-22 of its 49-78 s (session 24).
#: Only a Newton run that failed near convergence counts (residual <= NEAR_OUTPUT_RESIDUAL; at
#: that kink 1.1e-5 ... 2.3e-4), not a friction march that did not close (CycleNotClosed):
#: that one is not the amplitude's doing, and a retry from nearer gets there.
NEAR_OUTPUT = 0.125
NEAR_OUTPUT_RESIDUAL = 1e-3


class NonlinearModeProblem:
    """The condensed EPMC equations of one mode (module docstring) and their Newton solver.

    The state is x = (U.ravel(), w, xi); the residual is (R.ravel(), Re r, Im r), with R relative
    to nothing (mm) and r divided by lam_j a (dimensionless).

    Args:
        hb: the forced solver (structure, contacts, harmonics, samples, tolerances are its own).
        mode: elastic mode index of the linear base (0 = lowest non-rigid mode).
        tol, max_iter: Newton tolerance (relative) and iteration limit (default: hb's).
    """

    def __init__(self, hb, mode: int, tol: float | None = None, max_iter: int | None = None) -> None:
        G = hb.G
        if not G.diag_damping:
            raise ValueError("nonlinear_mode needs damping that is diagonal in the linear base's "
                             "modes (damping_ratio=, proportional C or none)")
        elastic = np.nonzero(~G.rigid)[0]
        if isinstance(mode, bool) or int(mode) != mode or not (0 <= mode < elastic.size):
            raise ValueError(f"mode must be an integer in [0, {elastic.size - 1}] (elastic modes "
                             f"kept), got {mode!r}")
        self.hb, self.mode = hb, int(mode)
        self.j = j = int(elastic[int(mode)])
        self.ep = copy.copy(hb)                 # same solver, modified receptance
        self.G = self.ep.G = _ModeReceptance(G, j)
        self.lam_j, self.c_j = float(G.lam[j]), float(G.cvec[j])
        self.psi_j = G.Psi[:, j].copy()
        self.tol = hb.tol if tol is None else float(tol)
        self.max_iter = hb.max_iter if max_iter is None else int(max_iter)
        if not (0 < self.tol < 1) or self.max_iter < 1:
            raise ValueError(f"tol must be in (0, 1) and max_iter >= 1, got {tol!r}, {max_iter!r}")
        self.shape_u = (hb.nH, hb.nc)

    # ------------------------------------------------------------------ pieces
    def linear_point(self, a: float):
        """The linear stuck mode at amplitude a: (U, w, xi)."""
        return self.ua(a), np.sqrt(self.lam_j), self.c_j

    def ua(self, a: float) -> np.ndarray:
        U = np.zeros(self.shape_u)
        U[1] = a * self.psi_j
        return U

    def _eval(self, U, w, xi, a, jacobian=True, deferred=False):
        self.G.xi = xi
        R, g, nl, Dg = self.ep.residual(U, w, self.ua(a), jacobian=jacobian, deferred=deferred)
        r = ((self.lam_j - w * w + 1j * w * (self.c_j - xi)) * a
             + self.psi_j @ (g[1] - 1j * g[2])) / (self.lam_j * a)
        return R, r, g, nl, Dg

    def _dg(self, nl, Dg, X):
        """dg/dU X for X (n_H, n_c) (nonzero on the nonlinear elements only)."""
        hb = self.hb
        out = np.zeros((hb.ne, 3, hb.nH))
        if nl.size:
            Xe = hb.to_contact(X)[nl].reshape(nl.size, -1)
            out[nl] = np.matmul(Dg, Xe[:, :, None])[:, :, 0].reshape(nl.size, 3, hb.nH)
        return hb.from_contact(out)

    def _row(self, dg, a):
        return self.psi_j @ (dg[1] - 1j * dg[2]) / (self.lam_j * a)

    def _param_derivs(self, g, w, xi, a):
        """dR/dw, dR/dxi at fixed U and dr/dw, dr/dxi (analytic)."""
        self.G.xi = xi
        H = self.hb.H
        out = []
        for wrt, dS in (("omega", -2.0 * w + 1j * (self.c_j - xi)), ("xi", -1j * w)):
            f = [self.G.dmodal(h, w, wrt) for h in range(H + 1)]
            out.append((self.ep.gapply(w, g, factors=f, static=False), dS / self.lam_j))
        return out

    def onset_amplitude(self) -> float:
        """Largest modal amplitude up to which w and xi are those of the linear mode (inf if never).

        On u = a psi_j cos(wt) (per element: p tangential, q normal amplitude per unit a, the
        tangential motion along a line; N0 = n0 - kn g), a closed element's periodic state sticks
        while the tangential force range 2 kt a |p| stays within mu (N(0) + N(pi)) = 2 mu N0,
        i.e. a <= mu N0 / (kt |p|), and stays closed while a kn |q| < N0; an open one (N0 <= 0)
        closes at a kn |q| = -N0. (Below the slip bound an element may still slip once on the way
        from rest, where the AFT march starts, and stick with a shifted slider: that moves the
        0th harmonic only.) The extremes cos = +-1 are samples of the AFT grid, so the sampled and
        the continuous onsets agree."""
        c = self.hb.c
        v = self.psi_j.reshape(c.ne, 3)
        p, q = np.hypot(v[:, 0], v[:, 1]), np.abs(v[:, 2])
        N0 = c.n0 - c.kn * c.gap
        with np.errstate(divide="ignore", invalid="ignore"):
            slip = np.where(c.kt * p > 0, c.mu * N0 / (c.kt * p), np.inf)
            sep = np.where(q > 0, np.abs(N0) / (c.kn * q), np.inf)
        a = np.where(N0 > 0, np.minimum(slip, sep), sep)
        return float(a.min())

    def background(self, dof: int) -> LinearBackground:
        """The base receptance at ``dof`` without the mode of interest (:class:`LinearBackground`)."""
        G = self.hb.G
        row = G.Phi[dof].copy()
        row[self.j] = 0.0
        static = np.zeros(self.hb.s.n) if G.complete else G.residual_row(dof)
        return LinearBackground(G.lam.copy(), G.cvec.copy(), row, G.Phi, static)

    # ------------------------------------------------------------------ vector form (tests)
    def split(self, x: np.ndarray):
        n = self.shape_u[0] * self.shape_u[1]
        return x[:n].reshape(self.shape_u), float(x[n]), float(x[n + 1])

    def residual(self, x: np.ndarray, a: float) -> np.ndarray:
        """Residual vector (R.ravel(), Re r, Im r) at state x = (U.ravel(), w, xi), amplitude a."""
        R, r, *_ = self._eval(*self.split(x), a, jacobian=False)
        return np.concatenate([R.ravel(), [r.real, r.imag]])

    def jacobian(self, x: np.ndarray, a: float) -> np.ndarray:
        """Dense analytic Jacobian of :meth:`residual` (small problems: one column per unknown)."""
        U, w, xi = self.split(x)
        R, r, g, nl, Dg = self._eval(U, w, xi, a)
        n = U.size
        J = np.zeros((n + 2, n + 2))
        for k in range(n):
            e = np.zeros(n)
            e[k] = 1.0
            E = e.reshape(self.shape_u)
            dg = self._dg(nl, Dg, E)
            col = E + self.ep.gapply(w, dg)
            rr = self._row(dg, a)
            J[:, k] = np.concatenate([col.ravel(), [rr.real, rr.imag]])
        for k, (dR, dS) in enumerate(self._param_derivs(g, w, xi, a)):
            J[:, n + k] = np.concatenate([dR.ravel(), [dS.real, dS.imag]])
        return J

    # ------------------------------------------------------------------ Newton
    def _merit(self, R, r, U, a):
        sU = max(np.linalg.norm(U), np.linalg.norm(self.psi_j) * a, 1e-300)
        return np.hypot(np.linalg.norm(R) / sU, abs(r)), sU

    def _trial(self, U, w, xi, a, phi: float, alpha: float) -> bool:
        """Line-search trial: True if the merit falls enough (evaluation kept in _last_trial).
        A trial whose friction march does not close counts as a rejected one (shorter step)."""
        try:
            ev = self._eval(U, w, xi, a, deferred=True)     # the Jacobian once accepted
        except CycleNotClosed:
            return False
        self._last_trial = (ev, self._merit(ev[0], ev[1], U, a))
        return self._last_trial[1][0] <= (1 - 1e-4 * alpha) * phi

    def solve(self, a: float, U: np.ndarray, w: float, xi: float):
        """Damped Newton at amplitude a from (U, w, xi).

        Returns:
            (U, w, xi, relative residual, iterations, g, nl).
        """
        R, r, g, nl, Dg = self._eval(U, w, xi, a)
        phi, sU = self._merit(R, r, U, a)
        step = np.inf
        best = (np.inf, None)          # the best iterate, (merit, (U, w, xi, phi, it, g, nl))
        mark = (np.inf, 0)             # the last merit that halved the one before, iteration
        for it in range(self.max_iter + 1):
            if phi <= self.tol or (phi <= 10 * self.tol and step <= 10 * self.tol):
                return U, w, xi, phi, it, g, nl
            if phi < best[0]:
                best = (phi, (U, w, xi, phi, it, g, nl))
            if phi <= 0.5 * mark[0]:
                mark = (phi, it)
            elif best[0] <= STAGNATION_FLOOR * self.tol and it - mark[1] >= FLOOR_STALL_ITERATIONS:
                return best[1]          # already acceptable, and no longer converging
            elif best[0] <= STALL_BELOW and it - mark[1] >= STALL_ITERATIONS:
                # the forced Newton's stall rule: near a kink of the sampled friction law the
                # merit can crawl for all max_iter iterations (the stiff layer joint's backbone
                # of the default model: 20-50 s per failed amplitude); the floor rule below
                # applies to the best iterate
                if best[0] <= STAGNATION_FLOOR * self.tol:
                    return best[1]
                break
            if it == self.max_iter:
                break
            (dRw, dSw), (dRx, dSx) = self._param_derivs(g, w, xi, a)
            # the bordered system solved to what the step needs (inexact Newton, as the forced
            # solver's corrector: ``_step``); session 11 had found the opposite (the stiff layer
            # joint's backbone 184 s against 150 s), before the stall and floor rules above
            dU, dw, dxi = self._step(w, nl, Dg, R, r, (dRw, dSw), (dRx, dSx), a, sU, phi)
            alpha = 1.0
            for _ in range(12):
                Ut, wt, xt = U + alpha * dU, w + alpha * dw, xi + alpha * dxi
                if wt > 0 and self._trial(Ut, wt, xt, a, phi, alpha):
                    ev, (phit, sUt) = self._last_trial
                    break
                alpha *= 0.5
            else:
                if best[0] <= STAGNATION_FLOOR * self.tol:
                    # no descent left at a floor of the nonsmooth residual (module constant)
                    return best[1]
                break
            step = alpha * max(np.linalg.norm(dU) / sU, abs(dw) / w, abs(dxi) / w)
            U, w, xi = Ut, wt, xt
            R, r, g, nl, Dg = ev
            Dg = Dg() if callable(Dg) else Dg
            phi, sU = phit, sUt
        raise ConvergenceError(f"EPMC Newton did not converge at modal amplitude {a:.6g}",
                               min(phi, best[0]))

    def _step(self, w, nl, Dg, R, r, dw_terms, dxi_terms, a, sU, phi):
        """The Newton step (dU, dw, dxi). On the GMRES path one bordered solve (the frequency and
        damping as its two borders, ``HarmonicBalance.linsolve_bordered``); else, or where it
        fails (then by the dense LU), three right-hand sides (-R, -dR/dw, -dR/dxi) and a 2 x 2
        elimination. (The default model's backbones took three GMRES runs of ~48 iterations
        each per step.)

        GMRES stops once the bordered system's residual is below ``KRYLOV_FORCING`` x tol x sU,
        what the merit needs (not ``krylov_tol`` relative to a right-hand side that shrinks with
        every Newton step). On the default model's backbones (issue 16, session 26): 31-34 %
        fewer GMRES iterations, the same points and residual counts, synthesized peaks within
        2e-8 in frequency; the stiff layer joint's 55 % fewer (60.3 -> 31.1 s)."""
        (dRw, dSw), (dRx, dSx) = dw_terms, dxi_terms
        re, im = np.zeros(self.shape_u), np.zeros(self.shape_u)
        re[1] = self.psi_j / (self.lam_j * a)             # row(dg) = re . dg + i im . dg
        im[2] = -re[1]
        S = np.array([[dSw.real, dSx.real], [dSw.imag, dSx.imag]])
        # the border rows weighted as in the merit: |R| / sU against |r|
        try:
            one = self.ep.linsolve_bordered(w, nl, Dg, [dRw, dRx], [re, im], S, R,
                                            np.array([r.real, r.imag]), row_scale=sU,
                                            atol=KRYLOV_FORCING * self.tol * sU)
        except ConvergenceError:                 # GMRES failed: the dense LU, as linsolve does
            one, direct = None, True
        else:
            direct = False
        if one is not None:
            dU, (dw, dxi) = one
            return dU, float(dw), float(dxi)
        X0, Xw, Xx = self.ep.linsolve(w, nl, Dg, [-R, -dRw, -dRx], direct=direct)
        cw = self._row(self._dg(nl, Dg, Xw), a) + dSw
        cx = self._row(self._dg(nl, Dg, Xx), a) + dSx
        b = -r - self._row(self._dg(nl, Dg, X0), a)
        A = np.array([[cw.real, cx.real], [cw.imag, cx.imag]])
        try:
            dw, dxi = np.linalg.solve(A, [b.real, b.imag])
        except np.linalg.LinAlgError:
            raise ConvergenceError(f"singular EPMC Newton system at a = {a:.6g}", phi) from None
        return X0 + Xw * dw + Xx * dxi, dw, dxi

    # ------------------------------------------------------------------ post-processing
    def modal_coordinates(self, g: np.ndarray, w: float, xi: float, a: float) -> np.ndarray:
        """Kept-mode coordinates eta (m, H+1) complex of the solution with correction forces g."""
        self.G.xi = xi
        G, H = self.G, self.hb.H
        gc = np.concatenate([g[:1], g[1::2] - 1j * g[2::2]]).T        # (nc, H+1)
        PtG = -(G.Psi.T @ gc)
        eta = np.stack([G.modal(h, w) * PtG[:, h] for h in range(H + 1)], axis=1)
        eta[self.j, 1] += a
        return eta

    def point(self, a, U, w, xi, g, dof):
        """Everything the Backbone stores about one converged point."""
        hb, G = self.hb, self.G
        eta = self.modal_coordinates(g, w, xi, a)
        h = np.arange(hb.H + 1)
        e2 = np.abs(eta) ** 2
        kin = 0.5 * np.sum((h * w) ** 2 * e2)
        Wv = np.pi * w * np.sum(h ** 2 * (G.cvec[:, None] * e2))
        eta1 = eta[:, 1]
        amass = float(np.linalg.norm(eta1))
        psi = eta1 / amass
        xi_v = float(np.real(np.conj(psi) @ (G.cvec * psi)))
        y = -(hb.B.T @ g.T).T
        qd = self.ep._recover_dofs(w, y, dof)
        qd[1] += a * G.Phi[dof, self.j]
        er = hb.element_results(Solution(w, None, hb.to_contact(U).copy(), 0.0, 0, 0))
        Wf = float(er.energy.sum())
        return dict(mass_amplitude=amass, displacement_amplitude=float(np.hypot(qd[1], qd[2])),
                    displacement=complex(qd[1] - 1j * qd[2]),
                    kinetic=kin, viscous_energy=Wv, friction_energy=Wf, xi_viscous=xi_v,
                    zeta_energy=(Wf + Wv) / (4.0 * np.pi * kin), shape=G.Phi @ psi,
                    element_status=er.status, element_energy=er.energy)


def continue_backbone(hb, mode: int, amplitudes, dof: int, *, n_points: int = 40,
                      tol: float | None = None, max_iter: int | None = None,
                      max_halvings: int = 8, partial: bool = False) -> Backbone:
    """Natural-parameter continuation of the nonlinear mode in log amplitude (secant predictor).

    The backbone is a function of the amplitude, so the amplitude is the parameter: output points
    at ``n_points`` log-spaced modal amplitudes from a0 to a1; the first starts from the linear
    stuck mode, each next one from the secant through the last two points in log a (of U/a, w and
    xi). A failed Newton halves the step in log a (intermediate points are not reported), at most
    ``max_halvings`` times in a row (``KINK_STALLS`` times when Newton stalls near convergence);
    then it tries once the whole step to the next output amplitude (a kink of the sampled
    friction law can sit right at one output amplitude: that one is then missing, and
    ``stop_reason`` names it, ``complete`` stays True); if that fails
    too, the continuation raises ConvergenceError, or with ``partial`` returns the points reached
    so far (``complete`` False, at least two points).

    Args: see ``HarmonicBalance.nonlinear_mode``.

    Returns:
        Backbone.
    """
    t0 = time.perf_counter()
    try:
        a0, a1 = (float(v) for v in amplitudes)
    except (TypeError, ValueError):
        raise ValueError(f"amplitudes must be a pair (a0, a1), got {amplitudes!r}") from None
    if not (np.isfinite(a0) and np.isfinite(a1) and 0 < a0 < a1):
        raise ValueError(f"amplitudes must satisfy 0 < a0 < a1 (finite), got {amplitudes!r}")
    if isinstance(n_points, bool) or int(n_points) != n_points or n_points < 2:
        raise ValueError(f"n_points must be an integer >= 2, got {n_points!r}")
    if isinstance(dof, bool) or int(dof) != dof or not (0 <= dof < hb.s.n):
        raise ValueError(f"dof must be an integer in [0, {hb.s.n - 1}], got {dof!r}")
    # a mode has no time origin (its sign is arbitrary, and flipping it moves the motion by half
    # a period): the elements that stick all cycle after slipping take the slider nearest rest,
    # which does not depend on it (hbm.shakedown); forced responses keep the march from rest at
    # the excitation's t = 0
    prev, hb.c.shakedown = hb.c.shakedown, True
    try:
        return _continue(hb, mode, a0, a1, dof, int(n_points), tol, max_iter, max_halvings, partial, t0)
    finally:
        hb.c.shakedown = prev


def _continue(hb, mode: int, a0: float, a1: float, dof: int, n_points: int, tol, max_iter,
              max_halvings: int, partial: bool, t0: float) -> Backbone:
    """continue_backbone's continuation (its arguments checked; t0 its start, perf_counter)."""
    prob = NonlinearModeProblem(hb, mode, tol, max_iter)
    targets = np.geomspace(a0, a1, int(n_points))
    onset = prob.onset_amplitude()
    if a0 < onset < a1:
        # the backbone has a corner there (xi leaves its linear value): a point exactly at the
        # corner lets the synthesis interpolate each side on its own
        targets = np.sort(np.append(targets, onset))
    U, w, xi = prob.linear_point(a0)
    U, w, xi, res, it, g, nl = prob.solve(a0, U, w, xi)
    hist = [(a0, U / a0, w, xi)]
    rows = [(a0, U, w, xi, g, res, it)]
    stop, skipped, moved = "", [], []
    i = 1
    while i < targets.size and not stop:
        at = targets[i]
        halvings, jump, stalls = 0, False, 0
        near = None         # the last point converged on the way to ``at`` (halved steps)
        while not stop:
            ac, Uc, wc, xc = hist[-1]
            a_try = ac * (at / ac) ** (0.5 ** halvings)
            if abs(a_try / at - 1) < 1e-12:
                # a halved step from an ulp below the target rounds to the current point: a
                # second point at the same amplitude made the next secant inf (the unit
                # oscillator's backbone stopped so on one machine, not on another)
                a_try = at
            if len(hist) > 1:
                ap, Up, wp, xp = hist[-2]
                rho = np.log(a_try / ac) / np.log(ac / ap)
                guess = (a_try * (Uc + rho * (Uc - Up)), wc + rho * (wc - wp), xc + rho * (xc - xp))
            else:
                guess = (a_try * Uc, wc, xc)
            try:
                U, w, xi, res, it, g, nl = prob.solve(a_try, *guess)
            except ConvergenceError as err:
                if (a_try == at and near is not None and not isinstance(err, CycleNotClosed)
                        and err.residual <= NEAR_OUTPUT_RESIDUAL
                        and np.log(at / near[0]) <= (NEAR_OUTPUT + 1e-9) * np.log(at / rows[-1][0])):
                    moved.append((float(at), float(near[0])))
                    break           # ``near`` is this output's point (NEAR_OUTPUT)
                halvings += 1
                stalls = stalls + 1 if err.residual <= STALL_BELOW else 0
                if ((halvings > max_halvings or stalls >= KINK_STALLS) and not jump
                        and i + 1 < targets.size):
                    # a kink of the sampled friction law right at this output amplitude: one
                    # whole step from here to the next one (the stiff layer joint of the default
                    # model stalled at 1e-7 … 1e-6 from 0.02285 to 0.0233 and converged beyond)
                    skipped.append((float(at), float(err.residual)))
                    i, halvings, jump, stalls, near = i + 1, 0, True, 0, None
                    at = targets[i]
                    continue
                if halvings > max_halvings or jump:
                    msg = (f"nonlinear mode: no step from modal amplitude {ac:.6g} towards "
                           f"{at:.6g} after {max_halvings} halvings"
                           + (" and a step over the amplitude before it" if jump else ""))
                    if not partial or len(rows) < 2:
                        raise ConvergenceError(msg, err.residual) from err
                    stop = f"{msg} (residual reached: {err.residual:.3g})"
                continue
            hist = hist[-1:] + [(a_try, U / a_try, w, xi)]
            if a_try == at:
                near = None
                break
            near = (a_try, U, w, xi, g, res, it)
            halvings, stalls = max(halvings - 1, 0), 0
        if not stop:
            rows.append(near if near is not None else (at, U, w, xi, g, res, it))
            i += 1
    reason = stop or ("skipped modal amplitude " + ", ".join(
        f"{a:.6g} (residual reached: {r:.3g})" for a, r in skipped) if skipped else "")
    if moved and not stop:
        reason = "; ".join(x for x in (reason, "moved modal amplitude " + ", ".join(
            f"{a:.6g} to {b:.6g}" for a, b in moved)) if x)
    pts = [prob.point(a, U, w, xi, g, int(dof)) for a, U, w, xi, g, _, _ in rows]
    col = {k: np.array([p[k] for p in pts]) for k in pts[0]}
    om = np.array([r[2] for r in rows])
    xis = np.array([r[3] for r in rows])
    return Backbone(mode=prob.mode, dof=int(dof), modal_amplitude=np.array([r[0] for r in rows]),
                    mass_amplitude=col["mass_amplitude"],
                    displacement_amplitude=col["displacement_amplitude"], omega=om, xi=xis,
                    zeta=xis / (2 * om), zeta_energy=col["zeta_energy"],
                    xi_viscous=col["xi_viscous"], friction_energy=col["friction_energy"],
                    viscous_energy=col["viscous_energy"], kinetic=col["kinetic"],
                    element_status=col["element_status"], element_energy=col["element_energy"],
                    shape=col["shape"], contact=np.stack([hb.to_contact(r[1]) for r in rows]),
                    residual=np.array([r[5] for r in rows]),
                    iterations=np.array([r[6] for r in rows]),
                    linear_omega=float(np.sqrt(prob.lam_j)),
                    linear_zeta=prob.c_j / (2 * np.sqrt(prob.lam_j)), onset_amplitude=onset,
                    wall_time=time.perf_counter() - t0, complete=not stop, stop_reason=reason,
                    displacement=col["displacement"],
                    background=prob.background(int(dof)))
