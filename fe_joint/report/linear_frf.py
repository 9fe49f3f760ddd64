"""The stuck (linear) FRF of a joint: the curve friction bends away from, for the FRF figures.

The structure with every loaded element stuck (``model.joint.stuck_stiffness``: k_n A, k_t A
springs on the pairs with N0 > 0) and the structural modal damping ζ on each of its elastic modes,
which is the HBM's linear base (``hbm.LinearStructure(damping_ratio=…)``: modal damping of the
assembly with the contacts closed at rest stuck). By modal superposition over all modes:

    X(ω) / F = Σ_r φ_r[resp] φ_r[exc] / (ω_r² − ω² + 2 i ζ ω_r ω)     (rigid modes undamped).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..model.joint import JointModel, stuck_stiffness


class StuckReceptance:
    """The stuck structure's receptance between the excitation and response DOFs, by modal
    superposition over all its modes (one generalized eigenproblem, then any frequencies).

    Args:
        rm: the reduced model (K, M, pair_dofs, damping_ratio, excitation/response DOFs).
        joint: the joint whose loaded elements are stuck.
    """

    def __init__(self, rm, joint: JointModel) -> None:
        Ks = stuck_stiffness(rm.K, rm.pair_dofs, joint)
        w2, phi = sla.eigh(Ks, rm.M)
        self.w2 = np.clip(w2, 0.0, None)
        self.wr = np.sqrt(self.w2)
        elastic = self.wr > 1e-4 * self.wr[-1] + 2 * np.pi      # free–free: rigid modes undamped
        self.zeta = np.where(elastic, rm.damping_ratio, 0.0)
        self.num = phi[rm.response_dof] * phi[rm.excitation_dof]

    def __call__(self, freq_hz: np.ndarray) -> np.ndarray:
        """(p,) complex receptance, mm/N, at frequencies ``freq_hz`` (p,), Hz."""
        w = 2 * np.pi * np.asarray(freq_hz, float)[:, None]
        return np.sum(self.num / (self.w2 - w ** 2 + 2j * self.zeta * self.wr * w), axis=1)


def stuck_receptance(rm, joint: JointModel, freq_hz: np.ndarray) -> np.ndarray:
    """Receptance of the stuck structure between the excitation and response DOFs.

    Args:
        rm: the reduced model (K, M, pair_dofs, damping_ratio, excitation/response DOFs).
        joint: the joint whose loaded elements are stuck.
        freq_hz: (p,) frequencies, Hz.
    Returns:
        (p,) complex receptance, mm/N (amplitude at the response DOF per N at the excitation DOF).
    """
    return StuckReceptance(rm, joint)(freq_hz)
