"""Independent references for the friction HBM (no code shared with the solver).

* ``jenkins_describing_function``: exact first harmonic and dissipated energy of the Jenkins
  element (spring kt in series with a Coulomb slider of limit fs) under x = A cos(theta).
* ``jenkins_frf_h1``: the closed-form single-harmonic (H = 1) response of the 1-DOF Jenkins
  oscillator m x'' + c x' + k x + f_J(x) = F cos(w t).
* ``jenkins_backbone_h1``: the closed-form single-harmonic nonlinear mode (EPMC backbone) of the
  same oscillator: frequency from the in-phase, damping from the dissipative describing-function
  coefficient.
* ``StickSlipIntegrator``: exact event-driven time integration of a small linear structure with
  1D Jenkins elements: within each stick/slip phase the motion is linear with harmonic forcing
  and is evaluated in closed form (eigen-decomposition of the phase's state matrix); the
  stick -> slip (|T| = fs) and slip -> stick (slip velocity = 0) events are located by bracketing
  and Brent's method; the map period -> period is iterated to the periodic steady state.
* ``circular_orbit_force``: closed-form steady force of one 3D friction element (circular
  Coulomb limit) whose tangential displacement runs on a circle at constant normal load.
* ``shakedown_slider_1d`` and ``shakedown_slider_circle``: the admissible slider nearest rest of
  an element that sticks all cycle (hbm.shakedown) for u_t = m + a cos t along a line, and on a
  circle of radius r about m, at constant limit: the ends of an interval, the centre of a disk.
* ``ramped_slider``: the slider an element is left with when its whole motion grows slowly from
  rest (a linear ramp over many periods, then held): Moreau's catching-up algorithm for the
  sweeping process of the slider by the moving stick disk, on a fine time grid.
* ``coulomb_element_reference``: fine adaptive time integration of 3D friction elements (the
  element of ``friction.py``: circular limit mu N, normal spring with separation and slider
  reset) along a prescribed periodic path, events located by root finding, steady state by
  repeating periods; harmonics by Gauss–Legendre quadrature between events.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from .errors import ConvergenceError


def jenkins_describing_function(A, kt: float, fs: float):
    """First harmonic (a1, b1) of the Jenkins force and energy per cycle under x = A cos(theta).

    Args:
        A: amplitude(s), mm (>= 0).
        kt: spring stiffness, N/mm.
        fs: slip force, N.

    Returns:
        (a1, b1, W): force = a1 cos(theta) + b1 sin(theta) + higher harmonics, N; W energy
        dissipated per cycle, N·mm. Stuck (kt A <= fs): a1 = kt A, b1 = 0, W = 0.
    """
    A = np.asarray(A, dtype=float)
    if np.any(A < 0) or kt <= 0 or fs < 0:
        raise ValueError("A must be >= 0, kt > 0, fs >= 0")
    slip = kt * A > fs
    As = np.where(slip, A, 1.0)
    cb = np.clip(1.0 - 2.0 * fs / (kt * As), -1.0, 1.0)
    beta = np.arccos(cb)
    a1 = np.where(slip, kt * As / np.pi * (beta - np.sin(beta) * cb), kt * A)
    b1 = np.where(slip, -4.0 * fs / np.pi * (1.0 - fs / (kt * As)), 0.0)
    W = np.where(slip, 4.0 * fs * (As - fs / kt), 0.0)
    return a1, b1, W


def jenkins_frf_h1(omega: float, m: float, k: float, c: float, kt: float, fs: float,
                   F: float) -> np.ndarray:
    """All first-harmonic amplitudes A of the 1-DOF Jenkins oscillator at omega (H = 1).

    Solves A |k - m w^2 + a1(A)/A + i (c w - b1(A)/A)| = F (describing function), sorted ascending.
    """
    def resid(A):
        a1, b1, _ = jenkins_describing_function(A, kt, fs)
        return A * abs(complex(k - m * omega**2 + a1 / A, c * omega - b1 / A)) - F

    roots = []
    Astick = F / abs(complex(k + kt - m * omega**2, c * omega))
    if kt * Astick <= fs:
        roots.append(Astick)
    a_lo = fs / kt
    dyn = max(abs(k - m * omega**2), c * omega, 1e-300)
    a_hi = 10.0 * (F + fs) / dyn + 10 * a_lo
    grid = a_lo * (1 + 1e-12) * np.geomspace(1.0, a_hi / a_lo, 4000)
    vals = np.array([resid(a) for a in grid])
    for i in np.nonzero(np.sign(vals[:-1]) * np.sign(vals[1:]) < 0)[0]:
        roots.append(brentq(resid, grid[i], grid[i + 1], xtol=1e-15 * grid[i + 1], rtol=1e-14))
    return np.sort(np.array(roots))


def jenkins_backbone_h1(A, m: float, k: float, c: float, kt: float, fs: float):
    """Single-harmonic (H = 1) nonlinear mode of m x'' + c x' + k x + f_J(x) = 0 (EPMC).

    With x = A cos(theta) and f_J = a1 cos + b1 sin (describing function), the balance of
    m x'' + (c - xi m) x' + k x + f_J = 0 gives, from the cos and sin terms,
    w^2 = (k + a1/A) / m and xi = c/m - b1 / (m w A) (b1 < 0 while slipping).

    Args:
        A: displacement amplitude(s), mm (> 0).
        m, k, c: mass (t), stiffness (N/mm), viscous damping (N·s/mm).
        kt, fs: Jenkins stiffness (N/mm) and slip force (N).

    Returns:
        (omega rad/s, xi 1/s, zeta = xi / (2 omega), W friction energy per cycle N·mm).
    """
    A = np.asarray(A, dtype=float)
    if np.any(A <= 0) or m <= 0:
        raise ValueError("A must be > 0 and m > 0")
    a1, b1, W = jenkins_describing_function(A, kt, fs)
    w = np.sqrt((k + a1 / A) / m)
    xi = c / m - b1 / (m * w * A)
    return w, xi, xi / (2 * w), W


class StickSlipIntegrator:
    """Exact periodic response of M q'' + C q' + K q + Sum_e b_e T_e = F cos(w t) with 1D Jenkins elements.

    Args:
        M, C, K: (n, n) matrices (K + stuck springs must be non-singular in every phase used).
        elements: list of (dof_a, dof_b, kt, fs); relative coordinate x_e = q_a - q_b (-1 = ground).
        force: (n,) amplitude, N.
        omega: rad/s.
        samples_per_period: bracketing grid for event detection.
    """

    def __init__(self, M, C, K, elements, force, omega: float, samples_per_period: int = 400):
        self.M, self.C, self.K = (np.atleast_2d(np.asarray(a, float)) for a in (M, C, K))
        self.n = self.M.shape[0]
        self.el = elements
        self.F = np.asarray(force, float).reshape(self.n)
        self.w = float(omega)
        self.T = 2 * np.pi / self.w
        self.ns = samples_per_period
        self.b = np.zeros((len(elements), self.n))
        for i, (a, bb, _, _) in enumerate(elements):
            if a >= 0:
                self.b[i, a] += 1.0
            if bb >= 0:
                self.b[i, bb] -= 1.0
        self.kt = np.array([e[2] for e in elements], float)
        self.fs = np.array([e[3] for e in elements], float)
        self.Minv = np.linalg.inv(self.M)
        self._cache = {}

    def _phase(self, stick):
        key = tuple(bool(s) for s in stick)
        if key not in self._cache:
            n = self.n
            Kp = self.K + (self.b[stick].T * self.kt[stick]) @ self.b[stick]
            A = np.zeros((2 * n, 2 * n))
            A[:n, n:] = np.eye(n)
            A[n:, :n] = -self.Minv @ Kp
            A[n:, n:] = -self.Minv @ self.C
            lam, V = sla.eig(A)
            Vinv = np.linalg.inv(V)
            Zh = np.linalg.solve(1j * self.w * np.eye(2 * n) - A,
                                 np.concatenate([np.zeros(n), self.Minv @ self.F]))
            self._cache[key] = (A, lam, V, Vinv, Zh, np.linalg.inv(A))
        return self._cache[key]

    def _segment(self, t0, z0, stick, w, s):
        """Closed-form trajectory z(t) from (t0, z0) in the phase (stick, w, s)."""
        n = self.n
        A, lam, V, Vinv, Zh, Ainv = self._phase(stick)
        f0 = -(self.b.T @ np.where(stick, -self.kt * w, s * self.fs))   # constant force on RHS
        f0v = np.concatenate([np.zeros(n), self.Minv @ f0])
        zc = -Ainv @ f0v

        def zp(t):
            return (np.outer(Zh, np.exp(1j * self.w * np.atleast_1d(t)))).real + zc[:, None]
        c = Vinv @ (z0 - zp(t0)[:, 0])

        def z(t):
            t = np.atleast_1d(t)
            return zp(t) + (V @ (c[:, None] * np.exp(np.outer(lam, t - t0)))).real
        return z

    def _events(self, z, stick, w, s):
        """Event functions (ne, nt) for state samples z (2n, nt): positive while the phase holds."""
        n = self.n
        x = self.b @ z[:n]
        v = self.b @ z[n:]
        g_st = self.fs[:, None] - np.abs(self.kt[:, None] * (x - w[:, None]))
        g_sl = s[:, None] * v
        return np.where(np.asarray(stick)[:, None], g_st, g_sl)

    def period(self, t0, z0, stick, w, s, record=False):
        """Integrate one period from t0; returns the end state and the segments if record."""
        t_end = t0 + self.T
        segs = []
        t, z_now = t0, z0.copy()
        stick, w, s = stick.copy(), w.copy(), s.copy()
        dt = self.T / self.ns
        guard = 0
        while t < t_end - 1e-14 * self.T:
            guard += 1
            if guard > 100 * self.ns:
                raise ConvergenceError("event detection stalled", float("nan"))
            traj = self._segment(t, z_now, stick, w, s)
            tt = np.minimum(t + dt * np.arange(1, self.ns + 2), t_end)
            tt = np.concatenate([[t + 1e-9 * dt], np.unique(tt)])
            gv = self._events(traj(tt), stick, w, s)
            viol = gv[:, 1:] < 0
            hit = np.nonzero(viol.any(axis=0))[0]
            if hit.size == 0:
                segs.append((t, t_end, traj))
                z_now = traj(t_end)[:, 0]
                t = t_end
                break
            j = hit[0]                    # first sample with a violated event
            lo, hi = tt[j], tt[j + 1]
            cand = []
            for e in np.nonzero(viol[:, j])[0]:
                fn = lambda tau, e=e: self._events(traj(tau), stick, w, s)[e, 0]
                te = brentq(fn, lo, hi, xtol=1e-15 * self.T, rtol=1e-15) if fn(lo) > 0 else lo
                cand.append((te, e))
            te, e = min(cand)
            segs.append((t, te, traj))
            z_now = traj(te)[:, 0]
            x = self.b @ z_now[:self.n]
            if stick[e]:                       # stick -> slip in the direction of the load
                stick[e] = False
                s[e] = np.sign(self.kt[e] * (x[e] - w[e]))
            else:                              # slip -> stick at the current slider position
                stick[e] = True
                w[e] = x[e] - s[e] * self.fs[e] / self.kt[e]
            t = te
        return z_now, stick, w, s, segs

    def steady_state(self, q0=None, v0=None, tol: float = 1e-10, max_periods: int = 3000):
        """Iterate periods from (q0, v0) (all stuck, sliders at 0) until the state repeats.

        Returns:
            dict with ``segments`` of the last period (t0, t1, z(t)), ``t0``, ``periods``.
        """
        n = self.n
        z = np.concatenate([np.zeros(n) if q0 is None else q0, np.zeros(n) if v0 is None else v0])
        ne = len(self.el)
        stick = np.ones(ne, dtype=bool)
        w, s = np.zeros(ne), np.ones(ne)
        # if the initial load exceeds the limit start slipping
        x = self.b @ z[:n]
        over = np.abs(self.kt * x) > self.fs
        stick[over] = False
        s[over] = np.sign(x[over])
        t = 0.0
        for p in range(1, max_periods + 1):
            zn, stick_n, wn, sn, segs = self.period(t, z, stick, w, s, record=True)
            scale = max(np.abs(zn[:n]).max() * (1 + self.w), 1e-300)
            err = np.abs(np.concatenate([zn[:n], zn[n:] / self.w]) -
                         np.concatenate([z[:n], z[n:] / self.w])).max() / max(np.abs(zn[:n]).max(), 1e-300)
            wd = np.abs(np.where(stick_n, wn, 0) - np.where(stick, w, 0)).max(initial=0.0)
            err = max(err, wd / max(np.abs(zn[:n]).max(), 1e-300))
            z, stick, w, s, t = zn, stick_n, wn, sn, t + self.T
            if err <= tol and p > 2:
                return {"segments": segs, "t0": t - self.T, "periods": p, "error": err}
        raise ConvergenceError(f"no periodic steady state within {max_periods} periods", err)

    def harmonics(self, ss, dof: int, H: int = 1, samples: int = 4096) -> np.ndarray:
        """Fourier coefficients [a0, a1, b1, ...] of q_dof over the steady period (time origin t0)."""
        t0 = ss["t0"]
        tt = t0 + self.T * np.arange(samples) / samples
        # each sample from the segment that contains it (a sample a rounding error before the
        # first segment's start belongs to it: every sample is set)
        starts = np.array([a for a, _, _ in ss["segments"]])
        which = np.clip(np.searchsorted(starts, tt, side="right") - 1, 0, len(starts) - 1)
        x = np.empty(samples)
        for i, (_, _, traj) in enumerate(ss["segments"]):
            msk = which == i
            if msk.any():
                x[msk] = traj(tt[msk])[dof]
        th = 2 * np.pi * np.arange(samples) / samples
        out = [x.mean()]
        for h in range(1, H + 1):
            out += [2 * np.mean(x * np.cos(h * th)), 2 * np.mean(x * np.sin(h * th))]
        return np.array(out)


def circular_orbit_force(theta, radius: float, kt: float, fs: float):
    """Steady force of one friction element whose tangential displacement runs on a circle.

    u_t = radius (cos theta, sin theta) at constant limit fs = mu N. Stuck (kt radius <= fs):
    T = kt u_t. Otherwise the element slips all the time: with T = fs e^{i psi} the direction
    obeys dpsi/dtheta = (kt radius / fs) cos(theta - psi) (the slip Riccati equation), whose
    stable steady solution is psi = theta + phi, cos phi = fs / (kt radius), 0 < phi < pi/2:
    the force leads the displacement by phi (the slider lags behind the point by
    sqrt(radius^2 - (fs/kt)^2) along the tangent), and the energy dissipated per cycle is
    2 pi fs radius sin(phi).

    Args:
        theta: phase(s), rad.
        radius: mm. kt: N/mm. fs: slip force mu N, N.

    Returns:
        (T, phi): T (2, len(theta)) force, N; phi phase lead, rad (0 when stuck).
    """
    th = np.atleast_1d(np.asarray(theta, dtype=float))
    if kt * radius <= fs:
        return kt * radius * np.stack([np.cos(th), np.sin(th)]), 0.0
    phi = float(np.arccos(fs / (kt * radius)))
    return fs * np.stack([np.cos(th + phi), np.sin(th + phi)]), phi


def shakedown_slider_1d(mean: float, amp: float, rho: float) -> float:
    """The admissible slider nearest 0 for u_t = mean + amp cos t (a line) at constant radius rho
    = mu N / kt: w must keep |u_t - w| <= rho all cycle, w in [mean + |amp| - rho, mean - |amp| +
    rho] (requires |amp| <= rho), mm."""
    lo, hi = mean + abs(amp) - rho, mean - abs(amp) + rho
    if lo > hi:
        raise ValueError("the element slips: |amp| > rho")
    return float(min(max(0.0, lo), hi))


def shakedown_slider_circle(centre: complex, r: float, rho: float) -> complex:
    """The admissible slider nearest 0 for u_t = centre + r e^{it} (a circle) at constant rho:
    the admissible set is the disk of radius rho - r about the centre (requires r <= rho), mm."""
    if r > rho:
        raise ValueError("the element slips: r > rho")
    d = abs(centre)
    return complex(0.0) if d <= rho - r else complex(centre * (1.0 - (rho - r) / d))


def ramped_slider(U: np.ndarray, kt, kn, mu, n0, gap=0.0, ramp_periods: int = 100,
                  hold_periods: int = 10, steps: int = 1000) -> np.ndarray:
    """Slider of closed friction elements after their motion r(t) u(t) grew from rest.

    r rises linearly from 0 to 1 over ``ramp_periods`` periods and stays 1 for ``hold_periods``.
    While the element is closed the stuck force kt (u_t - w) must stay in the disk of radius
    mu N: at each step w moves to the nearest point of the disk |u_t - w| <= mu N / kt (Moreau's
    catching-up algorithm; exact as the steps shrink). No separation (N > 0 is required).

    Args:
        U: (k, 3, nH) harmonics of (u_t1, u_t2, u_n) (hbm.fourier's layout: 1, cos t, sin t, ...), mm.
        kt, kn, mu, n0, gap: element parameters (scalars or (k,)).
        ramp_periods, hold_periods, steps: periods of the ramp and of the hold, steps per period.

    Returns:
        (k,) complex slider w1 + i w2 at the end, mm.
    """
    k, _, nH = U.shape
    kt, kn, mu, n0, gap = (np.broadcast_to(np.asarray(x, dtype=float), (k,)) for x in (kt, kn, mu, n0, gap))
    w = np.zeros(k, dtype=complex)
    n = (ramp_periods + hold_periods) * steps
    h = np.arange(1, (nH - 1) // 2 + 1)
    Ut = U[:, 0] + 1j * U[:, 1]
    for i in range(1, n + 1):
        t = 2.0 * np.pi * i / steps
        e = np.concatenate([[1.0], np.stack([np.cos(h * t), np.sin(h * t)], axis=1).ravel()])
        r = min(i / (ramp_periods * steps), 1.0)
        ut, un = r * (Ut @ e), r * (U[:, 2] @ e)
        N = n0 + kn * (un - gap)
        if np.any(N <= 0.0):
            raise ValueError("the element opens: ramped_slider needs N > 0 all along")
        rho = mu * N / kt
        d = w - ut
        ad = np.abs(d)
        out = ad > rho
        w[out] = ut[out] + d[out] * (rho[out] / ad[out])
    return w


class _Path:
    """A periodic path from harmonics [a0, a1, b1, ...] (rows: t1, t2, n), evaluated exactly."""

    def __init__(self, U) -> None:
        self.U = np.asarray(U, dtype=float)
        self.h = np.arange(1, (self.U.shape[-1] - 1) // 2 + 1)

    def __call__(self, th, d: int = 0):
        """d-th theta-derivative at th: (3,) or (3, n)."""
        x = np.multiply.outer(np.asarray(th, dtype=float), self.h)
        hd = self.h.astype(float) ** d
        # d/dtheta of cos(h th), sin(h th) = h cos(h th + pi/2), h sin(h th + pi/2)
        out = ((np.cos(x + d * np.pi / 2) * hd) @ self.U[:, 1::2].T
               + (np.sin(x + d * np.pi / 2) * hd) @ self.U[:, 2::2].T)
        if d == 0:
            out = out + self.U[:, 0]
        return np.moveaxis(out, -1, 0)


class _Element:
    """One element along a path: the phase functions used by the event-driven integration."""

    def __init__(self, U, kt, kn, mu, n0, gap) -> None:
        self.p = _Path(U)
        self.kt, self.kn, self.mu, self.n0, self.gap = kt, kn, mu, n0, gap

    def ut(self, th, d: int = 0):
        """d-th derivative of u_t1 + i u_t2, mm."""
        x = self.p(th, d)
        return x[0] + 1j * x[1]

    def N(self, th, d: int = 0):
        """d-th derivative of n0 + kn (u_n - g) (not clipped at 0), N."""
        x = self.p(th, d)[2]
        return self.n0 + self.kn * (x - self.gap) if d == 0 else self.kn * x

    def rate(self, th, psi):
        """Slip rate kt e.u_t' - L' (per rad) in the direction psi."""
        return self.kt * np.real(np.exp(-1j * psi) * self.ut(th, 1)) - self.mu * self.N(th, 1)


def _first_root(f, a: float, b: float, grid: float):
    """First upward zero crossing of f (vectorized in theta) in (a, b], by a grid scan of
    spacing <= grid and Brent's method."""
    n = max(2, int(np.ceil((b - a) / grid)) + 1)
    x = np.linspace(a, b, n)
    x[0] = a + 1e-12 * (b - a)            # just after the phase start (f may vanish there)
    v = f(x)
    idx = np.nonzero((v[:-1] <= 0) & (v[1:] > 0))[0]
    if not idx.size:
        return None
    i = idx[0]
    return brentq(f, x[i], x[i + 1], xtol=1e-15, rtol=1e-15)


#: rad, see the slip branch of _period
GAP = 1e-7


def _period(el: _Element, start: float, state, rtol: float, grid: float, method: str):
    """Integrate the element over [start, start + 2 pi) from state = (mode, value).

    Modes: 'open'; 'stick' (value: slider w, complex); 'slip' (value: force angle psi).
    Returns the end state and the segments [(a, b, mode, T)], T a callable theta -> complex
    force (None while open).
    """
    end = start + 2 * np.pi
    th, state, segs = start, state, []
    phase = {"open": _open_phase, "stick": _stick_phase, "slip": _slip_phase}
    while th < end - 1e-13:
        th, seg, state = phase[state[0]](el, th, end, state[1], grid, rtol, method)
        if seg is not None:
            segs.append(seg)
    return state, segs


def _open_phase(el: _Element, th, end, _, grid, rtol, method):
    """Open until N closes; then stuck with the slider there, or slipping at once along u_t'
    if the stuck force would outgrow the limit (kt |u_t'| > mu N')."""
    t1 = _first_root(lambda x: el.N(x), th, end, grid)
    seg = (th, end if t1 is None else t1, "open", None)
    if t1 is None:
        return end, seg, ("open", None)
    du = el.ut(t1, 1)
    if el.kt * abs(du) > el.mu * el.N(t1, 1):
        return t1, seg, ("slip", float(np.angle(du)))
    return t1, seg, ("stick", el.ut(t1))


def _stick_phase(el: _Element, th, end, w, grid, rtol, method):
    """Stuck at slider w until the force reaches the limit or the contact opens."""
    t_open = _first_root(lambda x: -el.N(x), th, end, grid)
    t_slip = _first_root(lambda x: np.abs(el.kt * (el.ut(x) - w)) - el.mu * el.N(x), th,
                         end if t_open is None else t_open, grid)
    t1 = min(t for t in (t_open, t_slip, end) if t is not None)
    seg = (th, t1, "stick", lambda x: el.kt * (el.ut(x) - w))
    if t1 == t_slip:
        return t1, seg, ("slip", float(np.angle(el.ut(t1) - w)))
    return t1, seg, (("open", None) if t1 == t_open else ("stick", w))


def _slip_phase(el: _Element, th, end, psi0, grid, rtol, method):
    """Slipping from direction psi0 until the slip rate vanishes (stick) or the contact opens.

    The slip equation is singular where L = 0 (its rate grows like 1/L): a slip starting at a
    closing begins GAP later along u_t', and one ending at an opening stops GAP before it. There
    T = L e^(i psi) is O(GAP), so the harmonics lose O(GAP^2).
    """
    if el.N(th) <= GAP * el.mu * el.kn:
        th = th + GAP
        psi0 = float(np.angle(el.ut(th, 1)))
    if el.rate(th, psi0) <= 0 or th >= end - GAP:     # no slip after all
        return th, None, ("stick", el.ut(th) - el.mu * max(el.N(th), 0.0) * np.exp(1j * psi0) / el.kt)

    def rhs(x, y):
        return [el.kt / (el.mu * max(el.N(x), 1e-300)) * np.imag(np.exp(-1j * y[0]) * el.ut(x, 1))]
    stop = lambda x, y: el.rate(x, y[0])
    stop.terminal, stop.direction = True, -1
    t_open = _first_root(lambda x: -el.N(x), th, end, grid)
    kw = dict(method=method, rtol=rtol, atol=rtol, max_step=16 * grid)
    # the end of the phase first, then its dense solution (solve_ivp's dense output can fail on a
    # terminal event that falls on a step boundary)
    with np.errstate(over="ignore"):                  # (solve_ivp's first-step guess, stiff start)
        first = solve_ivp(rhs, (th, end if t_open is None else t_open - GAP), [psi0], events=stop, **kw)
        if first.status < 0:
            raise ConvergenceError(f"reference slip integration failed: {first.message}", float(th))
        t1 = float(first.t[-1])
        psi = (solve_ivp(rhs, (th, t1), [psi0], dense_output=True, **kw).sol if t1 > th
               else (lambda x: np.full((1,) + np.shape(x), psi0)))
    seg = (th, t1, "slip", lambda x: el.mu * el.N(x) * np.exp(1j * psi(x)[0]))
    if first.status == 1:
        return t1, seg, ("stick", el.ut(t1) - el.mu * el.N(t1) * np.exp(1j * float(psi(t1)[0])) / el.kt)
    if t_open is not None:
        return t_open, seg, ("open", None)
    return t1, seg, ("slip", float(psi(t1)[0]))


def coulomb_element_reference(U, kt, kn, mu, n0, gap=0.0, theta=None, harmonics=None,
                              rtol: float = 1e-11, tol: float = 1e-11, max_periods: int = 400,
                              method: str = "DOP853"):
    """Steady periodic forces of 3D friction elements along prescribed periodic paths.

    The element is that of ``hbm.friction``: N = max(0, n0 + kn (u_n - g)); the tangential force
    T = kt (u_t - w) stays in the circle |T| <= L = mu N; while slipping T = L e^{i psi} with
    dpsi/dtheta = (kt / L) Im(e^{-i psi} u_t') (complex u_t = u_t1 + i u_t2), until the slip rate
    kt Re(e^{-i psi} u_t') - L' falls to zero (stick at the current slider) or N to zero (open:
    T = 0, slider reset). At closing the element sticks with the slider there, or slips at once
    along u_t' if kt |u_t'| > L'. Integration (independent of the AFT): stick and open phases are
    explicit, their ends located by a grid scan and Brent's method; slip phases by Radau with
    event location. Periods are repeated from rest (w = 0 at theta = 0) until the state at
    theta = 0 repeats within tol; the last period's force harmonics are integrated by
    Gauss–Legendre quadrature between the events (spectrally accurate).

    Args:
        U: (ne, 3, 2H+1) or (3, 2H+1) harmonics [a0, a1, b1, ...] of (u_t1, u_t2, u_n), mm, with
            theta = omega t the phase.
        kt, kn, mu, n0, gap: element parameters (scalars or (ne,)), N/mm, -, N, mm.
        theta: optional phases (rad) at which to return the force samples.
        harmonics: highest harmonic of the returned force (default: that of U).
        rtol: relative tolerance of the slip integration. tol: periodicity tolerance (relative
            to mu max N / kt). method: scipy's solve_ivp method for the slip phases (DOP853 and
            Radau agree to 1e-13 on the hbm tests).

    Returns:
        dict with F (ne, 3, 2H'+1) harmonics of (T1, T2, N - n0), N; T (ne, 2, len(theta)) and
        N (ne, len(theta)) samples when theta is given; periods (ne,) periods integrated.
    """
    U = np.asarray(U, dtype=float)
    single = U.ndim == 2
    U = U[None] if single else U
    ne, _, nh = U.shape
    H = (nh - 1) // 2 if harmonics is None else int(harmonics)
    par = [np.broadcast_to(np.asarray(v, dtype=float), (ne,)) for v in (kt, kn, mu, n0, gap)]
    F = np.zeros((ne, 3, 2 * H + 1))
    th = None if theta is None else np.mod(np.atleast_1d(np.asarray(theta, dtype=float)), 2 * np.pi)
    Ts = None if theta is None else np.zeros((ne, 2, th.size))
    Ns = None if theta is None else np.zeros((ne, th.size))
    periods = np.zeros(ne, dtype=int)
    for e in range(ne):
        el = _Element(U[e], *(float(v[e]) for v in par))
        segs, periods[e] = _steady(el, rtol, tol, max_periods, method)
        F[e] = _harmonics(el, segs, H)
        if theta is not None:
            for a, b, mode, fn in segs:
                m = (th >= a) & (th < b)
                if m.any() and fn is not None:
                    T = fn(th[m])
                    Ts[e, 0, m], Ts[e, 1, m] = T.real, T.imag
            Ns[e] = np.maximum(0.0, el.N(th))
    out = {"F": F[0] if single else F, "periods": periods}
    if theta is not None:
        out["T"], out["N"] = (Ts[0], Ns[0]) if single else (Ts, Ns)
    return out


def _steady(el: _Element, rtol: float, tol: float, max_periods: int, method: str):
    """Periods from rest (w = 0 at theta = 0) until the state at theta = 0 repeats within tol.

    Returns the last period's segments and the number of periods."""
    grid = 2 * np.pi / 2048
    scale = max(el.mu * max(el.N(np.linspace(0, 2 * np.pi, 512)).max(), 0.0) / el.kt, 1e-300)
    state = ("stick", 0j) if el.N(0.0) > 0 else ("open", None)
    if state[0] == "stick" and abs(el.kt * el.ut(0.0)) > el.mu * el.N(0.0):
        state = ("slip", float(np.angle(el.ut(0.0))))
    d = np.inf
    for p in range(1, max_periods + 1):
        new, segs = _period(el, 0.0, state, rtol, grid, method)
        if new[0] == state[0]:
            if new[0] == "open":
                d = 0.0
            elif new[0] == "stick":
                d = abs(new[1] - state[1]) / scale
            else:
                d = abs(np.angle(np.exp(1j * (new[1] - state[1]))))
            if d <= tol and p > 1:
                return segs, p
        state = new
    raise ConvergenceError(f"reference element: no periodic state in {max_periods} periods", d)


def _harmonics(el: _Element, segs, H: int) -> np.ndarray:
    """(3, 2H+1) harmonics of (T1, T2, N - n0) over one period from the phase segments:
    12-point Gauss–Legendre on pieces of at most 2 pi / 128 of each smooth segment."""
    xg, wg = np.polynomial.legendre.leggauss(12)
    out = np.zeros((3, 2 * H + 1))
    h = np.arange(1, H + 1)
    for a, b, mode, fn in segs:
        if b <= a or mode == "open":
            continue
        n = max(1, int(np.ceil((b - a) / (2 * np.pi / 128))))
        edges = np.linspace(a, b, n + 1)
        x = (0.5 * (edges[:-1, None] + edges[1:, None]) + 0.5 * np.diff(edges)[:, None] * xg).ravel()
        wx = (0.5 * np.diff(edges)[:, None] * wg).ravel()
        T = fn(x)
        vals = np.stack([T.real, T.imag, el.N(x)])                       # (3, m)
        c, s = np.cos(np.outer(h, x)), np.sin(np.outer(h, x))
        out[:, 0] += vals @ wx / (2 * np.pi)
        out[:, 1::2] += (vals * wx) @ c.T / np.pi
        out[:, 2::2] += (vals * wx) @ s.T / np.pi
    out[2, 0] -= el.n0
    return out


def elliptic_orbits_with_separation(H: int = 2) -> np.ndarray:
    """Relative-displacement harmonics (6, 3, 2H + 1), mm, of six elements: tangential ellipses
    of various axes, tilts and phases (plus a 2nd harmonic), and a normal oscillation that opens
    the contact for part of the cycle: the 2D-slip-with-separation case of the AFT's tests and
    benchmark (scripts/bench_aft2d.py), with coulomb_element_reference as its reference."""
    rows = [(0.10, 0.05, 0.3, 0.0, 0.015, 0.4, 0.01), (0.08, 0.02, -0.7, 1.0, 0.012, 2.0, 0.0),
            (0.05, 0.04, 1.2, 2.0, 0.020, -1.0, 0.005), (0.12, 0.01, 0.0, -0.5, 0.011, 0.0, 0.02),
            (0.03, 0.025, 0.5, 0.7, 0.013, 3.0, 0.0), (0.20, 0.15, -0.2, 1.5, 0.016, 1.0, 0.01)]
    U = np.zeros((len(rows), 3, 2 * H + 1))
    for e, (a, b, tilt, ph, an, phn, h2) in enumerate(rows):
        rot = np.array([[np.cos(tilt), -np.sin(tilt)], [np.sin(tilt), np.cos(tilt)]])
        # (a cos(th + ph), b sin(th + ph)) on (cos th, sin th), then tilted
        U[e, 0:2, 1:3] = rot @ np.array([[a * np.cos(ph), -a * np.sin(ph)],
                                         [b * np.sin(ph), b * np.cos(ph)]])
        U[e, 0, 3] = h2
        U[e, 2, 1:3] = an * np.cos(phn), an * np.sin(phn)
    return U
