"""Time-domain integration of a linear structure with 3D friction elements: an independent check
of the harmonic balance (it shares no code with ``hbm.friction``, the AFT or the receptance).

The problem is the one of :class:`hbm.HarmonicBalance` (docs/design.md, "Friction dynamics",
"Units and conventions")::

    M q'' + C q' + K q + B^T f(u, history) = F cos(w t),        u = B q = q_A - q_B,

with, per element, f = (T1, T2, N - n0): N = max(0, n0 + kn (u_n - g)); the tangential force
T = kt (u_t - w) stays in the circular Coulomb disc |T| <= mu N, the slider w moving radially when
T is on its rim; on separation (N = 0) T = 0 and the slider follows, w = u_t.

How it is integrated:

* **Linear part, exact.** The structure is written about its *linear base* (the contacts closed at
  rest stuck, K~ = K + B^T k0 B, the base of the HBM), whose modes Phi are computed once (all of
  them, dense ``eigh``). Modal damping c_i = 2 zeta omega_i on those modes (or a C that is
  diagonal in them). The excitation's steady harmonic response is exact in closed form; the rest
  of the motion obeys y'' + c y' + lam y = -Psi^T g(t), Psi = B Phi, with the contact *correction*
  g = f - k0 u taken piecewise linear in time over each step: that is integrated exactly
  (matrix exponential and phi-functions of each mode), so stiff modes cost nothing and the step
  only limits how well g(t) is resolved.
* **Contact, implicit.** The end-of-step contact displacement satisfies
  u1 = u_pred - G g(u1), G = Psi diag(c1) Psi^T; it is solved by Newton on the contact DOFs. The
  element law is :func:`friction_path_step`: the *exact* solution of the continuous law along the
  straight path u0 -> u1 (stick, then slip with the slider rotating in closed form; separation and
  closure inside the step), not a one-step return mapping. Its Jacobian is taken by finite
  differences, only on the elements that slip or change state in the step (the others have
  dg/du = 0 or a constant). Newton systems are reduced to those elements.
* **March.** From the preloaded rest state (q = 0, q' = 0, sliders 0) period after period, until
  the response over a period repeats (period-to-period change below ``rtol``). The scheme is
  second order in the step on smooth pieces (g piecewise linear in the structure, u piecewise
  linear in the law); the stick/slip/separation events inside steps make the observed order
  1.3-2.5 on the tests (a 1-DOF Jenkins oscillator: 4.1e-4 at 128 steps per period).

The energy per cycle is computed exactly per step for the contact work (closed-form integrals of
the modal solution), by 3-point Gauss quadrature of the exact intra-step solution for the input
and viscous work; at the periodic state they balance (W_in = W_visc + W_contact), which the tests
check.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg as sla

from .errors import ConvergenceError
from .structure import RIGID_TOL

STUCK, STICK_SLIP, GROSS_SLIP, PARTLY_OPEN, OPEN = 0, 1, 2, 3, 4
#: fraction of the steps spent slipping above which a closed element counts as gross slip
GROSS_SLIP_FRACTION = 0.9
#: |z| below which the phi-functions are summed as series
_PHI_SERIES = 0.5
#: Gauss-Legendre nodes per step of the energy quadrature
_GAUSS_NODES = 3


# --------------------------------------------------------------------------------------------
# Element law along a path
# --------------------------------------------------------------------------------------------
@dataclass
class PathStep:
    """End state of friction elements after a straight relative-displacement path.

    Attributes:
        T: (k, 2) tangential force at the end, N.
        N: (k,) normal force at the end, N.
        w: (k, 2) slider at the end, mm.
        slipped: (k,) the element slipped somewhere in the step.
        closed: (k,) N > 0 at the end.
    """
    T: np.ndarray
    N: np.ndarray
    w: np.ndarray
    slipped: np.ndarray
    closed: np.ndarray


def _log1p_ratio(x: np.ndarray) -> np.ndarray:
    """log(1 + x) / x, accurate near x = 0 (x > -1)."""
    small = np.abs(x) < 1e-8
    xs = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x, np.log1p(xs) / xs)


def _path_scalar(u0: list, u1: list, w0: list, kt: float, kn: float, mu: float, n0: float,
                 gap: float) -> tuple:
    """:func:`friction_path_step` for one element on Python floats (same algorithm).

    Returns:
        (T1, T2, N, w1, w2, slipped, closed): end forces (N), slider (mm) and flags."""
    a = n0 + kn * (u0[2] - gap)
    a1 = n0 + kn * (u1[2] - gap)
    if a1 <= 0.0:                                   # open at the end
        return 0.0, 0.0, 0.0, u1[0], u1[1], False, False
    b = a1 - a
    v1, v2 = u1[0] - u0[0], u1[1] - u0[1]
    if a > 0.0:
        sa, wa1, wa2, La = 0.0, w0[0], w0[1], mu * a
    else:                                           # closes at sa
        sa = min(max(a / (a - a1), 0.0), 1.0)
        wa1, wa2, La = u0[0] + sa * v1, u0[1] + sa * v2, 0.0
    Lb = mu * b
    T1 = kt * (u0[0] + sa * v1 - wa1)
    T2 = kt * (u0[1] + sa * v2 - wa2)
    nT = math.hypot(T1, T2)
    if nT > La:
        f = La / nT
        T1, T2, nT = T1 * f, T2 * f, La
    D = 1.0 - sa
    k1, k2 = kt * v1, kt * v2
    nkv = math.hypot(k1, k2)
    Tkv = T1 * k1 + T2 * k2
    c2 = nkv * nkv - Lb * Lb
    c1 = 2.0 * (Tkv - La * Lb)
    c0 = nT * nT - La * La
    tau = math.inf
    if c0 >= -1e-12 * La * La:                      # on the rim
        if (Tkv / La - Lb > 0.0) if La > 0.0 else (nkv - Lb > 0.0):
            tau = 0.0
        elif c2 > 0.0 and c1 < 0.0:
            tau = -c1 / c2
    else:
        disc = c1 * c1 - 4.0 * c2 * c0
        sq = math.sqrt(max(disc, 0.0))
        if c1 >= 0.0:
            if disc >= 0.0 and c1 + sq > 0.0:
                tau = -2.0 * c0 / (c1 + sq)
        elif c2 > 0.0:
            tau = (-c1 + sq) / (2.0 * c2)
    if not tau < D:                                 # sticks to the end
        return T1 + k1 * D, T2 + k2 * D, a1, wa1, wa2, False, True
    Ts1, Ts2 = T1 + k1 * tau, T2 + k2 * tau
    Ls = La + Lb * tau
    nTs = math.hypot(Ts1, Ts2)
    nv = math.hypot(v1, v2)
    L1 = mu * a1
    if nv > 0.0:
        h1, h2 = v1 / nv, v2 / nv
        e1, e2 = (Ts1 / nTs, Ts2 / nTs) if nTs > 0.0 else (h1, h2)
        if Ls > 0.0:
            Ds = D - tau
            x = Lb * Ds / Ls
            integral = Ds / Ls * (1.0 - 0.5 * x if abs(x) < 1e-8 else math.log1p(x) / x)
            decay = math.exp(-kt * nv * integral)
            phis = math.atan2(-e1 * h2 + e2 * h1, e1 * h1 + e2 * h2)
            phi1 = 2.0 * math.atan(math.tan(0.5 * phis) * decay)
        else:
            phi1 = 0.0
        cp, sp = math.cos(phi1), math.sin(phi1)
        e1, e2 = cp * h1 - sp * h2, cp * h2 + sp * h1
    else:
        e1, e2 = Ts1 / nTs, Ts2 / nTs
    T1, T2 = L1 * e1, L1 * e2
    return T1, T2, a1, u1[0] - T1 / kt, u1[1] - T2 / kt, True, True


#: up to this many elements (that may change state) the path law runs on Python floats
SCALAR_LIMIT = 8


def friction_path_step(u0, u1, w0, kt, kn, mu, n0, gap=0.0) -> PathStep:
    """Exact response of friction elements to a relative displacement linear in time from u0 to u1.

    Along the path s in [0, 1], u(s) = u0 + s (u1 - u0), so the Coulomb limit L = mu N(s) is
    linear in s while the element is closed. The element sticks (T = T_a + kt v s) until |T|
    reaches L (root of a quadratic), then slips: |T| = L and the direction e of T turns towards
    the path direction v, de/ds = kt (I - e e^T) v / L, whose solution is
    tan(phi/2) = tan(phi_s/2) exp(-kt |v| int ds/L) (phi the angle from v to e). Once slipping
    it slips to the end of the step (the slip condition kt e.v >= dL/ds only gets easier as e
    turns towards v). Separation inside the step ends it with T = 0, w = u_t; closure starts it
    from T = 0 at the closing instant.

    Args:
        u0, u1: (k, 3) relative displacement (t1, t2, n) at the start and the end, mm.
        w0: (k, 2) slider at the start, mm (= u_t0 for an element open at the start).
        kt, kn: (k,) or scalar element stiffnesses, N/mm (> 0).
        mu: friction coefficient(s).
        n0: preload normal force(s), N.
        gap: initial gap(s), mm.

    Returns:
        PathStep at s = 1.
    """
    u0 = np.atleast_2d(np.asarray(u0, float))
    u1 = np.atleast_2d(np.asarray(u1, float))
    w0 = np.atleast_2d(np.asarray(w0, float))
    k = u0.shape[0]
    kt, kn, mu, n0, gap = (np.broadcast_to(np.asarray(x, float), (k,)) for x in (kt, kn, mu, n0, gap))
    return _path_arrays(u0, u1, w0, kt, kn, mu, n0, gap)


def _path_arrays(u0: np.ndarray, u1: np.ndarray, w0: np.ndarray, kt: np.ndarray, kn: np.ndarray,
                 mu: np.ndarray, n0: np.ndarray, gap: np.ndarray) -> PathStep:
    """:func:`friction_path_step` on arrays of matching shapes: (k, 3), (k, 3), (k, 2), (k,)...

    A few elements go through :func:`_path_scalar`; many get a quick vectorized test (stuck
    all step, open all step) and :func:`_path_vector` for the rest."""
    k = u0.shape[0]
    if k <= SCALAR_LIMIT:
        r = [_path_scalar(*args) for args in zip(u0.tolist(), u1.tolist(), w0.tolist(), kt.tolist(),
                                                  kn.tolist(), mu.tolist(), n0.tolist(), gap.tolist())]
        a = np.array(r).reshape(k, 7)
        return PathStep(T=a[:, 0:2], N=a[:, 2], w=a[:, 3:5], slipped=a[:, 5] > 0, closed=a[:, 6] > 0)
    a = n0 + kn * (u0[:, 2] - gap)
    a1 = n0 + kn * (u1[:, 2] - gap)
    closed1 = a1 > 0.0
    # quick vectorized test: closed all step and strictly inside the disc at both ends with a
    # convex |T|^2 - L^2 (or its maximum outside the step) -> stuck; open at both ends -> open
    v = u1[:, :2] - u0[:, :2]
    Ta = kt[:, None] * (u0[:, :2] - w0)
    Te = Ta + kt[:, None] * v
    La, L1 = mu * a, mu * a1
    nTa2 = Ta[:, 0] ** 2 + Ta[:, 1] ** 2
    nTe2 = Te[:, 0] ** 2 + Te[:, 1] ** 2
    Lb = L1 - La
    kv2 = kt ** 2 * (v[:, 0] ** 2 + v[:, 1] ** 2)
    c2 = kv2 - Lb ** 2
    # f(s) = |T|^2 - L^2 = c2 s^2 + c1 s + c0: <= 0 at both ends; inside, only a concave f
    # (c2 < 0) can rise above 0, at its vertex
    c1 = 2.0 * (Ta[:, 0] * kt * v[:, 0] + Ta[:, 1] * kt * v[:, 1] - La * Lb)
    c0 = nTa2 - La ** 2
    cneg = np.where(c2 < 0.0, c2, -1.0)
    sv = -c1 / (2.0 * cneg)
    inside_ok = (c2 >= 0.0) | (sv <= 0.0) | (sv >= 1.0) | (c0 - c1 ** 2 / (4.0 * cneg) <= 0.0)
    stuck = (a > 0.0) & closed1 & (nTa2 < (1 - 1e-12) * La ** 2) & (nTe2 <= L1 ** 2) & inside_ok
    both_open = (a <= 0.0) & ~closed1
    T = np.where(stuck[:, None], Te, 0.0)
    w = np.where(stuck[:, None], w0, u1[:, :2])
    slipped = np.zeros(k, dtype=bool)
    rest = np.nonzero(~(stuck | both_open))[0]
    if rest.size:
        law = _path_arrays if rest.size <= SCALAR_LIMIT else _path_vector
        ps = law(u0[rest], u1[rest], w0[rest], kt[rest], kn[rest], mu[rest], n0[rest], gap[rest])
        T[rest], w[rest], slipped[rest] = ps.T, ps.w, ps.slipped
    return PathStep(T=T, N=np.maximum(a1, 0.0), w=w, slipped=slipped, closed=closed1)


def _path_vector(u0: np.ndarray, u1: np.ndarray, w0: np.ndarray, kt: np.ndarray, kn: np.ndarray,
                 mu: np.ndarray, n0: np.ndarray, gap: np.ndarray) -> PathStep:
    """:func:`friction_path_step` vectorized over elements (the full algorithm, no quick test)."""
    a = n0 + kn * (u0[:, 2] - gap)          # normal force (unclipped) at s = 0 and s = 1
    a1 = n0 + kn * (u1[:, 2] - gap)
    b = a1 - a
    closed0, closed1 = a > 0.0, a1 > 0.0
    ut0, ut1 = u0[:, :2], u1[:, :2]
    v = ut1 - ut0
    with np.errstate(divide="ignore", invalid="ignore"):
        # the closed interval that reaches s = 1 starts at sa (0, or the closing instant)
        sa = np.where(closed0, 0.0, np.where(closed1, a / np.where(closed1 & ~closed0, a - a1, 1.0), 1.0))
    sa = np.clip(sa, 0.0, 1.0)
    wa = np.where(closed0[:, None], w0, ut0 + sa[:, None] * v)
    La = mu * np.where(closed0, a, 0.0)
    Lb = mu * b                                               # dL/ds
    Ta = kt[:, None] * (ut0 + sa[:, None] * v - wa)
    nTa = np.hypot(Ta[:, 0], Ta[:, 1])
    over = nTa > La                                           # round-off outside the disc
    Ta = np.where(over[:, None], Ta * (La / np.where(over, nTa, 1.0))[:, None], Ta)
    nTa = np.where(over, La, nTa)
    D = 1.0 - sa
    kv = kt[:, None] * v
    nkv = np.hypot(kv[:, 0], kv[:, 1])
    Tkv = Ta[:, 0] * kv[:, 0] + Ta[:, 1] * kv[:, 1]
    # f(tau) = |Ta + kv tau|^2 - (La + Lb tau)^2 = c2 tau^2 + c1 tau + c0, c0 <= 0
    c2 = nkv ** 2 - Lb ** 2
    c1 = 2.0 * (Tkv - La * Lb)
    c0 = nTa ** 2 - La ** 2
    on_rim = c0 >= -1e-12 * La ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        slip_now = np.where(La > 0.0, Tkv / np.where(La > 0, La, 1.0) - Lb > 0.0, nkv - Lb > 0.0)
        disc = c1 ** 2 - 4.0 * c2 * c0
        sq = np.sqrt(np.maximum(disc, 0.0))
        inner = np.where(c1 >= 0.0,
                         np.where((disc >= 0.0) & (c1 + sq > 0.0), -2.0 * c0 / (c1 + sq), np.inf),
                         np.where(c2 > 0.0, (-c1 + sq) / (2.0 * c2), np.inf))
        rim = np.where(slip_now, 0.0, np.where((c2 > 0.0) & (c1 < 0.0), -c1 / c2, np.inf))
    tau = np.where(on_rim, rim, inner)
    slips = closed1 & (tau < D)
    tau = np.where(slips, tau, D)
    # stick to the end
    T1 = Ta + kv * D[:, None]
    w1 = wa.copy()
    if slips.any():
        i = np.nonzero(slips)[0]
        Ts = Ta[i] + kv[i] * tau[i, None]
        Ls = La[i] + Lb[i] * tau[i]
        nTs = np.hypot(Ts[:, 0], Ts[:, 1])
        nv = np.hypot(v[i, 0], v[i, 1])
        vh = v[i] / np.where(nv > 0, nv, 1.0)[:, None]
        es = np.where((nTs > 0)[:, None], Ts / np.where(nTs > 0, nTs, 1.0)[:, None], vh)
        L1 = mu[i] * a1[i]
        Ds = 1.0 - sa[i] - tau[i]
        moving = nv > 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            Lsafe = np.where(Ls > 0, Ls, 1.0)
            integral = Ds / Lsafe * _log1p_ratio(Lb[i] * Ds / Lsafe)          # int ds / L
            decay = np.where(Ls > 0, np.exp(-kt[i] * nv * integral), 0.0)
        vp = np.stack([-vh[:, 1], vh[:, 0]], axis=1)
        phis = np.arctan2(np.sum(es * vp, axis=1), np.sum(es * vh, axis=1))
        phi1 = 2.0 * np.arctan(np.tan(0.5 * phis) * decay)
        e1 = np.cos(phi1)[:, None] * vh + np.sin(phi1)[:, None] * vp
        e1 = np.where(moving[:, None], e1, es)
        T1[i] = L1[:, None] * e1
        w1[i] = ut1[i] - T1[i] / kt[i, None]
    # open at the end: no force, slider follows
    T1 = np.where(closed1[:, None], T1, 0.0)
    w1 = np.where(closed1[:, None], w1, ut1)
    return PathStep(T=T1, N=np.maximum(a1, 0.0), w=w1, slipped=slips, closed=closed1)


# --------------------------------------------------------------------------------------------
# Linear part: modes of the stuck base and exact step propagators
# --------------------------------------------------------------------------------------------
@dataclass
class BaseModes:
    """Modes of the linear base (the contacts closed at rest stuck).

    Attributes:
        lam: (m,) eigenvalues omega_i^2, (rad/s)^2 (rigid-body modes set to 0).
        phi: (n, m) mass-normalized mode shapes.
        damping: (m,) modal damping c_i, 1/s (0 for rigid-body modes).
        rigid: (m,) rigid-body modes.
    """
    lam: np.ndarray
    phi: np.ndarray
    damping: np.ndarray
    rigid: np.ndarray


def stuck_modal_damping(M, K, base_stiffness, C=None, damping_ratio: float | None = None,
                        rigid_tol: float = RIGID_TOL) -> BaseModes:
    """All modes of K~ = K + base_stiffness, with modal damping (the HBM's damping model).

    Args:
        M, K: (n, n) mass (t) and stiffness (N/mm).
        base_stiffness: (n, n) stiffness of the contacts stuck at rest, N/mm.
        C: optional (n, n) damping, N·s/mm; must be diagonal in the base modes.
        damping_ratio: modal damping ratio zeta of every elastic base mode (instead of C).
        rigid_tol: eigenvalues below rigid_tol · max(diag K~ / diag M) are rigid-body modes
            (``hbm.structure.RIGID_TOL``).

    Returns:
        BaseModes.
    """
    if C is not None and damping_ratio is not None:
        raise ValueError("give either C or damping_ratio, not both")
    Kb = np.asarray(K, float) + base_stiffness
    M = np.asarray(M, float)
    lam, phi = sla.eigh(0.5 * (Kb + Kb.T), 0.5 * (M + M.T))
    scale = max(np.max(np.diag(Kb) / np.diag(M)), 1e-300)
    rigid = lam < rigid_tol * scale
    lam = np.where(rigid, 0.0, lam)
    if C is not None:
        Cm = phi.T @ np.asarray(C, float) @ phi
        off = Cm - np.diag(np.diag(Cm))
        if np.abs(off).max() > 1e-8 * max(np.abs(Cm).max(), 1e-300):
            raise ValueError("C must be diagonal in the modes of the stuck base (modal damping)")
        c = np.diag(Cm).copy()
    elif damping_ratio is not None:
        if not (np.isfinite(damping_ratio) and 0.0 <= damping_ratio < 1.0):
            raise ValueError(f"damping_ratio must be in [0, 1), got {damping_ratio!r}")
        c = 2.0 * damping_ratio * np.sqrt(lam)
    else:
        c = np.zeros_like(lam)
    c = np.where(rigid & (np.abs(c) < 1e-12 * np.sqrt(scale)), 0.0, c)
    return BaseModes(lam=lam, phi=phi, damping=c, rigid=rigid & (c == 0.0))


def _phi12(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """phi1(z) = (e^z - 1)/z and phi2(z) = (e^z - 1 - z)/z^2 for complex z (series near 0)."""
    small = np.abs(z) < _PHI_SERIES
    zs = np.where(small, 1.0, z)
    ez = np.exp(zs)
    p1 = (ez - 1.0) / zs
    p2 = (ez - 1.0 - zs) / zs ** 2
    s1 = np.zeros_like(z)
    s2 = np.zeros_like(z)
    term1 = np.ones_like(z)           # z^j / (j+1)!
    term2 = 0.5 * np.ones_like(z)     # z^j / (j+2)!
    for j in range(18):
        s1 = s1 + term1
        s2 = s2 + term2
        term1 = term1 * z / (j + 2)
        term2 = term2 * z / (j + 3)
    return np.where(small, s1, p1), np.where(small, s2, p2)


def step_propagator(lam: np.ndarray, c: np.ndarray,
                    tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact map of y'' + c y' + lam y = p0 + p' t over [0, tau], per mode.

    Returns:
        (E, R1, R2): E (2, 2, m) state transition, R1 (2, m) response to p0 (tau phi1(A tau) b),
        R2 (2, m) response to the slope p' (tau^2 phi2(A tau) b): z(tau) = E z0 + R1 p0 + R2 p'.
    """
    lam = np.asarray(lam, float)
    c = np.asarray(c, float)
    m = lam.size
    E = np.zeros((2, 2, m))
    R1 = np.zeros((2, m))
    R2 = np.zeros((2, m))
    rig = (lam == 0.0) & (c == 0.0)
    # rigid body: y = y0 + tau y0' + p0 tau^2/2 + p' tau^3/6
    E[0, 0, rig] = E[1, 1, rig] = 1.0
    E[0, 1, rig] = tau
    R1[0, rig], R1[1, rig] = tau ** 2 / 2, tau
    R2[0, rig], R2[1, rig] = tau ** 3 / 6, tau ** 2 / 2
    el = ~rig
    if el.any():
        lm, cm = lam[el].astype(complex), c[el].astype(complex)
        root = np.sqrt(cm * cm - 4.0 * lm)
        mp, mm = 0.5 * (-cm + root), 0.5 * (-cm - root)
        den = mm - mp
        dp, dm = np.exp(mp * tau), np.exp(mm * tau)
        # V diag(d) V^-1 with V = [[1, 1], [mp, mm]]
        E[0, 0, el] = ((mm * dp - mp * dm) / den).real
        E[0, 1, el] = ((dm - dp) / den).real
        E[1, 0, el] = ((mp * mm * (dp - dm)) / den).real
        E[1, 1, el] = ((mm * dm - mp * dp) / den).real
        f1p, f2p = _phi12(mp * tau)
        f1m, f2m = _phi12(mm * tau)
        # f(A) b = ((f- - f+)/(m- - m+), (m- f- - m+ f+)/(m- - m+))
        R1[0, el] = (tau * (f1m - f1p) / den).real
        R1[1, el] = (tau * (mm * f1m - mp * f1p) / den).real
        R2[0, el] = (tau ** 2 * (f2m - f2p) / den).real
        R2[1, el] = (tau ** 2 * (mm * f2m - mp * f2p) / den).real
    return E, R1, R2


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
@dataclass
class TimeDomainResult:
    """Periodic steady state reached by marching from rest (arrays over the last period).

    Attributes:
        omega: excitation frequency, rad/s.
        steps_per_period: time steps per period.
        periods: periods marched (the last one is the recorded one).
        converged: period-to-period change <= rtol.
        change: (periods - 1,) period-to-period change (the largest of change_parts; inf first).
        change_parts: (periods - 2, 3) its parts: max |q - q_prev| / max |q| over the period at
            the response DOF, the same for the contact displacements u, and the sliders' change
            at the period end / max |u|.
        amplitudes: (periods,) first-harmonic amplitude at the response DOF per period, mm.
        harmonics: (2H+1,) Fourier coefficients [a0, a1, b1, ...] of the response DOF over the
            last period, mm (H = 3).
        amplitude: first-harmonic amplitude at the response DOF, mm.
        time: (N,) step-end times of the last period, s (t = 0 mod the period at the last sample).
        q: (N,) response DOF over the last period, mm.
        u: (ne, 3, N) relative displacement (t1, t2, n), mm.
        T: (ne, 2, N) tangential force, N.
        N: (ne, N) normal force, N.
        slip: (ne, N) the element slipped during the step ending at that sample.
        status: (ne,) 0 stuck, 1 stick-slip, 2 gross slip, 3 partly open, 4 open.
        mean_force: (ne, 3) cycle mean of (T1, T2, N), N.
        mean_u: (ne, 3) cycle mean of u, mm.
        joint_shear: (2,) cycle mean of (Sum T1, Sum T2), N.
        input_work: work of the excitation per cycle, N·mm.
        viscous_work: viscous dissipation per cycle, N·mm.
        friction_work: work of the contact forces on the structure per cycle, N·mm (what the
            joint dissipates; the normal springs are conservative).
        element_work: (ne,) the same per element, N·mm.
        (The three works are accumulated over the last period only.)
        mean_shear_x: (periods,) cycle mean of Sum T1 per period, N (how the mean state settles).
        newton_iterations: mean Newton iterations per step.
        seconds: wall time.
    """
    omega: float
    steps_per_period: int
    periods: int
    converged: bool
    change: np.ndarray
    change_parts: np.ndarray
    amplitudes: np.ndarray
    harmonics: np.ndarray
    amplitude: float
    time: np.ndarray
    q: np.ndarray
    u: np.ndarray
    T: np.ndarray
    N: np.ndarray
    slip: np.ndarray
    status: np.ndarray
    mean_force: np.ndarray
    mean_u: np.ndarray
    joint_shear: np.ndarray
    input_work: float
    viscous_work: float
    friction_work: float
    element_work: np.ndarray
    mean_shear_x: np.ndarray
    newton_iterations: float = 0.0
    seconds: float = 0.0

    @property
    def energy_balance(self) -> float:
        """(W_in - W_visc - W_friction) / W_in: zero at an exact periodic state."""
        return (self.input_work - self.viscous_work - self.friction_work) / max(abs(self.input_work), 1e-300)


# --------------------------------------------------------------------------------------------
# Integrator
# --------------------------------------------------------------------------------------------
def _fourier(x: np.ndarray, H: int) -> np.ndarray:
    """[a0, a1, b1, ...] of equally spaced samples x (..., N) at theta_j = 2 pi (j+1)/N."""
    N = x.shape[-1]
    th = 2 * np.pi * np.arange(1, N + 1) / N
    out = [x.mean(axis=-1)]
    for h in range(1, H + 1):
        out += [2 * np.mean(x * np.cos(h * th), axis=-1), 2 * np.mean(x * np.sin(h * th), axis=-1)]
    return np.array(out)


class FrictionTimeIntegrator:
    """M q'' + C q' + K q + B^T f_contact(q, history) = F cos(w t), marched in time (module docstring).

    Args:
        M, K: (n, n) mass (t) and stiffness (N/mm).
        dofs: (ne, 2, 3) int, DOFs of body A (row 0) and B (row 1) for (t1, t2, n); -1 = ground.
        kt, kn: element stiffnesses, N/mm (scalars or (ne,)), > 0.
        mu: friction coefficient(s), >= 0.
        n0: preload normal force(s), N, >= 0.
        gap: initial gap(s), mm.
        C: damping (n, n), N·s/mm, diagonal in the stuck-base modes; or
        damping_ratio: modal damping ratio of the stuck-base modes (the HBM's ``damping_ratio``).
        max_frequency: base modes above this frequency (rad/s) respond quasi-statically to the
            contact forces (their exact static flexibility); default None: every mode is
            integrated dynamically. The response to the excitation is the exact steady harmonic
            one of every mode either way. On a reduced FE model the pair nodes make modes up to
            MHz that only ring at the step's force kinks: a cutoff well above the highest
            harmonic of interest makes the steps cheaper and the contact history smoother.
        newton_tol: Newton tolerance on the contact displacement, relative to its size.
        max_newton: Newton iterations per step before ConvergenceError.
    """

    def __init__(self, M, K, dofs, kt, kn, mu, n0, gap=0.0, *, C=None,
                 damping_ratio: float | None = None, max_frequency: float | None = None,
                 newton_tol: float = 1e-8, max_newton: int = 30) -> None:
        M = np.asarray(M, float)
        K = np.asarray(K, float)
        n = M.shape[0]
        if M.shape != (n, n) or K.shape != (n, n):
            raise ValueError(f"M and K must be square of the same size, got {M.shape} and {K.shape}")
        d = np.asarray(dofs)
        if d.ndim != 3 or d.shape[1:] != (2, 3) or d.shape[0] < 1:
            raise ValueError(f"dofs must have shape (ne, 2, 3), got {d.shape}")
        d = d.astype(np.int64)
        if np.any(d < -1) or np.any(d >= n):
            raise ValueError(f"dofs must be in -1..{n - 1}")
        ne = d.shape[0]

        def arr(name, x, lo, strict):
            a = np.broadcast_to(np.asarray(x, float), (ne,)).copy()
            if not np.all(np.isfinite(a)) or np.any(a <= lo if strict else a < lo):
                raise ValueError(f"{name} must be finite and {'>' if strict else '>='} {lo}")
            return a

        self.kt, self.kn = arr("kt", kt, 0.0, True), arr("kn", kn, 0.0, True)
        self.mu, self.n0 = arr("mu", mu, 0.0, False), arr("n0", n0, 0.0, False)
        self.gap = np.broadcast_to(np.asarray(gap, float), (ne,)).copy()
        self.dofs, self.ne, self.n, self.nc = d, ne, n, 3 * ne
        self.newton_tol, self.max_newton = float(newton_tol), int(max_newton)
        self._par = list(zip(*(x.tolist() for x in (self.kt, self.kn, self.mu, self.n0, self.gap))))
        # the linear base: contacts closed at rest are stuck springs
        self.closed_at_rest = self.n0 - self.kn * self.gap > 0.0
        self.k0 = (np.stack([self.kt, self.kt, self.kn], axis=1)
                   * self.closed_at_rest[:, None]).ravel()                     # (nc,)
        Bd = np.zeros((self.nc, n))
        rows = np.arange(self.nc)
        for body, sign in ((0, 1.0), (1, -1.0)):
            col = d[:, body, :].ravel()
            keep = col >= 0
            Bd[rows[keep], col[keep]] += sign
        self.B = Bd
        self.M = M
        self.modes = stuck_modal_damping(M, K, Bd.T @ (self.k0[:, None] * Bd), C=C,
                                         damping_ratio=damping_ratio)
        Psi = Bd @ self.modes.phi
        Psi[:, self.modes.rigid] = 0.0          # rigid-body motion does not open or shear a pair
        self.Psi = Psi
        lam = self.modes.lam
        if max_frequency is not None and not (np.isfinite(max_frequency) and max_frequency > 0):
            raise ValueError(f"max_frequency must be > 0 rad/s, got {max_frequency!r}")
        self.dynamic = (np.ones(lam.size, dtype=bool) if max_frequency is None
                        else self.modes.rigid | (lam <= max_frequency ** 2))
        qs = ~self.dynamic
        #: static flexibility of the quasi-static modes in contact coordinates, mm/N
        self.R = (Psi[:, qs] / lam[qs]) @ Psi[:, qs].T if qs.any() else np.zeros((self.nc, self.nc))

    @classmethod
    def from_problem(cls, structure, contacts, **kw) -> "FrictionTimeIntegrator":
        """The problem of an ``hbm.LinearStructure`` and ``hbm.FrictionContacts`` (their arrays;
        keywords as in the constructor). The structure's ``n_modes`` is not used."""
        return cls(structure.M, structure.K, contacts.dofs, contacts.kt, contacts.kn, contacts.mu,
                   contacts.n0, contacts.gap, C=structure.C, damping_ratio=structure.damping_ratio, **kw)

    # ------------------------------------------------------------------ element law
    def _law(self, u0: np.ndarray, u1: np.ndarray, w0: np.ndarray,
             idx: np.ndarray | None = None) -> PathStep:
        """friction_path_step on elements idx (all if None); u0, u1 (k, 3), w0 (k, 2)."""
        if self.ne <= SCALAR_LIMIT:
            # a few elements: Python floats, no array overhead
            par = self._par if idx is None else [self._par[i] for i in idx]
            r = [_path_scalar(a, b, c, *p)
                 for a, b, c, p in zip(u0.tolist(), u1.tolist(), w0.tolist(), par)]
            a = np.array(r)
            return PathStep(T=a[:, 0:2], N=a[:, 2], w=a[:, 3:5], slipped=a[:, 5] > 0, closed=a[:, 6] > 0)
        if idx is None:
            return _path_arrays(u0, u1, w0, self.kt, self.kn, self.mu, self.n0, self.gap)
        return _path_arrays(u0, u1, w0, self.kt[idx], self.kn[idx], self.mu[idx], self.n0[idx],
                            self.gap[idx])

    def _forces(self, ps: PathStep, idx: np.ndarray | None = None) -> np.ndarray:
        """(k, 3) element force (T1, T2, N - n0) from a PathStep."""
        s = slice(None) if idx is None else idx
        return np.concatenate([ps.T, (ps.N - self.n0[s])[:, None]], axis=1)

    def _tangent(self, u0e: np.ndarray, u1e: np.ndarray, w0: np.ndarray, ps: PathStep,
                 nonlinear: np.ndarray) -> np.ndarray:
        """dg/du1 (k, 3, 3) of the nonlinear elements by forward differences."""
        i = nonlinear
        k = i.size
        if self.ne <= SCALAR_LIMIT:
            return self._tangent_scalar(u0e, u1e, w0, ps, i)
        f0 = self._forces(PathStep(ps.T[i], ps.N[i], ps.w[i], ps.slipped[i], ps.closed[i]), i)
        scale = (np.abs(u1e[i]).max(axis=1) + np.abs(u0e[i]).max(axis=1)
                 + self.mu[i] * self.n0[i] / self.kt[i] + self.n0[i] / self.kn[i] + np.abs(self.gap[i])
                 + 1e-300)
        hstep = 1e-7 * scale
        U1 = np.repeat(u1e[i][None], 3, axis=0)              # (3, k, 3)
        for j in range(3):
            U1[j, :, j] += hstep
        ii = np.tile(i, 3)
        pp = self._law(np.tile(u0e[i], (3, 1)), U1.reshape(3 * k, 3), np.tile(w0[i], (3, 1)), ii)
        fp = self._forces(pp, ii).reshape(3, k, 3)
        D = ((fp - f0[None]) / hstep[None, :, None]).transpose(1, 2, 0)       # (k, row, col)
        D -= self.k0.reshape(-1, 3)[i][:, :, None] * np.eye(3)[None]
        return D

    def _tangent_scalar(self, u0e: np.ndarray, u1e: np.ndarray, w0: np.ndarray, ps: PathStep,
                        idx: np.ndarray) -> np.ndarray:
        """:meth:`_tangent` on Python floats (a few elements)."""
        D = np.empty((idx.size, 3, 3))
        k0 = self.k0.reshape(-1, 3)
        for m, i in enumerate(idx.tolist()):
            a, b, w = u0e[i].tolist(), u1e[i].tolist(), w0[i].tolist()
            kt, kn, mu, n0, gap = self._par[i]
            h = 1e-7 * (max(map(abs, a)) + max(map(abs, b)) + mu * n0 / kt + n0 / kn + abs(gap) + 1e-300)
            f0 = (ps.T[i, 0], ps.T[i, 1], ps.N[i])
            for j in range(3):
                bp = list(b)
                bp[j] += h
                r = _path_scalar(a, bp, w, kt, kn, mu, n0, gap)
                D[m, 0, j] = (r[0] - f0[0]) / h
                D[m, 1, j] = (r[1] - f0[1]) / h
                D[m, 2, j] = (r[2] - f0[2]) / h
        D -= k0[idx][:, :, None] * np.eye(3)[None]
        return D

    def _contact_solve(self, u_pred: np.ndarray, guess: np.ndarray, u0: np.ndarray, w0: np.ndarray,
                       G: np.ndarray, closed0: np.ndarray) -> tuple:
        """Newton on u1 = u_pred - G g(u1) (closed0: elements closed at the step start); returns
        (u1, PathStep, g1, iterations)."""
        ne = self.ne
        k0 = self.k0
        u = guess.copy()
        tol = self.newton_tol * max(np.abs(u_pred).max(), np.abs(u0).max(), 1e-300)
        u0e = u0.reshape(ne, 3)

        def residual(u):
            ps = self._law(u0e, u.reshape(ne, 3), w0)
            g = self._forces(ps).ravel() - k0 * u
            return u - u_pred + G @ g, ps, g

        r, ps, g = residual(u)
        nr = np.abs(r).max()
        for it in range(1, self.max_newton + 1):
            if nr <= tol:
                return u, ps, g, it - 1
            # elements whose dg/du1 is not zero: slipping, opening, closing, or stuck but not in
            # the base (closed only now), or open but in the base
            u1e = u.reshape(ne, 3)
            stuck_closed = closed0 & ps.closed & ~ps.slipped
            both_open = ~closed0 & ~ps.closed
            lin = (stuck_closed & self.closed_at_rest) | (both_open & ~self.closed_at_rest)
            nl = np.nonzero(~lin)[0]
            if nl.size == 0:
                du = -r                      # J = I
            else:
                D = self._tangent(u0e, u1e, w0, ps, nl)
                cols = (3 * nl[:, None] + np.arange(3)).ravel()
                kk = nl.size
                # G[:, cols] times the block-diagonal element tangents
                GD = np.einsum("rkj,kjl->rkl", G[:, cols].reshape(-1, kk, 3), D).reshape(-1, 3 * kk)
                dA = np.linalg.solve(np.eye(3 * kk) + GD[cols], -r[cols])
                du = -r - GD @ dA
            alpha = 1.0
            for _ in range(12):
                ut = u + alpha * du
                rt, pst, gt = residual(ut)
                nrt = np.abs(rt).max()
                if nrt <= (1 - 1e-4 * alpha) * nr or nrt <= tol:
                    break
                alpha *= 0.5
            u, r, ps, g, nr = ut, rt, pst, gt, nrt
        if nr <= tol:
            return u, ps, g, self.max_newton
        raise ConvergenceError("time step: contact Newton did not converge", nr / max(tol, 1e-300))

    # ------------------------------------------------------------------ march
    def run(self, omega: float, force, dof: int, steps_per_period: int = 256, rtol: float = 1e-7,
            max_periods: int = 2000, min_periods: int = 3, harmonics: int = 3,
            callback: Callable[[int, float, float], None] | None = None,
            initial: tuple | None = None) -> TimeDomainResult:
        """March from the preloaded rest state to the periodic steady state.

        Args:
            omega: excitation frequency, rad/s.
            force: (n,) amplitude of force·cos(omega t), N.
            dof: response DOF.
            steps_per_period: time steps per period (the error is second order in the step).
            rtol: convergence when the period-to-period change (max over the period of the
                response DOF and of the contact displacements, relative to their largest value;
                and the sliders at the period end) falls below it.
            max_periods: periods marched at most (ConvergenceError beyond).
            min_periods: periods marched at least.
            harmonics: Fourier coefficients kept in ``TimeDomainResult.harmonics``.
            callback: called after each period with (period, change, first-harmonic amplitude).
            initial: optional start state at t = 0 instead of the preloaded rest state:
                (q0 (n,) mm, v0 (n,) mm/s, w0 (ne, 2) sliders mm), e.g. from an HBM solution, to
                see whether a periodic state is kept (quasi-static modes start on their static
                response).

        Returns:
            TimeDomainResult (its last period is marched once more after convergence, recording
            the per-element work).
        """
        t_start = time.perf_counter()
        omega = float(omega)
        if not (np.isfinite(omega) and omega > 0):
            raise ValueError(f"omega must be > 0, got {omega!r}")
        F = np.asarray(force, float)
        if F.shape != (self.n,):
            raise ValueError(f"force must have shape ({self.n},), got {F.shape}")
        Ns = int(steps_per_period)
        if Ns < 8:
            raise ValueError("steps_per_period must be >= 8")
        md = self.modes
        ne, nc = self.ne, self.nc
        dyn, qs = self.dynamic, ~self.dynamic
        # steady harmonic response of every base mode to F cos(wt): eta_h = Re(Hc e^{iwt})
        e_all = md.phi.T @ F
        Hc_all = e_all / (md.lam - omega ** 2 + 1j * omega * md.damping)
        Uh = self.Psi @ Hc_all                    # contact coordinates
        qh = md.phi[dof] @ Hc_all                 # response DOF
        eH = e_all @ Hc_all                       # e . eta_h = Re(eH e^{iwt})
        # the dynamic modes carry the rest of the motion, y = eta - eta_h
        lam, c = md.lam[dyn], md.damping[dyn]
        Psi, phid, e, Hc = self.Psi[:, dyn], md.phi[dof, dyn], e_all[dyn], Hc_all[dyn]
        # quasi-static modes: u = -R g, q_dof = -rq . g; their excitation work uses rF
        lq = np.where(qs, md.lam, 1.0)
        rq = self.Psi[:, qs] @ (md.phi[dof, qs] / lq[qs])
        rF = self.Psi[:, qs] @ (e_all[qs] / lq[qs])
        W_visc_qs = np.pi * omega * np.sum(md.damping[qs] * np.abs(Hc_all[qs]) ** 2)
        Tp = 2 * np.pi / omega
        h = Tp / Ns
        E, R1, R2 = step_propagator(lam, c, h)
        # end-of-step coefficients of p0 and p1 (p linear over the step)
        A0, A1 = R1 - R2 / h, R2 / h
        # Gauss nodes inside the step, for the input and viscous work
        xg, wg = np.polynomial.legendre.leggauss(_GAUSS_NODES)
        thg, wg = 0.5 * (xg + 1.0), 0.5 * wg
        gauss = []
        for th in thg:
            Eg, R1g, R2g = step_propagator(lam, c, th * h)
            gauss.append((Eg[1, 0], Eg[1, 1], R1g[1] - R2g[1] / h, R2g[1] / h))
        G = (Psi * A1[0]) @ Psi.T + self.R        # u1 = u_pred - G g1
        G = 0.5 * (G + G.T)
        lam_safe = np.where(lam > 0, lam, 1.0)
        # rest: q = 0, q' = 0, sliders 0 (the quasi-static modes start on their static response)
        y = -Hc.real
        yd = omega * Hc.imag
        u0 = np.zeros(nc)
        w = np.zeros((ne, 2))
        if initial is not None:
            q0, v0, w0 = (np.asarray(x, float) for x in initial)
            if q0.shape != (self.n,) or v0.shape != (self.n,) or w0.shape != (ne, 2):
                raise ValueError(f"initial must be (q0 ({self.n},), v0 ({self.n},), w0 ({ne}, 2))")
            y = y + (md.phi.T @ (self.M @ q0))[dyn]
            yd = yd + (md.phi.T @ (self.M @ v0))[dyn]
            u0 = self.B @ q0
            w = w0.copy()
        closed0 = self.n0 + self.kn * (u0.reshape(ne, 3)[:, 2] - self.gap) > 0.0
        ps0 = self._law(u0.reshape(ne, 3), u0.reshape(ne, 3), w)
        g0 = self._forces(ps0).ravel() - self.k0 * u0
        pi0 = Psi.T @ g0
        g_hist = [g0, g0, g0]
        # per period records
        q_per = np.empty(Ns)
        u_per = np.empty((Ns, nc))
        T_per = np.empty((Ns, ne, 2))
        N_per = np.empty((Ns, ne))
        slip_per = np.empty((Ns, ne), dtype=bool)
        prev_q = prev_u = prev_w = None
        changes, amps, hist_shear, parts_hist = [], [], [], []
        newton_its = 0
        steps = 0
        converged = False
        recording = False
        elem_work = np.zeros(ne)
        W_in = W_visc = 0.0
        period = 0
        while True:
            period += 1
            for j in range(Ns):
                t0 = j * h                                     # time inside the period
                t1 = t0 + h
                y_free = E[0, 0] * y + E[0, 1] * yd - A0[0] * pi0
                yd_free = E[1, 0] * y + E[1, 1] * yd - A0[1] * pi0
                e1 = np.exp(1j * omega * t1)
                u_pred = Psi @ y_free + (Uh * e1).real
                # start: the exact free response and the contact force extrapolated quadratically
                g_ext = 3 * g_hist[-1] - 3 * g_hist[-2] + g_hist[-3] if steps >= 2 else g0
                guess = u_pred - G @ g_ext
                u1, ps, g1, its = self._contact_solve(u_pred, guess, u0, w, G, closed0)
                newton_its += its
                steps += 1
                pi1 = Psi.T @ g1
                y1 = y_free - A1[0] * pi1
                yd1 = yd_free - A1[1] * pi1
                if recording:
                    # work of the contact forces, exact for g linear in t:
                    # int g.u' dt = g0.du + dg.(u1 - int u dt / h), with int y dt from the modal
                    # equations and the quasi-static part -R g
                    e0 = np.exp(1j * omega * t0)
                    Iy = np.where(lam > 0, (-0.5 * h * (pi0 + pi1) - (yd1 - yd) - c * (y1 - y))
                                  / lam_safe, 0.0)
                    Iu = Psi @ Iy + (Uh * (e1 - e0) / (1j * omega)).real - 0.5 * h * (self.R @ (g0 + g1))
                    dg = g1 - g0
                    we = g0 * (u1 - u0) + dg * (u1 - Iu / h) + 0.5 * self.k0 * (u1 ** 2 - u0 ** 2)
                    elem_work += we.reshape(ne, 3).sum(axis=1)
                    # input and viscous work: Gauss quadrature of the exact intra-step solution
                    for (th, wk, (e10, e11, r0, r1)) in zip(thg, wg, gauss):
                        tg = t0 + th * h
                        eg = np.exp(1j * omega * tg)
                        etad = e10 * y + e11 * yd - r0 * pi0 - r1 * pi1 + (1j * omega * Hc * eg).real
                        W_in += h * wk * np.cos(omega * tg) * (e @ (etad - (1j * omega * Hc * eg).real)
                                                               + (1j * omega * eH * eg).real)
                        W_visc += h * wk * np.dot(c * etad, etad)
                    W_in -= (rF @ dg) / h * (np.sin(omega * t1) - np.sin(omega * t0)) / omega
                # record
                q_per[j] = phid @ y1 + (qh * e1).real - rq @ g1
                u_per[j] = u1
                T_per[j] = ps.T
                N_per[j] = ps.N
                slip_per[j] = ps.slipped
                # advance
                y, yd, pi0, g0, u0, w = y1, yd1, pi1, g1, u1, ps.w
                closed0 = ps.closed
                g_hist = [g_hist[-2], g_hist[-1], g1]
            amps.append(float(np.hypot(*_fourier(q_per, 1)[1:3])))
            hist_shear.append(float(T_per[:, :, 0].sum(axis=1).mean()))
            if recording:
                W_visc += W_visc_qs
                break
            if prev_q is not None:
                qs_ = max(np.abs(q_per).max(), 1e-300)
                us = max(np.abs(u_per).max(), 1e-300)
                parts = (np.abs(q_per - prev_q).max() / qs_, np.abs(u_per - prev_u).max() / us,
                         np.abs(w - prev_w).max() / us)
                parts_hist.append(parts)
                ch = max(parts)
            else:
                ch = np.inf
            changes.append(ch)
            if callback is not None:
                callback(period, float(ch), amps[-1])
            prev_q, prev_u, prev_w = q_per.copy(), u_per.copy(), w.copy()
            if ch <= rtol and period >= min_periods:
                converged = True
                recording = True            # one more period, recording the work
                continue
            if period >= max_periods:
                raise ConvergenceError(f"no periodic state within {max_periods} periods "
                                       f"(last change {ch:.3g})", float(ch))
        W_fric = float(elem_work.sum())
        # last period's data
        Nt = N_per.T
        closed = Nt > 0
        frac = slip_per.T.mean(axis=1)
        status = np.full(ne, STICK_SLIP)
        status[frac >= GROSS_SLIP_FRACTION] = GROSS_SLIP
        status[~slip_per.T.any(axis=1)] = STUCK
        status[closed.any(axis=1) & ~closed.all(axis=1)] = PARTLY_OPEN
        status[~closed.any(axis=1)] = OPEN
        u = u_per.T.reshape(ne, 3, Ns)
        T = T_per.transpose(1, 2, 0)
        Hq = _fourier(q_per, harmonics)
        mean_force = np.concatenate([T.mean(axis=2), Nt.mean(axis=1)[:, None]], axis=1)
        return TimeDomainResult(
            omega=omega, steps_per_period=Ns, periods=period, converged=converged,
            change=np.array(changes), change_parts=np.array(parts_hist).reshape(-1, 3),
            amplitudes=np.array(amps), harmonics=Hq,
            amplitude=float(np.hypot(Hq[1], Hq[2])), time=h * np.arange(1, Ns + 1), q=q_per.copy(),
            u=u, T=T, N=Nt, slip=slip_per.T.copy(), status=status, mean_force=mean_force,
            mean_u=u.mean(axis=2), joint_shear=T.sum(axis=0).mean(axis=1),
            input_work=float(W_in), viscous_work=float(W_visc), friction_work=W_fric,
            element_work=elem_work.copy(), mean_shear_x=np.array(hist_shear),
            newton_iterations=newton_its / max(steps, 1), seconds=time.perf_counter() - t_start)
