"""Alternative definitions of the contact stiffness of a patch (issue 13, items 3 and 4).

**Normal: the roughness layer without the bulk.** ``patch_normal_stiffness`` gives
k_n = (dN/dδ)/A with δ the approach of the whole half-space under the patch: the flat-punch
stiffness of the *current contact set*. It contains the bulk compliance of the half-space below
the patch, which an FE model with springs between its interface nodes already has (the continuum
around the node). The series split

    1/k_n = 1/k_layer + 1/k_bulk,     k_bulk = flat punch of the *whole* patch (every cell in contact)

removes it. The bulk is the rigid flat punch, not the uniform pressure, because (i) a rough
patch in complete contact *is* that punch, so k_layer = ∞ exactly there (a uniform-pressure bulk,
8 % more compliant for a circle, would leave a spurious finite layer stiffness ≈ 13 k_bulk in
complete contact); (ii) a spring between two FE nodes is a displacement constraint between the
tributary areas in the stuck limit, i.e. a punch, not a prescribed pressure. Sparse contact:
k_n ≪ k_bulk and k_layer → k_n. Complete contact: k_layer is capped at ``LAYER_CAP`` = 10 × k_bulk
(the springs then add 10 % of the patch bulk's compliance; on the resonator the stuck frequency is
within 0.12 % of the tied limit, 250.31 vs 250.62 Hz at 1000 k_bulk; at 100 k_bulk the harmonic
balance's base is so stiff that hbm's relative rigid-mode threshold, 1e-9 · max K/M, takes the
breathing mode for a rigid-body mode). The same split on the stuck tangential stiffness gives the
tangential layer.

**Tangential: three readings of the hysteresis loop** under a force cycle ±Q at fixed normal
pressure (paper Fig. 4), with the virgin curve δ_v(q) (0 → Q) traced in ``n_steps`` increments:

* *stick*: the slope at load reversal = the stuck stiffness of the contact set (what v3 uses; it
  does not depend on |Q|, and for similar materials it obeys Mindlin's ratio to k_n);
* *secant*: 2Q/Δδ over the loop = Q/δ_v(Q) (Masing: the loop tips are ±δ_v(Q));
* *energy*: the Jenkins element (spring k in series with a slider at Q) through the loop's tips
  (±Q, ±δ_v(Q)) that encloses the loop's area W: W = 4Q(δ_v(Q) − Q/k). With Masing's rule
  (exact for Cattaneo–Mindlin, Jäger 1998) W = 4Qδ_v(Q) − 8∫₀^Q δ_v dq, so
  k_energy = Q² / (2∫₀^Q δ_v dq): also the linear spring with the loop's complementary energy
  on loading. secant ≤ energy ≤ stick; all three → stick as Q → 0.

All values per patch area A (N/mm³), batched over patches along the first axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import finite_array, positive_scalar
from .stiffness import (_AX, _along, _check_patches, _normal_tangent, _patch_halfspace, _patch_kn,
                        _patch_normal, _stuck_matrix, _unit_dir)
from .tangential import pk_tangential_compacting

#: complete contact: k_layer ≤ LAYER_CAP · k_bulk (the springs add ≤ 10 % of the bulk compliance)
LAYER_CAP = 10.0


@dataclass(frozen=True)
class BulkStiffness:
    """The half-space stiffness of a whole patch in complete contact, per patch area (N/mm³).

    Attributes:
        k_n: rigid flat punch over the whole patch (normal).
        k_t: the whole patch stuck, along x (tangential).
        area: patch area, mm².
    """
    k_n: float
    k_t: float
    area: float


def patch_bulk_stiffness(shape, cell_size, young: float, poisson: float, *, mask=None,
                         periodic: bool = False, threads: int = 1) -> BulkStiffness:
    """The bulk stiffness of a patch: every cell in contact (flat punch / fully stuck).

    Args:
        shape: (n, m) patch cells. cell_size: (dx, dy) mm. young, poisson: E (MPa), ν.
        mask: optional (n, m) bool nominal area (default the whole square patch).
        periodic, threads: as in ``patch_normal_stiffness`` (must match the patches' solves).
    Returns:
        BulkStiffness (per nominal area: the mask's, else the patch's).
    """
    z, cell, _ = _check_patches(np.zeros((1,) + tuple(shape)), cell_size, young, poisson, [0.0])
    hs = _patch_halfspace(z.shape[1:], cell, float(young), float(poisson), bool(periodic), int(threads))
    full = np.ones(z.shape, bool) if mask is None else np.asarray(mask, bool).reshape(z.shape)
    if not full.any():
        raise ValueError("mask: the nominal area is empty")
    kn = float(_normal_tangent(hs, full, 1e-12)[0])
    kt = float(_along(_stuck_matrix(hs, full, 1e-12), np.array([[1.0, 0.0]]))[0])
    A = float(full.sum() * hs.grid.cell_area)
    return BulkStiffness(kn / A, kt / A, A)


def layer_stiffness(k, k_bulk: float, cap: float = LAYER_CAP) -> np.ndarray:
    """The roughness layer's stiffness: k_layer = 1/max(1/k − 1/k_bulk, 1/(cap·k_bulk)).

    Args:
        k: (…,) contact stiffness per area with the bulk (N/mm³); 0 = no contact (kept 0).
        k_bulk: the patch's bulk stiffness per area (N/mm³), ``patch_bulk_stiffness``.
        cap: k_layer ≤ cap·k_bulk (complete contact, where 1/k − 1/k_bulk → 0).
    Returns:
        k_layer (…,) N/mm³: ≥ k, = k where k ≪ k_bulk, = cap·k_bulk in complete contact.
    """
    kb = positive_scalar("k_bulk", k_bulk)
    cap = positive_scalar("cap", cap)
    k = np.asarray(k, float)
    if np.any(k < 0) or not np.all(np.isfinite(k)):
        raise ValueError("k: must be finite and >= 0")
    comp = np.maximum(1.0 / np.where(k > 0, k, 1.0) - 1.0 / kb, 1.0 / (cap * kb))
    return np.where(k > 0, 1.0 / comp, 0.0)


@dataclass
class LoopStiffness:
    """Tangential stiffness of patches from their loop ±Q at fixed pressure (arrays (np,)).

    Attributes:
        k_n: normal stiffness (dN/dδ)/A at the load, N/mm³ (``patch_normal_stiffness``).
        stick: slope at load reversal per area, N/mm³.
        secant: Q/δ_v(Q) per area, N/mm³ (= stick where Q = 0).
        energy: Q²/(2∫₀^Q δ_v dq) per area, N/mm³ (the Jenkins element of the same loop area).
        dissipation: loop area W = 4Qδ_v(Q) − 8∫₀^Q δ_v dq, N·mm per cycle.
        amplitude: δ_v(Q), mm (half the loop's displacement range).
        force: |Q| used (after clipping), N.
        clipped: |Q| was clipped to max_ratio·μN.
    """
    k_n: np.ndarray
    stick: np.ndarray
    secant: np.ndarray
    energy: np.ndarray
    dissipation: np.ndarray
    amplitude: np.ndarray
    force: np.ndarray
    clipped: np.ndarray


def patch_loop_stiffness(patches, cell_size, young: float, poisson: float, mu: float, loads,
                         q_amplitudes, *, n_steps: int = 8, periodic: bool = False, threads: int = 1,
                         tol: float = 1e-8, tangential_tol: float = 1e-7,
                         max_ratio: float = 0.99) -> LoopStiffness:
    """Stick, secant and energy-equivalent k_t of many patches (module docstring).

    Args:
        patches: (np, n, m) heights (mm). cell_size: (dx, dy) mm. young, poisson: E (MPa), ν.
        mu: friction coefficient. loads: (np,) normal loads N.
        q_amplitudes: (np, 2) tangential force amplitudes N, clipped to max_ratio·μN.
        n_steps: even number of virgin-curve increments (Simpson's rule for ∫δ_v).
        periodic, threads, tol: as in ``patch_normal_stiffness``. tangential_tol: partial-slip
            tolerance. max_ratio: clipping ratio in (0, 1).
    Returns:
        LoopStiffness.
    """
    n = int(n_steps)
    if n < 2 or n % 2:
        raise ValueError(f"n_steps: must be an even number >= 2, got {n_steps!r}")
    z, cell, W = _check_patches(patches, cell_size, young, poisson, loads)
    mu = positive_scalar("mu", mu)
    Qa = finite_array("q_amplitudes", q_amplitudes, (z.shape[0], 2))
    max_ratio = positive_scalar("max_ratio", max_ratio, upper=1.0, upper_open=True)
    hs, p = _patch_normal(z, cell, young, poisson, W, periodic, threads, tol)
    contact = p > 0
    has = contact.any(axis=_AX)
    e = _unit_dir(Qa)
    stick = np.zeros(z.shape[0])
    if has.any():
        stick[has] = _along(_stuck_matrix(hs, contact[has], 1e-10), e[has])
    q = np.hypot(Qa[:, 0], Qa[:, 1])
    limit = mu * W * max_ratio
    clipped = q > limit
    q = np.where(has, np.minimum(q, limit), 0.0)
    delta = _virgin_curve(hs, mu * p, e, q, n, tangential_tol, has & (q > 0))
    h = q / n
    integral = h / 3.0 * (delta[:, 0] + 4 * delta[:, 1:-1:2].sum(axis=1)
                          + 2 * delta[:, 2:-1:2].sum(axis=1) + delta[:, -1])
    A = hs.grid.area
    live = (q > 0) & (delta[:, -1] > 0) & (integral > 0)
    secant = np.where(live, q / np.where(live, delta[:, -1], 1.0) / A, stick / A)
    energy = np.where(live, q ** 2 / (2 * np.where(live, integral, 1.0)) / A, stick / A)
    diss = np.where(live, 4 * q * delta[:, -1] - 8 * integral, 0.0)
    return LoopStiffness(_patch_kn(hs, p), stick / A, secant, energy, diss, delta[:, -1], q, clipped)


def _virgin_curve(hs, R, e, q, n, tol, live) -> np.ndarray:
    """(np, n+1) tangential shift along e on virgin loading 0 → q e in n equal increments
    (0 for patches not ``live``), each increment warm-started from the last."""
    out = np.zeros((len(q), n + 1))
    idx = np.nonzero(live)[0]
    if not len(idx):
        return out
    A = hs.grid.cell_area
    s = np.zeros((len(idx), 2) + R.shape[1:])
    t = np.zeros_like(s)
    for k in range(1, n + 1):
        Q = (k / n) * q[idx, None] * e[idx]
        r = pk_tangential_compacting(hs._apply_tangential, R[idx], s, t, Q, A, tol=tol,
                                     lipschitz=hs.tangential_lipschitz)
        # the next increment starts from this state: slip so far (shift − elastic displacement)
        s = r["shift"][:, :, None, None] - r["displacement"]
        t = r["traction"]
        out[idx, k] = (r["shift"] * e[idx]).sum(axis=1)
    return out
