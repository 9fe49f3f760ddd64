"""Contact stiffness extraction: normal k_n and tangential k_t per unit area (N/mm³).

* Normal: k_n = (dN/dδ)/A at the given load. The tangent of the load–approach curve of an elastic
  contact equals the stiffness of a rigid flat punch with the current contact area (Barber 2003),
  so dN/dδ is computed exactly by one linear CG solve K_c x = 1 on the contact set (no finite
  differences of the nonlinear curve; ``load_approach_curve`` gives the curve for checking).
* Tangential: at a load reversal every cell sticks again, so the slope of the hysteresis loop at the
  reversal (paper Fig. 4; Mindlin–Deresiewicz) is the stiffness of the fully stuck contact area, again
  one linear solve K_t,c q = e on the contact set (2 right-hand sides give the 2×2 matrix). The
  secant stiffness 2Q/(δ(+Q) − δ(−Q)) of the loop ±Q needs the partial-slip solution and depends on Q.
* ``mindlin_ratio(ν) = 2(1-ν)/(2-ν)`` is the cheap k_t/k_n of a Hertz contact.
* ``patch_normal_stiffness`` / ``patch_tangential_stiffness`` solve many small patches at once, batched
  along the leading axis (one FFT call for all patches per CG iteration).

A is the patch (grid or mask) area, so k·A is the element stiffness.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .errors import ConvergenceError, finite_array, positive_scalar
from .grid import Grid
from .halfspace import ElasticHalfSpace
from .normal import NormalSolution, capped_load_control, pk_normal_batch, solve_normal
from .tangential import pk_tangential_compacting, solve_tangential

_AX = (-2, -1)


def mindlin_ratio(poisson: float) -> float:
    """Mindlin tangential/normal stiffness ratio k_t/k_n = 2(1-ν)/(2-ν) (two identical bodies)."""
    nu = float(poisson)
    if not (np.isfinite(nu) and 0.0 <= nu < 0.5):
        raise ValueError(f"poisson: must be in [0, 0.5), got {poisson!r}")
    return 2.0 * (1.0 - nu) / (2.0 - nu)


def restricted_cg(apply_k, rhs: np.ndarray, support: np.ndarray, *, tol: float = 1e-10,
                  max_iter: int = 2000) -> np.ndarray:
    """Batched CG for K x = rhs restricted to ``support`` (x = 0 elsewhere).

    Args:
        apply_k: callable on arrays shaped like ``rhs`` (symmetric positive definite operator).
        rhs: (B, ..., nx, ny) right-hand sides.
        support: bool array broadcastable to rhs (the contact set).
        tol: relative residual ‖r‖/‖rhs‖ to reach.
        max_iter: iteration cap (ConvergenceError beyond).

    Returns:
        x shaped like rhs.
    """
    B = rhs.shape[0]
    red = tuple(range(1, rhs.ndim))
    sup = np.broadcast_to(support, rhs.shape)
    x = np.zeros_like(rhs)
    r = np.where(sup, rhs, 0.0)
    p = r.copy()
    rs = (r * r).sum(axis=red)
    rs0 = np.where(rs > 0, rs, 1.0)
    shape = (B,) + (1,) * (rhs.ndim - 1)
    for it in range(max_iter):
        rel = np.sqrt(rs / rs0)
        if np.all(rel < tol):
            return x
        Ap = np.where(sup, apply_k(p), 0.0)
        pAp = (p * Ap).sum(axis=red)
        alpha = np.where(pAp > 0, rs / np.where(pAp > 0, pAp, 1.0), 0.0)
        x += alpha.reshape(shape) * p
        r -= alpha.reshape(shape) * Ap
        rs_new = (r * r).sum(axis=red)
        p = r + (rs_new / np.where(rs > 0, rs, 1.0)).reshape(shape) * p
        rs = rs_new
    raise ConvergenceError("restricted_cg: linear stiffness solve not converged",
                           float(np.max(np.sqrt(rs / rs0))), max_iter)


@dataclass
class NormalStiffness:
    """Normal contact stiffness at one load.

    Attributes:
        k_n: (dN/dδ)/A in N/mm³.
        dn_ddelta: dN/dδ in N/mm.
        area: reference area A in mm² (allowed area of the grid).
        solution: the NormalSolution at the load.
    """

    k_n: float
    dn_ddelta: float
    area: float
    solution: NormalSolution


def _normal_tangent(hs: ElasticHalfSpace, contact: np.ndarray, tol: float) -> np.ndarray:
    """dN/dδ (B,) of contact sets (B, nx, ny) by a restricted CG (rigid flat punch of that shape)."""
    x = restricted_cg(hs._apply_normal, np.ones(contact.shape), contact, tol=tol)
    return x.sum(axis=_AX) * hs.grid.cell_area


def normal_stiffness(hs: ElasticHalfSpace, gap, load: float, *, mask=None, tol: float = 1e-8,
                     solution: NormalSolution | None = None) -> NormalStiffness:
    """Normal contact stiffness k_n = (dN/dδ)/A at total load ``load``.

    Args:
        hs: half-space operator.
        gap: (nx, ny) initial separation (mm), as for ``solve_normal``.
        load: normal load N (≥ 0; 0 gives k_n = 0).
        mask: optional (nx, ny) bool contact mask; A is its area.
        tol: tolerance of the normal solve (the linear tangent solve uses tol·1e-2).
        solution: reuse an existing NormalSolution at this load instead of solving.

    Returns:
        NormalStiffness.
    """
    ns = solution if solution is not None else solve_normal(hs, gap, load=load, mask=mask, tol=tol)
    area = float(ns.mask.sum() * hs.grid.cell_area)
    if not ns.contact.any():
        return NormalStiffness(0.0, 0.0, area, ns)
    k = float(_normal_tangent(hs, ns.contact[None], min(tol * 1e-2, 1e-10))[0])
    return NormalStiffness(k / area, k, area, ns)


def load_approach_curve(hs: ElasticHalfSpace, gap, loads, *, mask=None, tol: float = 1e-10) -> np.ndarray:
    """Rigid approach δ (mm) at each load (N), warm-started along the list."""
    L = finite_array("loads", loads, (None,))
    out = np.empty(L.size)
    p = None
    for i, W in enumerate(L):
        ns = solve_normal(hs, gap, load=W, mask=mask, tol=tol, initial_pressure=p)
        p = ns.pressure
        out[i] = ns.approach
    return out


@dataclass
class TangentialStiffness:
    """Tangential contact stiffness.

    Attributes:
        k_t: slope at load reversal per area, N/mm³ (stuck contact area, along ``direction``).
        matrix: (2, 2) stuck tangential stiffness matrix (N/mm), F = matrix @ δ.
        direction: (2,) unit direction of the load.
        area: reference area (mm²).
        k_t_secant: secant 2|Q|/(δ(+Q) − δ(−Q)) / A of the loop ±Q (N/mm³), nan if not computed.
    """

    k_t: float
    matrix: np.ndarray
    direction: np.ndarray
    area: float
    k_t_secant: float = float("nan")


def _stuck_matrix(hs: ElasticHalfSpace, contact: np.ndarray, tol: float) -> np.ndarray:
    """(B, 2, 2) stuck tangential stiffness matrices (N/mm) of contact sets (B, nx, ny)."""
    B = contact.shape[0]
    rhs = np.zeros((B, 2, 2) + contact.shape[1:])
    rhs[:, 0, 0] = 1.0
    rhs[:, 1, 1] = 1.0
    sup = np.repeat(contact[:, None, None], 2, axis=1).reshape((2 * B, 1) + contact.shape[1:])
    x = restricted_cg(hs._apply_tangential, rhs.reshape((2 * B, 2) + contact.shape[1:]), sup, tol=tol)
    F = x.reshape((B, 2, 2) + contact.shape[1:]).sum(axis=_AX) * hs.grid.cell_area  # [b, load case, comp]
    return np.swapaxes(F, 1, 2)                                                      # [b, comp, case]


def _along(matrix: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Stiffness along unit e under force control: 1/(eᵀ K⁻¹ e); 0 for a singular (empty) K."""
    det = matrix[:, 0, 0] * matrix[:, 1, 1] - matrix[:, 0, 1] * matrix[:, 1, 0]
    ok = det > 0
    d = np.where(ok, det, 1.0)
    c00, c11 = matrix[:, 1, 1] / d, matrix[:, 0, 0] / d
    c01, c10 = -matrix[:, 0, 1] / d, -matrix[:, 1, 0] / d
    comp = e[:, 0] ** 2 * c00 + e[:, 0] * e[:, 1] * (c01 + c10) + e[:, 1] ** 2 * c11
    return np.where(ok & (comp > 0), 1.0 / np.where(comp > 0, comp, 1.0), 0.0)


def _unit_dir(q: np.ndarray) -> np.ndarray:
    n = np.hypot(q[:, 0], q[:, 1])
    e = np.zeros_like(q)
    e[:, 0] = 1.0
    return np.where((n > 0)[:, None], q / np.where(n > 0, n, 1.0)[:, None], e)


def tangential_stiffness(hs: ElasticHalfSpace, ns: NormalSolution, mu: float | None = None,
                         amplitude=None, *, tol: float = 1e-6) -> TangentialStiffness:
    """Tangential stiffness: slope at load reversal (stuck contact) and optionally the loop secant.

    Args:
        hs: half-space operator. ns: normal solution (fixed pressure).
        mu: friction coefficient, needed only for the secant.
        amplitude: (Q_x, Q_y) tangential force amplitude (N) of the cycle ±Q; gives the direction of
            the stiffness (default x) and, with mu, the secant value.
        tol: tolerance of the partial-slip solves.

    Returns:
        TangentialStiffness.
    """
    area = float(ns.mask.sum() * hs.grid.cell_area)
    Q = np.zeros(2) if amplitude is None else finite_array("amplitude", amplitude, (2,))
    e = _unit_dir(Q[None])[0]
    if not ns.contact.any():
        return TangentialStiffness(0.0, np.zeros((2, 2)), e, area, 0.0)
    K = _stuck_matrix(hs, ns.contact[None], 1e-10)[0]
    k = float(_along(K[None], e[None])[0])
    sec = float("nan")
    if mu is not None and amplitude is not None and np.hypot(*Q) > 0:
        st = solve_tangential(hs, ns, mu, [Q, -Q], tol=tol)
        sec = 2.0 * np.hypot(*Q) / float(e @ (st[0].shift - st[1].shift)) / area
    return TangentialStiffness(k / area, K, e, area, sec)


@dataclass
class TangentialLoop:
    """Hysteresis loop under the tangential force cycle 0 → +Q → −Q → +Q.

    Attributes:
        force: (m, 2) total tangential force per step (N), starting at 0.
        shift: (m, 2) rigid tangential displacement per step (mm).
        states: the TangentialState of each step (the first, virgin state excluded).
        energy: energy dissipated over the closed cycle +Q → −Q → +Q (N·mm), trapezoidal ∮ Q·dδ.
        k_t: exact slope at reversal per area (stuck contact) in N/mm³.
        k_t_first_step: slope of the first unloading increment per area (what a discrete loop shows).
        k_t_secant: 2|Q|/(δ(+Q) − δ(−Q)) per area (N/mm³).
        stick_fraction: (m,) stuck fraction of the loaded area per step.
    """

    force: np.ndarray
    shift: np.ndarray
    states: list
    energy: float
    k_t: float
    k_t_first_step: float
    k_t_secant: float
    stick_fraction: np.ndarray


def tangential_loop(hs: ElasticHalfSpace, ns: NormalSolution, mu: float, amplitude, *,
                    n_steps: int = 8, tol: float = 1e-6) -> TangentialLoop:
    """Quasi-static hysteresis loop 0 → +Q → −Q → +Q at fixed normal pressure.

    Args:
        hs, ns: half-space and normal solution.
        mu: friction coefficient.
        amplitude: (Q_x, Q_y) in N, |Q| < μP.
        n_steps: increments per quarter cycle (≥ 1); the half branches use 2·n_steps.
        tol: tolerance of the partial-slip solves.

    Returns:
        TangentialLoop.
    """
    Q = finite_array("amplitude", amplitude, (2,))
    n = int(n_steps)
    if n < 1:
        raise ValueError(f"n_steps: must be >= 1, got {n_steps!r}")
    s = np.concatenate([np.linspace(0, 1, n + 1)[1:], np.linspace(1, -1, 2 * n + 1)[1:],
                        np.linspace(-1, 1, 2 * n + 1)[1:]])
    path = s[:, None] * Q[None]
    states = solve_tangential(hs, ns, mu, path, tol=tol)
    force = np.vstack([np.zeros(2), path])
    shift = np.vstack([np.zeros(2), [st.shift for st in states]])
    area = float(ns.mask.sum() * hs.grid.cell_area)
    e = _unit_dir(Q[None])[0]
    fc = force[n:] @ e
    dc = shift[n:] @ e
    energy = float(np.sum(0.5 * (fc[1:] + fc[:-1]) * np.diff(dc)))
    ts = tangential_stiffness(hs, ns, None, Q)
    d_first = (shift[n + 1] - shift[n]) @ e
    f_first = (force[n + 1] - force[n]) @ e
    k_first = float(f_first / d_first / area) if d_first != 0 else float("nan")
    sec = 2.0 * np.hypot(*Q) / float((shift[n] - shift[3 * n]) @ e) / area
    return TangentialLoop(force, shift, states, abs(energy), ts.k_t, k_first, sec,
                          np.array([st.stick_fraction for st in states]))


# ---------------------------------------------------------------------------- batched patches
@lru_cache(maxsize=8)
def _patch_halfspace(shape: tuple[int, int], cell_size: tuple[float, float], young: float, poisson: float,
                     periodic: bool, threads: int) -> ElasticHalfSpace:
    grid = Grid(shape, (shape[0] * cell_size[0], shape[1] * cell_size[1]))
    return ElasticHalfSpace(grid, young, poisson, periodic=periodic, threads=threads)


def _check_patches(patches, cell_size, young, poisson, loads):
    z = finite_array("patches", patches)
    if z.ndim != 3 or z.shape[1] < 2 or z.shape[2] < 2:
        raise ValueError(f"patches: expected shape (np, n, n) with n >= 2, got {z.shape}")
    try:
        dx, dy = (positive_scalar("cell_size", c) for c in cell_size)
    except TypeError:
        raise ValueError(f"cell_size: expected (dx, dy) in mm, got {cell_size!r}") from None
    positive_scalar("young", young)
    if not (0.0 <= float(poisson) < 0.5):
        raise ValueError(f"poisson: must be in [0, 0.5), got {poisson!r}")
    W = finite_array("loads", loads, (z.shape[0],))
    if np.any(W < 0):
        raise ValueError("loads: must be >= 0 N (0 gives k = 0)")
    return z, (float(dx), float(dy)), W


def _patch_normal(z, cell, young, poisson, W, periodic, threads, tol, hardness=None):
    hs = _patch_halfspace(z.shape[1:], cell, float(young), float(poisson), bool(periodic), int(threads))
    h = z.max(axis=_AX, keepdims=True) - z
    if hardness is not None:
        H = positive_scalar("hardness", hardness)
        if np.any(W >= H * hs.grid.area):
            raise ValueError(f"loads: must be below hardness × patch area = {H * hs.grid.area:.6g} N")
        p, _ = capped_load_control(hs._apply_normal, h, np.ones(h.shape, bool), hs.grid.cell_area,
                                   W, H, tol)
        return hs, p
    res = pk_normal_batch(hs._apply_normal, h, np.ones(z.shape, bool), hs.grid.cell_area, load=W, tol=tol)
    return hs, res["pressure"]


def patch_normal_stiffness(patches, cell_size, young: float, poisson: float, loads, *,
                           periodic: bool = False, threads: int = 1, tol: float = 1e-8,
                           return_pressure: bool = False, hardness: float | None = None):
    """Normal contact stiffness of many rough patches at once (batched along the first axis).

    Each patch (heights z, rough face against a flat) is pressed with its load; k_n = (dN/dδ)/A with
    A the patch area, dN/dδ the stuck-set tangent (see module docstring).

    With ``hardness`` the pressure is capped at H (perfectly plastic asperities, as in
    ``solve_normal``) and k_n is the *unloading* tangent of the whole contact set, capped cells
    included: after the first (plastic) loading by the bolt, the flattened asperities unload and
    reload elastically, which is what a vibration cycle does.

    Args:
        patches: (np, n, m) heights in mm.
        cell_size: (dx, dy) mm.
        young, poisson: E (MPa) and ν of both bodies.
        loads: (np,) normal loads N (≤ 0 → k_n = 0).
        periodic: periodic patches (default non-periodic DC-FFT).
        threads: FFTW threads.
        tol: tolerance of the normal solves.
        return_pressure: also return the (np, n, m) pressures.
        hardness: optional pressure cap H in MPa (each load must stay below H × patch area).

    Returns:
        k_n (np,) in N/mm³ [, pressures].
    """
    z, cell, W = _check_patches(patches, cell_size, young, poisson, loads)
    hs, p = _patch_normal(z, cell, young, poisson, W, periodic, threads, tol, hardness)
    k = _patch_kn(hs, p)
    return (k, p) if return_pressure else k


def _patch_kn(hs: ElasticHalfSpace, p: np.ndarray) -> np.ndarray:
    """k_n (np,) N/mm³ of solved patches with pressures p (np, n, m); 0 without contact."""
    contact = p > 0
    k = np.zeros(p.shape[0])
    has = contact.any(axis=_AX)
    if has.any():
        k[has] = _normal_tangent(hs, contact[has], 1e-10)
    return k / hs.grid.area


def patch_tangential_stiffness(patches, cell_size, young: float, poisson: float, mu: float, loads,
                               q_amplitudes, *, periodic: bool = False, threads: int = 1,
                               tol: float = 1e-8, tangential_tol: float = 1e-6, secant: bool = True,
                               max_ratio: float = 0.99):
    """Tangential contact stiffness of many rough patches at once.

    k_t is the slope of the hysteresis loop at load reversal under the cycle ±Q at the patch's normal
    load (the stuck-contact stiffness along Q, per patch area); with ``secant=True`` also the loop
    secant 2|Q|/(δ(+Q) − δ(−Q))/A from two batched partial-slip increments 0 → +Q → −Q.

    Args:
        patches: (np, n, m) heights (mm). cell_size: (dx, dy) mm. young, poisson: E (MPa), ν.
        mu: friction coefficient (> 0).
        loads: (np,) normal loads N.
        q_amplitudes: (np, 2) tangential force amplitudes N; amplitudes above max_ratio·μN are
            clipped to it (gross slip has no secant) and reported in ``clipped``.
        periodic, threads, tol: as in patch_normal_stiffness. tangential_tol: partial-slip tolerance.
        secant: compute the secant values.
        max_ratio: clipping ratio of |Q|/(μN) in (0, 1).

    Returns:
        (k_t, k_t_secant, clipped): (np,) N/mm³, (np,) N/mm³ (nan if secant=False), (np,) bool.
    """
    z, cell, W = _check_patches(patches, cell_size, young, poisson, loads)
    hs, p = _patch_normal(z, cell, young, poisson, W, periodic, threads, tol)
    return _patch_tangential(hs, p, W, mu, q_amplitudes, tangential_tol, secant, max_ratio)


def _patch_tangential(hs, p, W, mu, q_amplitudes, tangential_tol, secant, max_ratio):
    z = p
    mu = positive_scalar("mu", mu)
    Qa = finite_array("q_amplitudes", q_amplitudes, (z.shape[0], 2))
    max_ratio = positive_scalar("max_ratio", max_ratio, upper=1.0, upper_open=True)
    contact = p > 0
    has = contact.any(axis=_AX)
    e = _unit_dir(Qa)
    kt = np.zeros(z.shape[0])
    if has.any():
        K = _stuck_matrix(hs, contact[has], 1e-10)
        kt[has] = _along(K, e[has])
    kt /= hs.grid.area
    A = hs.grid.cell_area
    qn = np.hypot(Qa[:, 0], Qa[:, 1])
    limit = mu * W * max_ratio
    clipped = qn > limit
    Qc = np.where(clipped[:, None], e * limit[:, None], Qa)
    Qc = np.where(has[:, None], Qc, 0.0)
    sec = np.full(z.shape[0], np.nan)
    if secant:
        R = mu * p
        zero = np.zeros((z.shape[0], 2) + z.shape[1:])
        L = hs.tangential_lipschitz
        r1 = pk_tangential_compacting(hs._apply_tangential, R, zero, zero, Qc, A, tol=tangential_tol,
                                      lipschitz=L)
        s1 = r1["shift"][:, :, None, None] - r1["displacement"]
        r2 = pk_tangential_compacting(hs._apply_tangential, R, s1, r1["traction"], -Qc, A, tol=tangential_tol,
                                      lipschitz=L)
        dd = ((r1["shift"] - r2["shift"]) * e).sum(axis=1)
        qc = np.hypot(Qc[:, 0], Qc[:, 1])
        ok = (qc > 0) & (dd > 0)
        sec = np.where(ok, 2.0 * qc / np.where(ok, dd, 1.0) / hs.grid.area, kt)
    return kt, sec, clipped


@dataclass
class PatchStiffness:
    """Normal and tangential stiffness of a batch of patches (all arrays (np,)).

    Attributes:
        k_n: (dN/dδ)/A, N/mm³.
        k_t: slope at load reversal per area, N/mm³.
        k_t_secant: loop secant per area, N/mm³ (nan if not requested).
        clipped: tangential amplitude clipped to max_ratio·μN.
        contact_fraction: real contact area / patch area.
    """

    k_n: np.ndarray
    k_t: np.ndarray
    k_t_secant: np.ndarray
    clipped: np.ndarray
    contact_fraction: np.ndarray


def patch_stiffness(patches, cell_size, young: float, poisson: float, mu: float, loads, q_amplitudes, *,
                    periodic: bool = False, threads: int = 1, tol: float = 1e-8,
                    tangential_tol: float = 1e-6, secant: bool = True,
                    max_ratio: float = 0.99) -> PatchStiffness:
    """k_n and k_t of many patches sharing one batched normal solve (arguments as in
    ``patch_normal_stiffness`` and ``patch_tangential_stiffness``).

    Returns:
        PatchStiffness.
    """
    z, cell, W = _check_patches(patches, cell_size, young, poisson, loads)
    hs, p = _patch_normal(z, cell, young, poisson, W, periodic, threads, tol)
    kn = _patch_kn(hs, p)
    kt, sec, clipped = _patch_tangential(hs, p, W, mu, q_amplitudes, tangential_tol, secant, max_ratio)
    return PatchStiffness(kn, kt, sec, clipped, (p > 0).mean(axis=_AX))
