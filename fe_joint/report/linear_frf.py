"""The stuck (linear) FRF of a joint: the curve friction bends away from, for the FRF figures.

The structure with every loaded element stuck (``model.joint.stuck_stiffness``: k_n A, k_t A
springs on the pairs with N0 > 0) and the structural modal damping ζ on each of its elastic modes,
which is the HBM's linear base (``hbm.LinearStructure(damping_ratio=…)``: modal damping of the
assembly with the contacts closed at rest stuck). By modal superposition over all modes:

    X(ω) / F = Σ_r φ_r[resp] φ_r[exc] / (ω_r² − ω² + 2 i ζ ω_r ω)     (rigid modes undamped).
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
import scipy.linalg as sla

from ..model.joint import JointModel, _springs_digest, remember_stuck_modes, stuck_modes, stuck_stiffness

#: the receptances computed lately, by the identity of the reduced model and the joint's springs
#: (the FRF figures and a rank that computed them for rank 0: :func:`share_eigenproblems`)
_CACHE: OrderedDict = OrderedDict()
CACHE_SIZE = 8


class StuckReceptance:
    """The stuck structure's receptance between the excitation and response DOFs, by modal
    superposition over all its modes (one generalized eigenproblem, then any frequencies).

    Args:
        rm: the reduced model (K, M, pair_dofs, damping_ratio, excitation/response DOFs).
        joint: the joint whose loaded elements are stuck.
    """

    def __init__(self, rm, joint: JointModel) -> None:
        key = (id(rm), _springs_digest(joint))
        hit = _CACHE.get(key)
        if hit is not None and hit[0] is rm:
            self.w2, self.wr, self.zeta, self.num = hit[1]
            return
        Ks = stuck_stiffness(rm.K, rm.pair_dofs, joint)
        w2, phi = sla.eigh(Ks, rm.M)
        self.w2 = np.clip(w2, 0.0, None)
        self.wr = np.sqrt(self.w2)
        elastic = self.wr > 1e-4 * self.wr[-1] + 2 * np.pi      # free–free: rigid modes undamped
        self.zeta = np.where(elastic, rm.damping_ratio, 0.0)
        self.num = phi[rm.response_dof] * phi[rm.excitation_dof]
        self._remember(rm, joint)

    def _remember(self, rm, joint: JointModel) -> None:
        key = (id(rm), _springs_digest(joint))
        _CACHE[key] = (rm, (self.w2, self.wr, self.zeta, self.num))
        _CACHE.move_to_end(key)
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)

    @classmethod
    def from_parts(cls, rm, joint: JointModel, parts: tuple) -> "StuckReceptance":
        """The receptance whose (w2, wr, zeta, num) were computed elsewhere (another rank), cached
        as if computed here."""
        self = object.__new__(cls)
        self.w2, self.wr, self.zeta, self.num = parts
        self._remember(rm, joint)
        return self

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


def share_eigenproblems(data, comm) -> None:
    """The report's costliest eigenproblems, dealt to the ranks before rank 0 writes the report:
    each configuration joint's stuck receptance (a full generalized eigenproblem, 1.7 s at the
    default model's 2198 DOFs) and its ten stuck modes (0.7 s). The results are cached on every
    rank, so rank 0's figures and tables find them; they are the same bits as rank 0's own
    (the same computation on the same inputs, one BLAS thread). Collective.

    Args:
        data: the run's artifacts (``report.data.ReportData``), loaded on every rank.
        comm: MPI communicator.
    """
    from ..study.queue import map_ranks
    from .stiffness import configuration_joints
    rm, joints = data.rm, configuration_joints(data)
    items = [(kind, name) for name in joints for kind in ("receptance", "modes")]

    def one(item):
        kind, name = item
        if kind == "receptance":
            r = StuckReceptance(rm, joints[name])
            return (r.w2, r.wr, r.zeta, r.num)
        try:
            return stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[name])
        except ValueError:          # no elastic mode among the lowest ten: rank 0 says so itself
            return None
    for (kind, name), r in zip(items, map_ranks(one, items, comm)):
        if kind == "receptance":
            StuckReceptance.from_parts(rm, joints[name], r)
        elif r is not None:
            remember_stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[name], r)
