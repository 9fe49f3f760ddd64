"""Elasticity and modal analysis: cantilever vs Euler–Bernoulli, P1 vs P2, eigenstrain load."""
import numpy as np
import pytest
from mpi4py import MPI

import dolfinx
import ufl

from fe_joint.case import Material
from fe_joint.fe.elasticity import assemble_eigenstrain_load, assemble_mass, assemble_stiffness, vector_space
from fe_joint.fe.modal import free_modes, solve_eigenproblem, to_hz, vec_values_at

MAT = Material()
L, H = 100.0, 5.0  # slender (L/h = 20): shear and rotary inertia change f1 by < 0.2 %


def euler_bernoulli_f1() -> float:
    """First bending frequency of a clamped-free beam, Hz."""
    inertia, area = H ** 4 / 12, H * H
    return 1.875104068711961 ** 2 / (2 * np.pi) * np.sqrt(MAT.young * inertia / (MAT.density * area * L ** 4))


def cantilever_f1(degree: int, n: tuple) -> tuple[float, int]:
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [L, H, H]], n, dolfinx.mesh.CellType.tetrahedron)
    V = vector_space(mesh, degree)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, facets), V)
    vals, _ = solve_eigenproblem(assemble_stiffness(V, MAT, [bc]), assemble_mass(V, MAT, [bc]), 2, 0.0)
    return to_hz(vals)[0], V.dofmap.index_map.size_global * 3


def test_cantilever_p2_first_bending_within_1_percent():
    f, _ = cantilever_f1(2, (40, 2, 2))
    assert abs(f / euler_bernoulli_f1() - 1) < 0.01


def test_p2_beats_p1_at_equal_dofs():
    f2, n2 = cantilever_f1(2, (20, 1, 1))
    f1, n1 = cantilever_f1(1, (40, 2, 2))
    assert n1 == n2  # same number of unknowns
    ref = euler_bernoulli_f1()
    assert abs(f2 / ref - 1) < 0.01
    assert abs(f1 / ref - 1) > 10 * abs(f2 / ref - 1)  # P1 shear-locks: > 10x the error of P2


def test_free_box_has_six_rigid_modes_and_m_orthonormal_modes():
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [L, H, H]], (10, 1, 1),
                                   dolfinx.mesh.CellType.tetrahedron)
    V = vector_space(mesh, 2)
    K, M = assemble_stiffness(V, MAT), assemble_mass(V, MAT)
    res = free_modes(K, M, n_elastic=4)
    assert res.n_rigid == 6
    assert np.all(np.abs(res.frequencies[:6]) < 1e-4 * res.frequencies[6])
    Mv = K.createVecLeft()
    G = np.empty((len(res.modes), len(res.modes)))
    for i, a in enumerate(res.modes):
        M.mult(a, Mv)
        G[i] = [Mv.dot(b) for b in res.modes]
    assert np.abs(G - np.eye(len(G))).max() < 1e-10
    # the first elastic pair is the bending doublet (square section): equal frequencies
    assert res.frequencies[7] == pytest.approx(res.frequencies[6], rel=1e-2)


def test_unpurified_eigenvectors_meet_the_residual_tolerance():
    """solve_eigenproblem leaves SLEPc's purification off: each returned pair must still have
    a relative residual ||K phi - lam M phi|| / ||K phi|| within the solver's tolerance (1e-8),
    and the pairs must be M-orthonormal (the Rayleigh-Ritz step)."""
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [L, H, H]], (12, 2, 2),
                                   dolfinx.mesh.CellType.tetrahedron)
    V = vector_space(mesh, 2)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda x: np.isclose(x[0], 0.0))
    bc = dolfinx.fem.dirichletbc(np.zeros(3), dolfinx.fem.locate_dofs_topological(V, 2, facets), V)
    K, M = assemble_stiffness(V, MAT, [bc]), assemble_mass(V, MAT, [bc])
    vals, vecs = solve_eigenproblem(K, M, 8, 0.0)
    Kv, Mv = K.createVecLeft(), K.createVecLeft()
    for lam, v in zip(vals, vecs):
        K.mult(v, Kv)
        M.mult(v, Mv)
        assert Mv.dot(v) == pytest.approx(1.0, abs=1e-10)
        Mv.scale(lam)
        Mv.axpy(-1.0, Kv)
        assert Mv.norm() <= 1e-8 * Kv.norm()


def test_eigenstrain_load_is_self_equilibrated():
    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [4, 3, 10]], (2, 2, 4),
                                   dolfinx.mesh.CellType.tetrahedron)
    V = vector_space(mesh, 2)
    dx = ufl.Measure("dx", domain=mesh)
    f = assemble_eigenstrain_load(V, MAT, dx)
    x = V.tabulate_dof_coordinates()
    n_own = V.dofmap.index_map.size_local
    fa = f.array.reshape(-1, 3)[:n_own]
    xo = x[:n_own]
    force = MPI.COMM_WORLD.allreduce(fa.sum(axis=0), op=MPI.SUM)
    moment = MPI.COMM_WORLD.allreduce(np.cross(xo, fa).sum(axis=0), op=MPI.SUM)
    scale = MPI.COMM_WORLD.allreduce(np.abs(fa).sum(), op=MPI.SUM)
    assert np.abs(force).max() < 1e-10 * scale
    assert np.abs(moment).max() < 1e-10 * scale * 10
    # total axial "pull": the load equals the stress of the unit eigenstrain, E(1-nu)/((1+nu)(1-2nu))
    # on the z-faces (x area 12 mm²): sum of f_z on the top face nodes
    top = np.isclose(xo[:, 2], 10.0)
    fz_top = MPI.COMM_WORLD.allreduce(fa[top, 2].sum(), op=MPI.SUM)
    lam, mu = MAT.lame
    assert fz_top == pytest.approx(-(lam + 2 * mu) * 12.0, rel=1e-10)


def test_material_rejects_bad_values():
    with pytest.raises(ValueError, match="poisson"):
        Material(poisson=0.5)
    with pytest.raises(ValueError, match="young"):
        Material(young=float("nan"))
