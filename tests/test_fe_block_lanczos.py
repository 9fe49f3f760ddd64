"""Block Lanczos on K_II's factor (the fixed-interface modes) against SLEPc's Krylov–Schur, and
the paths that hand the problem to SLEPc (memory budget, a mode missed below the cut-off)."""
import numpy as np
import pytest
from mpi4py import MPI

import fe_joint.fe.reduction as red
from fe_joint.case import Material
from fe_joint.fe.assembly import assemble_joint
from fe_joint.fe.block_lanczos import lowest_modes
from fe_joint.fe.box_joint import build_box_joint
from fe_joint.fe.condensation import BoundaryCondensation
from fe_joint.fe.mesh import mesh_from_data
from fe_joint.fe.modal import solve_eigenproblem, to_hz

CUTOFF = 150000.0


def _condensation(comm):
    data = build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)
    prob = assemble_joint(mesh_from_data(data, comm), Material())
    return BoundaryCondensation(prob.K, prob.M, prob.layout.dofs)


def _m_products(KII, MII, A: list, B: list) -> np.ndarray:
    """A^T M B over distributed Vecs, (len(A), len(B))."""
    out = np.empty((len(A), len(B)))
    tmp = MII.createVecLeft()
    for j, b in enumerate(B):
        MII.mult(b, tmp)
        for i, a in enumerate(A):
            out[i, j] = a.dot(tmp)
    return out


@pytest.mark.mpi
def test_block_lanczos_equals_slepc():
    """The 12 lowest pairs of the box joint's interior: eigenvalues equal SLEPc's to 1e-10
    relative, the vectors M-orthonormal to 1e-12 and spanning SLEPc's subspace (the singular
    values of Φᵀ M Φ_SLEPc are 1 to 1e-9), on 1 rank and on 2."""
    cond = _condensation(MPI.COMM_WORLD)
    KII, MII = cond.interior_pair()
    nev = 12
    lam, vecs = lowest_modes(KII, MII, cond.factor, nev)
    lam_s, vecs_s = solve_eigenproblem(KII, MII, nev, sigma=0.0)
    assert np.max(np.abs(lam / lam_s - 1)) < 1e-10
    G = _m_products(KII, MII, vecs, vecs)
    assert np.max(np.abs(G - np.eye(nev))) < 1e-12
    # the 12th and 13th eigenvalues are apart, so the subspaces are comparable as a whole
    s = np.linalg.svd(_m_products(KII, MII, vecs, vecs_s), compute_uv=False)
    assert np.max(np.abs(s - 1)) < 1e-9
    # the residuals ||K x - lambda M x|| / ||K x|| of the pairs themselves, the same order as
    # SLEPc's at the same tolerance (measured serially: 3.9e-7 against 2.2e-7)
    own, slepc = _residuals(KII, MII, lam, vecs), _residuals(KII, MII, lam_s, vecs_s)
    assert own.max() < 1e-6 and own.max() < 5 * slepc.max()
    cond.destroy()


def _residuals(KII, MII, lam, vecs) -> np.ndarray:
    r, tmp, out = KII.createVecLeft(), KII.createVecLeft(), []
    for lm, v in zip(lam, vecs):
        KII.mult(v, r)
        MII.mult(v, tmp)
        r.axpy(-lm, tmp)
        KII.mult(v, tmp)
        out.append(r.norm() / tmp.norm())
    return np.array(out)


def test_fixed_interface_modes_over_budget_are_slepcs(monkeypatch):
    """A basis over the memory budget gives None, and the fixed-interface modes are SLEPc's."""
    cond = _condensation(MPI.COMM_SELF)
    KII, MII = cond.interior_pair()
    assert lowest_modes(KII, MII, cond.factor, 4, budget_mb=1e-3) is None
    f_block, _ = red.fixed_interface_modes(cond, CUTOFF)
    calls = []

    def over_budget(*args, **kw):
        calls.append(1)
        return lowest_modes(*args, **kw, budget_mb=1e-3)
    monkeypatch.setattr(red, "lowest_modes", over_budget)
    f_slepc, modes = red.fixed_interface_modes(cond, CUTOFF)
    assert calls and len(f_slepc) == len(f_block) == len(modes) >= 4
    assert np.max(np.abs(f_slepc / f_block - 1)) < 1e-10
    cond.destroy()


def test_a_mode_missed_below_the_cutoff_goes_to_slepc(monkeypatch):
    """Ritz values above the cut-off mean a mode below it was missed (there are as many as the
    inertia count says): such a result is not used, SLEPc's is. Here the stand-in returns the
    pairs n+1 … 2n instead of 1 … n."""
    cond = _condensation(MPI.COMM_SELF)
    n = red.count_modes_below(*cond.interior_pair(), CUTOFF)
    f_ref, _ = red.fixed_interface_modes(cond, CUTOFF)

    def shifted(K, M, factor, nev, **kw):
        lam, vecs = lowest_modes(K, M, factor, 2 * nev, **kw)
        return lam[nev:], vecs[nev:]
    monkeypatch.setattr(red, "lowest_modes", shifted)
    f, modes = red.fixed_interface_modes(cond, CUTOFF)
    assert len(f) == len(modes) == n and np.all(f <= CUTOFF)
    assert np.max(np.abs(f / f_ref - 1)) < 1e-10
    # the shifted pairs really lay above the cut-off (what the check caught)
    lam2, _ = lowest_modes(*cond.interior_pair(), cond.factor, 2 * n)
    assert to_hz(lam2[n:])[0] > CUTOFF
    cond.destroy()


def test_nev_must_be_positive():
    cond = _condensation(MPI.COMM_SELF)
    with pytest.raises(ValueError, match="nev"):
        lowest_modes(*cond.interior_pair(), cond.factor, 0)
    cond.destroy()
