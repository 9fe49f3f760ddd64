"""3D friction contact elements (two coupled Jenkins directions + normal spring), vectorized.

Each element joins a DOF triple of body A to one of body B (or ground) in its local frame
(t1, t2, n). Relative displacement u = q_A - q_B; u_n > 0 closes (DESIGN §3).

* Normal: N = max(0, n0 + kn (u_n - g)).
* Tangential: slider w (2,), trial T* = kt (u_t - w); stick if |T*| <= mu N, else radial return
  T = mu N T*/|T*| and the slider follows, w = u_t - T/kt (circular Coulomb limit, the two
  directions are coupled). Separation (N = 0) gives T = 0 and resets the slider, w = u_t.
* The force added to the structure's left-hand side is (T1, T2, N - n0) on A and the opposite on
  B, so the preloaded rest state u = 0 adds nothing.

The AFT evaluation starts each element from the rest state (w = 0, i.e. the preloaded equilibrium
with no tangential load) at t = 0, and marches the period sample by sample (elastic predictor,
radial-return corrector) until the state at t = T equals the state at t = 0 within ``close_tol``.
Elements that stay closed and within the cone all cycle with w = 0 (stuck) or open all cycle are
recognized by a vectorized test over all samples and never marched: stuck elements are exactly
linear (T = kt u_t), open ones carry the constant -n0. The analytic Jacobian of the force
harmonics is propagated through every step of the march (stick, slip projection, separation),
including the cycles before closure, so it is the exact derivative of the computed map.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ConvergenceError
from .fourier import Fourier

STUCK, STICK_SLIP, GROSS_SLIP, PARTLY_OPEN, OPEN = 0, 1, 2, 3, 4
#: fraction of the cycle spent slipping above which a closed element counts as gross slip
GROSS_SLIP_FRACTION = 0.9
#: up to this many marched elements the forward march runs on Python floats (less overhead)
SCALAR_LIMIT = 4


def _param(name: str, value, ne: int, lo: float, allow_equal: bool = True) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(ne, float(arr))
    if arr.shape != (ne,):
        raise ValueError(f"{name} must be a scalar or an array of shape ({ne},), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    bad = arr < lo if allow_equal else arr <= lo
    if np.any(bad):
        rel = ">=" if allow_equal else ">"
        raise ValueError(f"{name} must be {rel} {lo}, got min {arr.min()!r}")
    return arr


#: |det(I - A_cycle)| below which the slider fixed point is treated as neutral (plain iteration)
NEWTON_DET = 1e-6
#: cycle budget of the plain-repetition redo of neutral elements, × max_cycles
REDO_CYCLES_FACTOR = 5


def _cycle_matrix(closed, slip, rho, that):
    """Derivative of the end-of-cycle slider w.r.t. the start slider, (k, 2, 2): prod_j A_j with
    A_j = I (stick), rho (I - t t^T) (slip), 0 (open)."""
    k, nt = closed.shape
    P = np.broadcast_to(np.eye(2), (k, 2, 2)).copy()
    eye = np.eye(2)
    for j in np.nonzero(~(closed & ~slip).all(axis=0))[0]:
        t = that[:, j]
        A = np.where((closed[:, j] & ~slip[:, j])[:, None, None], eye,
                     rho[:, j, None, None] * (eye - t[:, :, None] * t[:, None, :]))
        P = A @ P
    return P


def _newton_restart(w_start, w_end, P, active):
    """Next cycle's start slider: Newton step on w = Phi(w) (the cycle map is piecewise affine in
    w with slope P), which closes 2D stick-slip cycles in a few periods instead of the slow
    geometric convergence of plain repetition. Neutral elements (det(I - P) ~ 0, e.g. sticking
    all the closing cycle) keep the plain repetition, i.e. their history from rest."""
    M = np.eye(2) - P
    det = M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] * M[:, 1, 0]
    ok = active & (np.abs(det) > NEWTON_DET)
    w = w_end.copy()
    if ok.any():
        d = (w_end - w_start)[ok]
        w[ok] = w_start[ok] + np.linalg.solve(M[ok], d[:, :, None])[:, :, 0]
    return w


#: up to this many marched elements the Jacobian recurrence uses a prefix scan
SCAN_LIMIT = 16


def _affine_scan(A, B):
    """Inclusive prefix composition of x_{i+1} = A_i x_i + B_i along axis 1 (Hillis–Steele).

    Returns (P, D) with x_{i+1} = P_i x_0 + D_i."""
    P, D = A.copy(), B.copy()
    n = A.shape[1]
    step = 1
    while step < n:
        Pn = P[:, step:] @ P[:, :-step]
        Dn = P[:, step:] @ D[:, :-step] + D[:, step:]
        P[:, step:], D[:, step:] = Pn, Dn
        step *= 2
    return P, D


class FrictionContacts:
    """A set of 3D friction elements.

    Args:
        dofs: int array (ne, 2, 3): DOF index of body A (row 0) and body B (row 1) for the
            directions t1, t2, n; -1 means ground (zero displacement).
        kt: tangential element stiffness, N/mm (scalar or (ne,)), > 0.
        kn: normal element stiffness, N/mm, > 0.
        mu: friction coefficient, >= 0.
        n0: preload normal force, N, >= 0.
        gap: initial normal gap g, mm (g > 0 open at rest); default 0.
        close_tol: relative tolerance on the slider state for cycle closure.
        max_cycles: cycles marched before declaring non-closure.
    """

    def __init__(self, dofs, kt, kn, mu, n0, gap=0.0, close_tol: float = 1e-10,
                 max_cycles: int = 200) -> None:
        d = np.asarray(dofs)
        if d.ndim != 3 or d.shape[1:] != (2, 3):
            raise ValueError(f"dofs must have shape (ne, 2, 3), got {d.shape}")
        if d.shape[0] < 1:
            raise ValueError("dofs must describe at least one element (ne >= 1)")
        if not np.issubdtype(d.dtype, np.integer):
            if not np.all(np.isfinite(d)) or np.any(d != np.round(d)):
                raise ValueError("dofs must be integers (-1 = ground)")
            d = d.astype(int)
        if np.any(d < -1):
            raise ValueError("dofs must be >= -1 (-1 = ground)")
        self.dofs = d.astype(np.int64)
        self.ne = d.shape[0]
        ne = self.ne
        # (elements without stiffness carry no force: drop them before building the contacts)
        self.kt = _param("kt", kt, ne, 0.0, allow_equal=False)
        self.kn = _param("kn", kn, ne, 0.0, allow_equal=False)
        self.mu = _param("mu", mu, ne, 0.0)
        self.n0 = _param("n0", n0, ne, 0.0)
        g = np.asarray(gap, dtype=float)
        self.gap = np.full(ne, float(g)) if g.ndim == 0 else g
        if self.gap.shape != (ne,) or not np.all(np.isfinite(self.gap)):
            raise ValueError(f"gap must be a finite scalar or array of shape ({ne},)")
        if not (0 < close_tol < 1):
            raise ValueError(f"close_tol must be in (0, 1), got {close_tol}")
        self.close_tol = float(close_tol)
        self.max_cycles = int(max_cycles)
        #: how often a neutral element kept its Newton-closed periodic state (see ``march``)
        self.neutral_kept = 0
        #: closed at rest (u = 0): these contribute their stuck stiffness to the linear base
        self.closed_at_rest = self.n0 - self.kn * self.gap > 0.0

    # ------------------------------------------------------------------ linear base
    def base_stiffness(self) -> np.ndarray:
        """Element stiffness of the linear base state, (ne, 3): (kt, kt, kn) if closed at rest, else 0."""
        k = np.stack([self.kt, self.kt, self.kn], axis=1)
        return k * self.closed_at_rest[:, None]

    def check_dofs(self, n: int) -> None:
        """Raise ValueError if a DOF index is outside 0..n-1 (or -1)."""
        if np.any(self.dofs >= n):
            raise ValueError(f"dofs must be < n = {n} (number of structure DOFs), got max {self.dofs.max()}")

    # ------------------------------------------------------------------ classification
    def _classify(self, u: np.ndarray, idx: np.ndarray):
        """Vectorized over samples: open-all and stuck-all (from rest, w = 0) masks."""
        N = self.n0[idx, None] + self.kn[idx, None] * (u[:, 2] - self.gap[idx, None])
        open_all = np.all(N <= 0.0, axis=1)
        closed_all = np.all(N > 0.0, axis=1)
        T2 = self.kt[idx, None] ** 2 * (u[:, 0] ** 2 + u[:, 1] ** 2)
        stuck_all = closed_all & np.all(T2 <= (self.mu[idx, None] * N) ** 2, axis=1)
        return open_all, stuck_all

    # ------------------------------------------------------------------ time march
    def march(self, u: np.ndarray, idx: np.ndarray, fourier: Fourier | None = None,
              jacobian: bool = False, newton: bool = True, max_cycles: int | None = None):
        """March the elements ``idx`` over periods of the sampled motion until the cycle closes.

        The forward pass only carries (k, 2) states. The Jacobian is obtained afterwards from the
        recorded per-sample linearization, which is an affine recurrence for the slider
        sensitivity, dw_{j+1} = A_j dw_j + S_j (x) E_j, with A_j = I (stick), rho (I - t t^T)
        (slip, rho = mu N / |T*|, t = T*/|T*|) or 0 (open), and dT_j = Q_j (x) E_j - kt A_j dw_j.

        Args:
            u: relative displacement samples (k, 3, nt), mm.
            idx: element indices (k,).
            fourier: needed when jacobian=True.
            jacobian: also return d(force samples)/d(harmonics).

        Returns:
            T (k, 2, nt) tangential force N, N (k, nt) normal force N, slip (k, nt) bool,
            closed (k, nt) bool, cycles marched, and when jacobian: dT (k, 2, nt, 3 nH),
            dN (k, nt, 3 nH) in the element's (direction, harmonic) layout.
        """
        k, _, nt = u.shape
        kt1 = self.kt[idx]
        kt = kt1[:, None]
        mu = self.mu[idx]
        kn = self.kn[idx]
        Nall = np.maximum(0.0, self.n0[idx, None] + kn[:, None] * (u[:, 2] - self.gap[idx, None]))
        closed = Nall > 0.0
        lim_all = mu[:, None] * Nall
        T = np.zeros((k, 2, nt))
        slip = np.zeros((k, nt), dtype=bool)
        rho = np.zeros((k, nt))
        that = np.zeros((k, nt, 2))
        scale = np.maximum(lim_all.max(axis=1), 1e-300) / kt1          # slider length scale, mm
        fwd = self._forward_scalar if k <= SCALAR_LIMIT else self._forward_vector
        n_cycles = self.max_cycles if max_cycles is None else int(max_cycles)
        cycle, err, rec, jumped = fwd(u, kt1 if k <= SCALAR_LIMIT else kt, lim_all, closed, T, slip,
                                      rho, that, scale, jacobian, newton, n_cycles)
        if err > self.close_tol:
            raise ConvergenceError(f"friction cycle did not close in {n_cycles} periods", err)
        # Elements that stick through the whole closing cycle have a neutral, history-dependent
        # slider; if a Newton restart touched their history, redo them by plain repetition from
        # rest so that state and Jacobian are those of the march from rest.
        redo = np.zeros(k, dtype=bool)
        if newton and jumped.any():
            P = _cycle_matrix(closed, slip, rho, that)
            Mf = np.eye(2) - P
            det = Mf[:, 0, 0] * Mf[:, 1, 1] - Mf[:, 0, 1] * Mf[:, 1, 0]
            redo = jumped & (np.abs(det) <= NEWTON_DET)
        if redo.any():
            # Plain repetition contracts only geometrically: rates of 0.93 per cycle and, for an
            # element that barely slips at one sample, 1 − 1e-6 were seen on the resonator. These
            # few elements get a larger budget; if even that does not close, the Newton-closed
            # state is kept: it is a periodic state too (the neutral direction only shifts the
            # slider), and its Jacobian is the plain propagation used for neutral elements.
            try:
                sub = self.march(u[redo], idx[redo], fourier, jacobian, newton=False,
                                 max_cycles=REDO_CYCLES_FACTOR * n_cycles)
            except ConvergenceError:
                redo[:] = False
                self.neutral_kept += 1
            else:
                T[redo], Nall[redo], slip[redo] = sub[0], sub[1], sub[2]
                cycle = max(cycle, sub[4])
        out = [T, Nall, slip, closed, cycle]
        if jacobian:
            if k <= SCALAR_LIMIT:
                # per element: its own number of cycles
                nx = 3 * fourier.nH
                dT, dN = np.empty((k, 2, nt, nx)), np.empty((k, nt, nx))
                for e in range(k):
                    sl_ = slice(e, e + 1)
                    cyc = [(np.array([a]), np.array([b]), np.stack([c1, c2], axis=-1)[None])
                           for a, b, c1, c2 in rec[e]]
                    dT[sl_], dN[sl_] = self._march_jacobian(cyc, closed[sl_], kt1[sl_], kn[sl_],
                                                            mu[sl_], fourier)
                out += [dT, dN]
            else:
                out += list(self._march_jacobian(rec, closed, kt1, kn, mu, fourier))
            if redo.any():
                out[5][redo], out[6][redo] = sub[5], sub[6]
        return out

    def _forward_vector(self, u, kt, lim_all, closed, T, slip, rho, that, scale, jacobian, newton,
                        max_cycles):
        """Forward march vectorized over elements (one numpy step per sample)."""
        k, _, nt = u.shape
        w = np.zeros((k, 2))
        jumped = np.zeros(k, dtype=bool)
        rec = []
        ut_all = np.ascontiguousarray(u[:, 0:2].transpose(2, 0, 1))    # (nt, k, 2)
        err = np.inf
        for cycle in range(1, max_cycles + 1):
            w_start = w.copy()
            for j in range(nt):
                ut = ut_all[j]
                Ts = kt * (ut - w)
                Tn = np.sqrt(Ts[:, 0] ** 2 + Ts[:, 1] ** 2)
                lim = lim_all[:, j]
                cj = closed[:, j]
                sl = cj & (Tn > lim)
                if sl.any():
                    r = np.where(sl, lim / np.where(sl, Tn, 1.0), 1.0)
                    rho[:, j] = np.where(sl, r, 0.0)
                    that[:, j] = Ts / np.where(sl, Tn, 1.0)[:, None]
                    Tj = Ts * (r * cj)[:, None]
                else:
                    rho[:, j] = 0.0
                    Tj = Ts * cj[:, None]
                T[:, :, j] = Tj
                slip[:, j] = sl
                stick = cj & ~sl
                w = np.where(stick[:, None], w, ut - Tj / kt)
            if jacobian:
                rec.append((slip.copy(), rho.copy(), that.copy()))
            dev = np.abs(w - w_start).max(axis=1) / scale
            err = np.max(dev) if k else 0.0
            if err <= self.close_tol:
                break
            if newton and cycle >= 2:
                # (after the plain second cycle: 1D stick-slip and transients are closed by then)
                act = dev > self.close_tol
                P = np.broadcast_to(np.eye(2), (k, 2, 2)).copy()
                P[act] = _cycle_matrix(closed[act], slip[act], rho[act], that[act])
                w_new = _newton_restart(w_start, w, P, act)
                jumped |= np.any(w_new != w, axis=1)
                w = w_new
        return cycle, err, rec, jumped

    def _forward_scalar(self, u, kt, lim_all, closed, T, slip, rho, that, scale, jacobian, newton,
                        max_cycles):
        """Forward march with Python floats, element by element (faster for a few elements)."""
        k, _, nt = u.shape
        rec = []
        jumped = np.zeros(k, dtype=bool)
        cyc_max, err_max = 1, 0.0
        ul = u[:, 0:2].tolist()
        liml, cl = lim_all.tolist(), closed.tolist()
        for e in range(k):
            k_e = float(kt[e])
            u1, u2, lim_e, c_e = ul[e][0], ul[e][1], liml[e], cl[e]
            w1 = w2 = 0.0
            Tl1, Tl2 = [0.0] * nt, [0.0] * nt
            sll, rl, t1l, t2l = [False] * nt, [0.0] * nt, [0.0] * nt, [0.0] * nt
            recs = []
            err = np.inf
            for cycle in range(1, max_cycles + 1):
                s1, s2 = w1, w2
                p11, p12, p21, p22 = 1.0, 0.0, 0.0, 1.0        # cycle matrix (product of A_j)
                for j in range(nt):
                    a, b = u1[j], u2[j]
                    if not c_e[j]:
                        Tl1[j] = Tl2[j] = 0.0
                        sll[j] = False
                        rl[j] = 0.0
                        w1, w2 = a, b
                        p11 = p12 = p21 = p22 = 0.0
                        continue
                    x, y = k_e * (a - w1), k_e * (b - w2)
                    tn = math.sqrt(x * x + y * y)
                    lim = lim_e[j]
                    if tn > lim:
                        r = lim / tn
                        sll[j] = True
                        rl[j] = r
                        e1, e2 = x / tn, y / tn
                        t1l[j], t2l[j] = e1, e2
                        # A_j = r (I - t t^T); P <- A_j P
                        a11, a12, a22 = r * (1 - e1 * e1), -r * e1 * e2, r * (1 - e2 * e2)
                        p11, p12, p21, p22 = (a11 * p11 + a12 * p21, a11 * p12 + a12 * p22,
                                              a12 * p11 + a22 * p21, a12 * p12 + a22 * p22)
                        x, y = x * r, y * r
                        w1, w2 = a - x / k_e, b - y / k_e
                    else:
                        sll[j] = False
                        rl[j] = 0.0
                    Tl1[j], Tl2[j] = x, y
                if jacobian:
                    recs.append((list(sll), list(rl), list(t1l), list(t2l)))
                err = max(abs(w1 - s1), abs(w2 - s2)) / scale[e]
                if err <= self.close_tol:
                    break
                # Newton restart on the slider fixed point w = Phi(w), Phi' = P (see _newton_restart)
                m11, m12, m21, m22 = 1 - p11, -p12, -p21, 1 - p22
                det = m11 * m22 - m12 * m21
                if newton and cycle >= 2 and abs(det) > NEWTON_DET:
                    jumped[e] = True
                    d1, d2 = w1 - s1, w2 - s2
                    w1 = s1 + (m22 * d1 - m12 * d2) / det
                    w2 = s2 + (-m21 * d1 + m11 * d2) / det
            T[e, 0], T[e, 1] = Tl1, Tl2
            slip[e], rho[e] = sll, rl
            that[e, :, 0], that[e, :, 1] = t1l, t2l
            cyc_max, err_max = max(cyc_max, cycle), max(err_max, err)
            rec.append(recs)
        return cyc_max, err_max, rec, jumped

    @staticmethod
    def _march_jacobian(rec, closed, kt, kn, mu, fourier):
        """Sensitivities of the closed cycle (see ``march``).

        In the final (closed) cycle the slider sensitivity is affine in its start value,
        dw_j = Phi_j dw_0 + d_j. The start value is that of the periodic state,
        dw_0 = (I - Phi_nt)^-1 d_nt (implicit derivative of the fixed point w = Phi(w)); for neutral
        elements (det(I - Phi_nt) ~ 0) it is the plain propagation of the history from rest.
        """
        k, nt = closed.shape
        nH = fourier.nH
        nx = 3 * nH
        E = fourier.E
        eye = np.eye(2)

        def cycle_ops(slip, rho, that, sel=slice(None)):
            cl, m, kn_, kt_ = closed[sel], mu[sel], kn[sel], kt[sel]
            stick = cl & ~slip
            P = eye - that[..., :, None] * that[..., None, :]
            A = np.where(stick[..., None, None], eye, rho[..., None, None] * P)
            c = (m[:, None, None] * slip[..., None]) * that                  # (k, nt, 2)
            cn = c * (kn_[:, None, None] * cl[..., None])                    # c_j * dN/du_n
            S = np.empty(slip.shape + (2, 3))
            S[..., 0:2] = eye - A
            S[..., 2] = -cn / kt_[:, None, None]
            active = np.nonzero(~stick.all(axis=0))[0]                       # samples where dw may change
            return A, cn, S, active

        def sources(S):
            return (S[..., None] * E[None, :, None, None, :]).reshape(S.shape[0], nt, 2, nx)

        # final cycle with dw_0 = 0: particular part d_j and homogeneous part Phi_j
        A, cn, S, active = cycle_ops(*rec[-1])
        SE = sources(S)
        d = np.zeros((k, 2, nx))
        Ph = np.broadcast_to(eye, (k, 2, 2)).copy()
        if k <= SCAN_LIMIT and active.size:
            # few elements: prefix scan of the affine maps (log2(n) vectorized steps instead of
            # one small step per sample)
            Pc, Dc = _affine_scan(A[:, active], SE[:, active])
            snaps_P = [Ph] + [Pc[:, i] for i in range(active.size)]
            snaps_d = [d] + [Dc[:, i] for i in range(active.size)]
            Ph, d = Pc[:, -1], Dc[:, -1]
        else:
            snaps_d, snaps_P = [d], [Ph]
            for j in active:
                d = A[:, j] @ d + SE[:, j]
                Ph = A[:, j] @ Ph
                snaps_d.append(d)
                snaps_P.append(Ph)
        Mfix = eye - Ph
        det = Mfix[:, 0, 0] * Mfix[:, 1, 1] - Mfix[:, 0, 1] * Mfix[:, 1, 0]
        fixed = np.abs(det) > NEWTON_DET
        dw0 = np.zeros((k, 2, nx))
        if fixed.any():
            dw0[fixed] = np.linalg.solve(Mfix[fixed], d[fixed])
        neutral = np.nonzero(~fixed)[0]
        if neutral.size and len(rec) > 1:
            # history from rest, only for the neutral elements
            dwh = np.zeros((neutral.size, 2, nx))
            for sl_c, rho_c, that_c in rec[:-1]:
                # only the neutral elements' operators (not all, then sliced)
                Ac, _, Sc, act = cycle_ops(sl_c[neutral], rho_c[neutral], that_c[neutral], neutral)
                SEc = sources(Sc)
                for j in act:
                    dwh = Ac[:, j] @ dwh + SEc[:, j]
            dw0[neutral] = dwh
        # dw seen at sample j = after the updates of the active samples before j
        which = np.searchsorted(active, np.arange(nt), side="left")
        dws = (np.stack(snaps_P, axis=1)[:, which] @ dw0[:, None]
               + np.stack(snaps_d, axis=1)[:, which])                         # (k, nt, 2, nx)
        Q = np.empty((k, nt, 2, 3))
        Q[..., 0:2] = kt[:, None, None, None] * A
        Q[..., 2] = cn
        # dT_j = Q_j (x) E_j - kt A_j dw_j
        dT = (Q[..., None] * E[None, :, None, None, :]).reshape(k, nt, 2, nx)
        dT = dT - kt[:, None, None, None] * (A @ dws)
        dT = dT.transpose(0, 2, 1, 3)
        dN = np.zeros((k, nt, 3, nH))
        dN[:, :, 2] = (kn[:, None] * closed)[..., None] * E[None]
        return dT, dN.reshape(k, nt, nx)

    # ------------------------------------------------------------------ AFT
    def evaluate(self, U: np.ndarray, fourier: Fourier, jacobian: bool = True):
        """Force harmonics and their Jacobian for relative-displacement harmonics U.

        Args:
            U: (ne, 3, nH) harmonics of u = q_A - q_B in the element frame, mm.
            fourier: the Fourier object (harmonics, samples).
            jacobian: compute the Jacobian.

        Returns:
            F: (ne, 3, nH) harmonics of (T1, T2, N - n0), N.
            nl: indices of the elements whose Jacobian differs from the linear base stiffness.
            DF: (len(nl), 3 nH, 3 nH) Jacobian dF/dU of those elements, N/mm, in the element
                layout index = direction * nH + harmonic (None when jacobian=False).
        """
        ne, nH = self.ne, fourier.nH
        if U.shape != (ne, 3, nH):
            raise ValueError(f"U must have shape ({ne}, 3, {nH}), got {U.shape}")
        u = fourier.to_time(U)                                    # (ne, 3, nt)
        allidx = np.arange(ne)
        open_all, stuck_all = self._classify(u, allidx)
        F = np.zeros((ne, 3, nH))
        # stuck all cycle (slider at rest): exactly linear
        s = stuck_all
        F[s, 0:2] = self.kt[s, None, None] * U[s, 0:2]
        F[s, 2] = self.kn[s, None] * U[s, 2]
        F[s, 2, 0] -= self.kn[s] * self.gap[s]
        # open all cycle: the structure still feels -n0
        F[open_all, 2, 0] = -self.n0[open_all]
        base = self.closed_at_rest
        lin = (stuck_all & base) | (open_all & ~base)
        marched = np.nonzero(~(open_all | stuck_all))[0]
        nl = np.nonzero(~lin)[0]
        DF = None
        if jacobian:
            DF = np.zeros((nl.size, 3 * nH, 3 * nH))
            pos = np.full(ne, -1)
            pos[nl] = np.arange(nl.size)
            # stuck elements that are not in the base (closed only under vibration): kt, kn
            sx = np.nonzero(stuck_all & ~base)[0]
            if sx.size:
                eye = np.eye(nH)
                blk = np.zeros((sx.size, 3 * nH, 3 * nH))
                for dd, kk in enumerate((self.kt[sx], self.kt[sx], self.kn[sx])):
                    blk[:, dd * nH:(dd + 1) * nH, dd * nH:(dd + 1) * nH] = kk[:, None, None] * eye
                DF[pos[sx]] = blk
        if marched.size:
            res = self.march(u[marched], marched, fourier, jacobian)
            T, Nt = res[0], res[1]
            F[marched, 0:2] = fourier.to_freq(T)
            F[marched, 2] = fourier.to_freq(Nt - self.n0[marched, None])
            if jacobian:
                dT, dN = res[5], res[6]
                D = fourier.D
                blk = np.empty((marched.size, 3 * nH, 3 * nH))
                blk[:, 0:nH] = D @ dT[:, 0]
                blk[:, nH:2 * nH] = D @ dT[:, 1]
                blk[:, 2 * nH:] = D @ dN
                DF[pos[marched]] = blk
        return F, nl, DF

    # ------------------------------------------------------------------ post-processing
    def histories(self, U: np.ndarray, fourier: Fourier):
        """Time histories over one closed period and the per-element status.

        Returns:
            dict with u_t (ne, 2, nt) mm, T (ne, 2, nt) N, N (ne, nt) N (total normal force),
            status (ne,) int, slip_fraction (ne,).
        """
        ne = self.ne
        u = fourier.to_time(U)
        allidx = np.arange(ne)
        open_all, stuck_all = self._classify(u, allidx)
        Nt = np.maximum(0.0, self.n0[:, None] + self.kn[:, None] * (u[:, 2] - self.gap[:, None]))
        T = np.zeros((ne, 2, fourier.nt))
        T[stuck_all] = self.kt[stuck_all, None, None] * u[stuck_all, 0:2]
        slip = np.zeros((ne, fourier.nt), dtype=bool)
        marched = np.nonzero(~(open_all | stuck_all))[0]
        if marched.size:
            res = self.march(u[marched], marched)
            T[marched] = res[0]
            slip[marched] = res[2]
        closed = Nt > 0
        frac = slip.mean(axis=1)
        status = np.full(ne, STICK_SLIP)
        status[frac >= GROSS_SLIP_FRACTION] = GROSS_SLIP
        status[~slip.any(axis=1)] = STUCK
        status[closed.any(axis=1) & ~closed.all(axis=1)] = PARTLY_OPEN
        status[~closed.any(axis=1)] = OPEN
        return {"u_t": u[:, 0:2].copy(), "T": T, "N": Nt, "status": status, "slip_fraction": frac}
