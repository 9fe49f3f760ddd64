"""Craig–Bampton reduction: reduced vs full frequencies, rigid modes, CB identity, damping, HDF5."""
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI

from fe_joint.fe.box_joint import build_box_joint
from fe_joint.fe.condensation import BoundaryCondensation
from fe_joint.case import Material
from fe_joint.fe.assembly import assemble_joint
from fe_joint.fe.mesh import load_resonator, mesh_from_data
from fe_joint.model.reduced_model import ReducedModel, modal_damping_matrix
from fe_joint.fe.reduction import build_reduced_model_from_fe
from geometry.resonator import ResonatorParams

COARSE = ResonatorParams(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0)
CUTOFF = 60000.0


@pytest.fixture(scope="module")
def reduced(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("reduce"))
    out = MPI.COMM_WORLD.bcast(out, root=0)
    fe = load_resonator(COARSE, MPI.COMM_WORLD)
    rm = build_reduced_model_from_fe(fe, Material(), 30000.0, 1e-3, CUTOFF, out_dir=out)
    return rm, out


def test_first_ten_elastic_frequencies_match_full_model(reduced):
    rm, _ = reduced
    n_rigid = rm.metadata["n_rigid_full"]
    assert n_rigid == 6
    full = rm.full_frequencies[6:16]
    red = rm.reduced_frequencies[6:16]
    assert len(full) == 10
    assert np.abs(red / full - 1).max() < 1e-3
    # CB is a Ritz method: reduced frequencies bound the full ones from above
    assert np.all(red >= full * (1 - 1e-9))


def test_six_rigid_modes_at_zero(reduced):
    rm, _ = reduced
    first_elastic = rm.full_frequencies[6]
    assert np.abs(rm.full_frequencies[:6]).max() < 1e-3 * first_elastic
    assert np.abs(rm.reduced_frequencies[:6]).max() < 1e-3 * first_elastic
    assert rm.reduced_frequencies[6] > 0.5 * first_elastic


def test_reduced_modes_m_orthonormal_and_modal_damping(reduced):
    rm, _ = reduced
    lam, phi = sla.eigh(rm.K, rm.M)
    assert np.abs(phi.T @ rm.M @ phi - np.eye(rm.n_dofs)).max() < 1e-10
    modal_c = phi[:, 6:].T @ rm.C @ phi[:, 6:]
    omega = np.sqrt(lam[6:])
    assert np.abs(np.diag(modal_c) / (2 * omega) - 1e-3).max() < 1e-9
    assert np.abs(phi[:, :6].T @ rm.C @ phi[:, :6]).max() < 1e-9 * np.abs(modal_c).max()


def test_breathing_mode_and_stuck_joint_frequency(reduced):
    rm, _ = reduced
    # first elastic mode = breathing (mass A moving in x)
    assert rm.metadata["breathing_index"] == 6
    # with the closed pairs stuck (baseline k = 6e4 N/mm³) the breathing mode is the leaf bending
    # of docs/design.md, "The resonator" (≈ 248 Hz on the default mesh)
    f_stuck = rm.tied_frequencies(6e4)[6]
    assert f_stuck == pytest.approx(248.0, rel=0.05)


def test_labels_and_interface_fields(reduced):
    rm, _ = reduced
    p = rm.n_pairs // 2
    assert rm.dof_labels[rm.pair_dofs[p, 0, 2]] == f"pair{p}.A.z"
    assert rm.dof_labels[rm.pair_dofs[p, 1, 0]] == f"pair{p}.B.x"
    assert rm.dof_labels[rm.excitation_dof] == "excitation.x"
    assert rm.preload_normal_force.sum() == pytest.approx(30000.0, rel=1e-6)
    assert np.allclose(rm.pair_frame[p], np.eye(3))


def test_hdf5_roundtrip_without_dolfinx(reduced):
    rm, out = reduced
    path = os.path.join(out, "reduced_model.h5")
    code = ("import sys; sys.modules['dolfinx'] = None; sys.modules['petsc4py'] = None\n"
            "from fe_joint.model.reduced_model import ReducedModel\n"
            f"m = ReducedModel.load({path!r}); print(m.K.shape[0], m.K.sum(), m.excitation_dof)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert res.returncode == 0, res.stderr
    n, ksum, ex = res.stdout.split()
    assert int(n) == rm.n_dofs and int(ex) == rm.excitation_dof
    assert float(ksum) == pytest.approx(rm.K.sum(), rel=1e-12, abs=1e-6)
    back = ReducedModel.load(path)
    assert np.array_equal(back.M, rm.M) and back.dof_labels == rm.dof_labels
    assert back.metadata["n_pairs"] == rm.n_pairs


def test_constraint_mode_identity_against_superlu():
    """K_r,BB = K_BB + K_BI Psi from chunked MUMPS solves equals a SuperLU Schur complement."""
    data = build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)
    prob = assemble_joint(mesh_from_data(data, MPI.COMM_SELF), Material())
    cond = BoundaryCondensation(prob.K, prob.M, prob.layout.dofs)
    blocks = cond.condense(None, chunk=100)  # several chunks
    ai, aj, av = prob.K.getValuesCSR()
    K = sp.csr_matrix((av, aj, ai), shape=prob.K.getSize())
    b = prob.layout.dofs
    i = np.setdiff1d(np.arange(K.shape[0]), b)
    lu = spla.splu(K[i][:, i].tocsc())
    schur = K[b][:, b].toarray() - K[b][:, i] @ lu.solve(K[i][:, b].toarray())
    assert np.abs(blocks["K_BB"] - schur).max() < 1e-9 * np.abs(schur).max()
    # mass: Psiᵀ-projected M with Psi from SuperLU
    ai, aj, av = prob.M.getValuesCSR()
    M = sp.csr_matrix((av, aj, ai), shape=prob.M.getSize())
    psi = -lu.solve(K[i][:, b].toarray())
    mr = (M[b][:, b].toarray() + M[b][:, i] @ psi + psi.T @ M[i][:, b].toarray()
          + psi.T @ (M[i][:, i] @ psi))
    assert np.abs(blocks["M_BB"] - mr).max() < 1e-9 * np.abs(mr).max()
    cond.destroy()


@pytest.mark.parametrize("zeta", [-0.1, 1.0, float("nan")])
def test_damping_ratio_out_of_range(zeta):
    with pytest.raises(ValueError, match="damping_ratio"):
        modal_damping_matrix(np.eye(2), np.eye(2), zeta)


def test_canonical_mode_signs():
    """Each mode's largest coupling entry comes out positive whatever sign the solver gave it;
    among entries tied to 1e-6 the first in boundary order decides (mirror-symmetric DOFs)."""
    from fe_joint.fe.reduction import canonical_mode_signs
    rng = np.random.default_rng(3)
    m = rng.standard_normal((7, 40))
    m[5, [3, 17]] = 10.0, -10.0 * (1 + 1e-9)        # a round-off tie: entry 3 decides
    m[6, [2, 30]] = -10.0, 10.0                      # an exact tie: entry 2 decides
    flips = np.array([1, -1, -1, 1, -1, 1, -1], float)[:, None]
    a = m * canonical_mode_signs(m)[:, None]
    b = (m * flips) * canonical_mode_signs(m * flips)[:, None]
    assert np.array_equal(a, b)
    assert a[5, 3] > 0 and a[6, 2] > 0
    big = np.argmax(np.abs(a[:5]), axis=1)
    assert (a[np.arange(5), big] > 0).all()


def test_reduced_model_independent_of_eigenvector_signs():
    """Craig–Bampton from the same fixed-interface modes with some of them negated (what another
    run or rank count may return) gives the same reduced M and C to the bit; two builds of the
    same model in one process are bit-identical."""
    from fe_joint.fe.reduction import craig_bampton, fixed_interface_modes
    data = build_box_joint(half=6.0, thickness=4.0, cell=2.0, shank_half=2.0, hole_half=4.0)
    prob = assemble_joint(mesh_from_data(data, MPI.COMM_SELF), Material())
    out = []
    for flip in (False, True, False):
        cond = BoundaryCondensation(prob.K, prob.M, prob.layout.dofs)
        fm, modes = fixed_interface_modes(cond, 150000.0)
        if flip:
            for v in modes[::2]:
                v.scale(-1.0)
        out.append(craig_bampton(prob, 150000.0, 1e-3, condensation=cond,
                                 interface_modes=(fm, modes)))
        cond.destroy()
    assert out[0].metadata["n_modes"] >= 4
    for rm in out[1:]:
        for k in ("K", "M", "C", "reduced_frequencies"):
            assert np.array_equal(getattr(rm, k), getattr(out[0], k)), k
