"""The stuck (linear) FRF of a joint: the curve friction bends away from, for the FRF figures.

The structure with every loaded element stuck (``model.joint.stuck_stiffness``: k_n A, k_t A
springs on the pairs with N0 > 0) and the structural modal damping ζ on each of its elastic modes,
which is the HBM's linear base (``hbm.LinearStructure(damping_ratio=…)``: modal damping of the
assembly with the contacts closed at rest stuck). By modal superposition:

    X(ω) / F = Σ_r φ_r[resp] φ_r[exc] / (ω_r² − ω² + 2 i ζ ω_r ω) + S     (rigid modes undamped),

over every mode of a model of up to ``ALL_MODES_UP_TO`` DOFs (S = 0), else over its lowest
``KEPT_MODES`` (the HBM receptance's, ``hbm.LinearStructure``) with the static response of the
others, S = [K_s⁻¹ − Σ_kept φ φᵀ / ω_r²]_(resp, exc) (rigid modes removed as in ``hbm.structure``).
What S leaves out, the dynamic amplification and damping of the modes above the kept ones, is
(f / f_kept)² of S, below what a figure shows: on the default model within 2.6e-5 of the full
superposition over 200–260 Hz (median 8.5e-7). The kept modes and S come as the HBM's do
(``hbm.structure.lowest_modes_and_factor``: block Lanczos on one Cholesky factor, 0.74-0.82 s
with M's Cholesky where LAPACK's subset eigh alone took 0.89 s and the full eigh 2.3 s at 2198
DOFs; issue 16, sessions 24 and 27).
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
import scipy.linalg as sla

from hbm.structure import discarded_static_response, lowest_modes_and_factor, rigid_modes

from ..model.joint import JointModel, _springs_digest, remember_stuck_modes, stuck_modes, stuck_stiffness
from ..model.reduced_model import mass_cholesky

#: the receptances computed lately, by the identity of the reduced model and the joint's springs
#: (the FRF figures and a rank that computed them for rank 0: :func:`share_eigenproblems`)
_CACHE: OrderedDict = OrderedDict()
CACHE_SIZE = 8
#: models up to this many DOFs superpose all their modes; larger ones KEPT_MODES and the static
#: residual (as ``hbm.LinearStructure``'s default n_modes)
ALL_MODES_UP_TO = 300
KEPT_MODES = 60


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
            self.w2, self.wr, self.zeta, self.num, self.static = hit[1]
            return
        Ks = stuck_stiffness(rm.K, rm.pair_dofs, joint)
        n = Ks.shape[0]
        complete = n <= ALL_MODES_UP_TO
        if complete:
            w2, phi = sla.eigh(Ks, rm.M)
        else:
            w2, phi, factor, shift = lowest_modes_and_factor(Ks, rm.M, KEPT_MODES, mass_cholesky(rm.M))
        rigid = rigid_modes(w2, Ks, rm.M)                       # free–free: rigid modes undamped
        self.w2 = np.where(rigid, 0.0, w2)
        self.wr = np.sqrt(self.w2)
        self.zeta = np.where(rigid, 0.0, rm.damping_ratio)
        self.num = phi[rm.response_dof] * phi[rm.excitation_dof]
        self.static = 0.0
        if not complete:
            e = np.zeros(n)
            e[rm.excitation_dof] = 1.0
            self.static = float(discarded_static_response(rm.M, factor, shift, self.w2, phi, rigid,
                                                          e)[rm.response_dof])
        self._remember(rm, joint)

    def _remember(self, rm, joint: JointModel) -> None:
        key = (id(rm), _springs_digest(joint))
        _CACHE[key] = (rm, (self.w2, self.wr, self.zeta, self.num, self.static))
        _CACHE.move_to_end(key)
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)

    @classmethod
    def from_parts(cls, rm, joint: JointModel, parts: tuple) -> "StuckReceptance":
        """The receptance whose (w2, wr, zeta, num, static) were computed elsewhere (another
        rank), cached as if computed here."""
        self = object.__new__(cls)
        self.w2, self.wr, self.zeta, self.num, self.static = parts
        self._remember(rm, joint)
        return self

    def __call__(self, freq_hz: np.ndarray) -> np.ndarray:
        """(p,) complex receptance, mm/N, at frequencies ``freq_hz`` (p,), Hz."""
        w = 2 * np.pi * np.asarray(freq_hz, float)[:, None]
        return np.sum(self.num / (self.w2 - w ** 2 + 2j * self.zeta * self.wr * w), axis=1) + self.static


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
    each configuration joint's stuck receptance (its kept modes and static residual, 0.8 s at
    the default model's 2198 DOFs) and its ten stuck modes (0.2 s). The results are cached on every
    rank, so rank 0's figures and tables find them; they are the same bits as rank 0's own
    (the same computation on the same inputs, one BLAS thread). Collective.

    Args:
        data: the run's artifacts (``report.data.ReportData``), loaded on every rank.
        comm: MPI communicator.
    """
    from ..study.queue import map_ranks
    from .stiffness import configuration_joints
    rm, joints = data.rm, configuration_joints(data)
    # the receptances first, then the cheaper modes: dealt round-robin, so that each rank gets
    # about as much work (interleaved, rank 0 drew every receptance and rank 1 every mode set)
    items = [(kind, name) for kind in ("receptance", "modes") for name in joints]

    def one(item):
        kind, name = item
        if kind == "receptance":
            r = StuckReceptance(rm, joints[name])
            return (r.w2, r.wr, r.zeta, r.num, r.static)
        try:
            return stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[name])
        except ValueError:          # no elastic mode among the lowest ten: rank 0 says so itself
            return None
    for (kind, name), r in zip(items, map_ranks(one, items, comm)):
        if kind == "receptance":
            StuckReceptance.from_parts(rm, joints[name], r)
        elif r is not None:
            remember_stuck_modes(rm.K, rm.M, rm.pair_dofs, joints[name], r)
