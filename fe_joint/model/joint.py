"""The joint as the dynamics sees it: one friction element per matched pair, and its linear limit.

A :class:`JointModel` holds, per element, the preload normal force N0, the initial gap, the
contact stiffnesses per unit area (k_n, k_t in N/mm³, as the paper states them) and the
tributary area; element stiffnesses are k·A (N/mm). This module also gives the *stuck* linear
limit of the joint (every loaded element a linear spring), which sets the sweep band, the
small-excitation check and the choice of excitation levels.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from .reduced_model import add_pair_springs, lowest_modes


@dataclass
class JointModel:
    """Friction-element parameters of one configuration.

    Attributes:
        name: configuration ('baseline', 'smooth-ms', 'v1', 'v2', 'v3', 'v3-rq5', …).
        n0: (ne,) preload normal force, N.
        gap: (ne,) initial gap, mm (0 for loaded elements).
        kn, kt: (ne,) normal and tangential contact stiffness per unit area, N/mm³.
        area: (ne,) tributary area, mm².
        rq_um: composite roughness of the surface behind it (None: smooth FE preload).
        info: extra per-configuration data for the report (contact fraction, …).
    """
    name: str
    n0: np.ndarray
    gap: np.ndarray
    kn: np.ndarray
    kt: np.ndarray
    area: np.ndarray
    rq_um: float | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        ne = len(self.area)
        for k in ("n0", "gap", "kn", "kt"):
            v = np.asarray(getattr(self, k), float)
            if v.shape != (ne,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f"JointModel.{k}: expected {ne} finite values ≥ 0")
            setattr(self, k, v)

    @property
    def closed(self) -> np.ndarray:
        """Elements carrying preload (N0 > 0)."""
        return self.n0 > 0

    def k_eq(self, which: str = "kn") -> float:
        """Equivalent stiffness Σ k_i A_i / Σ A_i over all elements, N/mm³ (paper Figs. 15, 19)."""
        k = getattr(self, which)
        return float(np.sum(k * self.area) / np.sum(self.area))


def stuck_stiffness(K: np.ndarray, pair_dofs: np.ndarray, joint: JointModel) -> np.ndarray:
    """Stiffness of the structure with every loaded element stuck (linear springs).

    Args:
        K: (n, n) reduced stiffness without the joint.
        pair_dofs: (ne, 2, 3) reduced DOFs of sides A and B for (t1, t2, n); the interface frame
            is the global one (z normal), so the element frame needs no rotation.
        joint: the configuration.
    Returns:
        (n, n) stiffness including k_t·A (t1, t2) and k_n·A (n) of every element with N0 > 0.
    """
    c = joint.closed
    k = np.stack([joint.kt, joint.kt, joint.kn], axis=1)[c] * joint.area[c, None]   # (nc, 3)
    return add_pair_springs(K, pair_dofs[c], k)


@dataclass
class LinearJoint:
    """Modes of the structure with the joint stuck."""
    frequencies: np.ndarray     # (m,) Hz, ascending (rigid-body modes ≈ 0 first)
    modes: np.ndarray           # (n, m) mass-normalized
    mode_index: int             # index of the breathing mode (first elastic mode)

    @property
    def frequency(self) -> float:
        """Breathing-mode frequency, Hz."""
        return float(self.frequencies[self.mode_index])


#: the stuck modes computed lately (:func:`stuck_modes`), at most STUCK_CACHE_SIZE of them
_STUCK_CACHE: OrderedDict = OrderedDict()
STUCK_CACHE_SIZE = 16


def _springs_digest(joint: JointModel) -> bytes:
    """Digest of what the stuck stiffness reads from a joint: the loaded elements and their
    k_t A, k_n A."""
    c = np.asarray(joint.closed)
    h = hashlib.blake2b(digest_size=16)
    for a in (c, (joint.kt * joint.area)[c], (joint.kn * joint.area)[c]):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.digest()


def stuck_modes(K: np.ndarray, M: np.ndarray, pair_dofs: np.ndarray, joint: JointModel,
                n_modes: int = 10) -> LinearJoint:
    """Lowest modes of the stuck structure; the breathing mode is the first elastic one.

    Rigid-body modes are recognised as those below 1 % of the highest computed frequency's
    hundredth (free–free structure: six of them).

    The last ``STUCK_CACHE_SIZE`` results are kept, by the identity of K, M and pair_dofs (the
    arrays are never modified in place) and the joint's springs: the report asked for the same
    joints' modes from five of its sections, each a generalized eigenproblem of about 1 s at the
    default model's 2198 DOFs. The returned object is shared: do not modify it.
    """
    key = (id(K), id(M), id(pair_dofs), _springs_digest(joint), int(n_modes))
    hit = _STUCK_CACHE.get(key)
    if hit is not None and hit[0] is K and hit[1] is M and hit[2] is pair_dofs:
        _STUCK_CACHE.move_to_end(key)
        return hit[3]
    lin = _stuck_modes(K, M, pair_dofs, joint, n_modes)
    remember_stuck_modes(K, M, pair_dofs, joint, lin, n_modes)
    return lin


def remember_stuck_modes(K: np.ndarray, M: np.ndarray, pair_dofs: np.ndarray, joint: JointModel,
                         lin: LinearJoint, n_modes: int = 10) -> None:
    """Put ``lin``, the result of ``stuck_modes(K, M, pair_dofs, joint, n_modes)`` computed
    elsewhere (another rank: ``report.linear_frf.share_eigenproblems``), in its cache."""
    key = (id(K), id(M), id(pair_dofs), _springs_digest(joint), int(n_modes))
    _STUCK_CACHE[key] = (K, M, pair_dofs, lin)
    _STUCK_CACHE.move_to_end(key)
    while len(_STUCK_CACHE) > STUCK_CACHE_SIZE:
        _STUCK_CACHE.popitem(last=False)


def _stuck_modes(K: np.ndarray, M: np.ndarray, pair_dofs: np.ndarray, joint: JointModel,
                 n_modes: int) -> LinearJoint:
    Ks = stuck_stiffness(K, pair_dofs, joint)
    n = Ks.shape[0]
    w2, phi = lowest_modes(Ks, M, min(n_modes, n))
    f = np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi)
    elastic = np.nonzero(f > 1e-4 * f[-1] + 1.0)[0]
    if len(elastic) == 0:
        raise ValueError("stuck joint: no elastic mode among the computed ones")
    return LinearJoint(frequencies=f, modes=phi, mode_index=int(elastic[0]))


def slip_onset(K: np.ndarray, M: np.ndarray, pair_dofs: np.ndarray, joint: JointModel,
               excitation_dof: int, damping_ratio: float, mu: float,
               lin: LinearJoint | None = None) -> dict:
    """Linear estimate of the excitation at which elements start to slip, at resonance.

    With the joint stuck and modal damping ζ, the resonant response to a unit force is
    φ_r (φ_r·e)/(2ζω_r²). An element slips once its tangential force k_t A |u_t| reaches μN0,
    so its onset force is μN0 / (k_t A |u_t|). The whole joint slips (macroslip) once the net
    tangential force reaches μ ΣN0. Friction damping caps the real response, so these are
    lower bounds of what the nonlinear model needs — used only to place the excitation levels.

    Returns:
        dict: ``onset`` (ne,) N (inf for unloaded elements), ``macroslip`` N,
        ``first_slip`` N, ``quantile(q)`` callable: the force at which a fraction q of the
        loaded contact area slips.
    """
    lin = lin or stuck_modes(K, M, pair_dofs, joint)
    r = lin.mode_index
    phi = lin.modes[:, r]
    w = 2 * np.pi * lin.frequencies[r]
    x = phi * phi[excitation_dof] / (2 * damping_ratio * w * w)      # amplitude per N
    ut = x[pair_dofs[:, 0, :2]] - x[pair_dofs[:, 1, :2]]            # (ne, 2)
    tang = joint.kt * joint.area * np.hypot(ut[:, 0], ut[:, 1])
    c = joint.closed
    onset = np.full(len(c), np.inf)
    onset[c] = mu * joint.n0[c] / np.maximum(tang[c], 1e-300)
    net = np.abs(np.sum((joint.kt * joint.area)[c] * ut[c, 0]))
    macroslip = mu * joint.n0.sum() / max(net, 1e-300)
    order = np.argsort(onset[c])
    cum = np.cumsum(joint.area[c][order]) / joint.area[c].sum()

    def quantile(q: float) -> float:
        return float(onset[c][order][min(np.searchsorted(cum, q), len(order) - 1)])

    return {"onset": onset, "macroslip": float(macroslip), "first_slip": float(onset[c].min()),
            "quantile": quantile, "frequency": lin.frequency}


def closure_onset(lin: LinearJoint, pair_dofs: np.ndarray, joint: JointModel,
                  excitation_dof: int) -> np.ndarray:
    """Response amplitude at which each element open at rest first closes, in the stuck mode.

    In the stuck mode φ (the loaded elements are springs, the open ones carry nothing) an element
    open at rest with gap g sees the normal relative displacement a·Δφ_n cos ωt at modal amplitude
    a, so it touches once a |Δφ_n| ≥ g, i.e. at the response amplitude X = a |φ_e| =
    g |φ_e| / |Δφ_n| at the excitation DOF. A linear estimate (slip elsewhere changes the shape),
    used to say which open elements a level can close.

    Args:
        lin: the stuck modes of the joint (mode of interest at ``lin.mode_index``).
        pair_dofs: (ne, 2, 3) reduced DOFs of sides A and B for (t1, t2, n).
        joint: the configuration (its gaps, mm; loaded elements are not "open").
        excitation_dof: the DOF whose amplitude X measures the response.
    Returns:
        (ne,) X at first closure, mm (inf for loaded elements and those the mode does not move
        normally).
    """
    phi = np.append(lin.modes[:, lin.mode_index], 0.0)     # index -1 (ground) reads the 0
    un = np.abs(phi[pair_dofs[:, 0, 2]] - phi[pair_dofs[:, 1, 2]])
    out = np.full(len(joint.area), np.inf)
    o = ~joint.closed & (un > 0)
    out[o] = joint.gap[o] * abs(phi[excitation_dof]) / un[o]
    return out
