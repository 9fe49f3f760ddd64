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
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
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
