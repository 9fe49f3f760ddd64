"""How the interface moves in a mode: rigid relative sliding, rocking, or deformation.

A friction joint dissipates through the relative motion u = q_A − q_B of its node pairs. Fitting
that field (global components, weighted by the pairs' tributary areas) with a rigid relative
motion d + θ × (x − x_c) about the area centroid splits its mean-square into sliding (d_x, d_y),
closing (d_z), rocking/pitching (θ_x, θ_y), twisting (θ_z) and what no rigid motion explains:
the two plates deforming differently (shear lag, secondary bending). A joint that slides moves
by d; a lap joint whose mode bends it rocks about the axis across the load path and opens at the
overlap's ends — which is what the resonator's breathing mode does (docs/design.md, "The resonator").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: names of the six rigid relative motions, in the order of :attr:`InterfaceMotion.rigid`
RIGID_NAMES = ("slide x", "slide y", "close z", "rock about x", "rock about y", "twist about z")


@dataclass(frozen=True)
class InterfaceMotion:
    """Decomposition of an interface's relative motion (shares of Σ A |u|², summing to 1).

    Attributes:
        rigid: (6,) shares of the rigid motions named in ``RIGID_NAMES``.
        deformation: (3,) shares of the non-rigid remainder in x, y, z.
        mean_over_rms: (3,) |area mean| of u_x, u_y, u_z over their area rms (0: the motion
            cancels over the interface, 1: uniform; the magnitude: a mode's sign is arbitrary).
    """
    rigid: np.ndarray
    deformation: np.ndarray
    mean_over_rms: np.ndarray

    def as_dict(self) -> dict:
        """Plain floats keyed by name (for summary.json and tables)."""
        d = {n: float(v) for n, v in zip(RIGID_NAMES, self.rigid)}
        d.update({f"deform {c}": float(v) for c, v in zip("xyz", self.deformation)})
        return d


def relative_motion(phi: np.ndarray, pair_dofs: np.ndarray, pair_frame: np.ndarray) -> np.ndarray:
    """Relative displacement q_A − q_B of every pair in global components.

    Args:
        phi: (n,) a displacement vector of the reduced model (a mode shape), mm.
        pair_dofs: (m, 2, 3) DOFs of sides A and B along the pair's (t1, t2, n).
        pair_frame: (m, 3, 3) rows t1, t2, n in global components.
    Returns:
        (m, 3) global relative displacement, mm.
    """
    local = phi[pair_dofs[:, 0, :]] - phi[pair_dofs[:, 1, :]]
    return np.einsum("mk,mkj->mj", local, pair_frame)


def decompose(u: np.ndarray, xyz: np.ndarray, area: np.ndarray) -> InterfaceMotion:
    """Split a relative motion field into rigid motions about the area centroid and the rest.

    Args:
        u: (m, 3) relative displacement per pair, global components, mm.
        xyz: (m, 3) pair coordinates, mm.
        area: (m,) tributary areas, mm² (the weights).
    Returns:
        the shares of each rigid motion and of the deformation (rigid parts are area-orthogonal
        to each other only approximately on a real mesh: the shares are of the fitted parts).
    """
    r = xyz - (area[:, None] * xyz).sum(0) / area.sum()
    m = len(r)
    A = np.zeros((m, 3, 6))
    A[:, [0, 1, 2], [0, 1, 2]] = 1.0
    # θ × r = (θy rz − θz ry, θz rx − θx rz, θx ry − θy rx)
    A[:, 0, 4], A[:, 0, 5] = r[:, 2], -r[:, 1]
    A[:, 1, 3], A[:, 1, 5] = -r[:, 2], r[:, 0]
    A[:, 2, 3], A[:, 2, 4] = r[:, 1], -r[:, 0]
    w = np.sqrt(area)[:, None, None]
    coef, *_ = np.linalg.lstsq((A * w).reshape(3 * m, 6), (u[:, :, None] * w).ravel(), rcond=None)
    total = float(np.sum(area[:, None] * u**2))
    parts = A * coef[None, None, :]                       # (m, 3, 6) each rigid motion's field
    rigid = np.array([np.sum(area[:, None] * parts[:, :, k] ** 2) for k in range(6)]) / total
    rest = u - parts.sum(axis=2)
    deformation = np.sum(area[:, None] * rest**2, axis=0) / total
    rms = np.sqrt(np.sum(area[:, None] * u**2, axis=0) / area.sum())
    # |mean|: a mode's sign is arbitrary (LAPACK's eigh and ARPACK's Lanczos return the same
    # stuck mode with opposite signs), so only the magnitude says how uniform the motion is
    mean = np.abs(np.sum(area[:, None] * u, axis=0)) / area.sum()
    return InterfaceMotion(rigid=rigid, deformation=deformation,
                           mean_over_rms=np.divide(mean, rms, out=np.zeros(3), where=rms > 0))
