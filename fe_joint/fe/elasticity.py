"""Linear isotropic elasticity in dolfinx 0.5.2: stiffness, mass, eigenstrain load, stresses.

Units N, mm, s, tonne: E in MPa, density in t/mm³, so K is N/mm, M is t and frequencies are Hz.
"""
from __future__ import annotations

import numpy as np
import ufl
from petsc4py import PETSc

import dolfinx
import dolfinx.fem.petsc

from ..case.schema import Material


def vector_space(mesh: "dolfinx.mesh.Mesh", degree: int = 2) -> "dolfinx.fem.FunctionSpace":
    """Continuous Lagrange vector space of the given degree (1 or 2)."""
    if degree not in (1, 2):
        raise ValueError(f"degree must be 1 or 2, got {degree}")
    return dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", degree))


def strain(u):
    """Small strain tensor sym(grad u)."""
    return ufl.sym(ufl.grad(u))


def stress(eps, material: Material):
    """Hooke's law sigma = lambda tr(eps) I + 2 mu eps (MPa)."""
    lam, mu = material.lame
    return lam * ufl.tr(eps) * ufl.Identity(3) + 2 * mu * eps


def assemble_stiffness(V, material: Material, bcs=()) -> PETSc.Mat:
    """Assemble the stiffness matrix K (N/mm); Dirichlet rows/columns get 1 on the diagonal."""
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = dolfinx.fem.form(ufl.inner(stress(strain(u), material), strain(v)) * ufl.dx)
    K = dolfinx.fem.petsc.assemble_matrix(a, bcs=list(bcs), diagonal=1.0)
    K.assemble()
    return K


def assemble_mass(V, material: Material, bcs=()) -> PETSc.Mat:
    """Assemble the consistent mass matrix M (t); Dirichlet rows get 0 on the diagonal (modes at infinity)."""
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    m = dolfinx.fem.form(material.density * ufl.inner(u, v) * ufl.dx)
    M = dolfinx.fem.petsc.assemble_matrix(m, bcs=list(bcs), diagonal=0.0)
    M.assemble()
    return M


def axial_eigenstrain(axis=(0.0, 0.0, 1.0)):
    """Unit shortening eigenstrain -a⊗a along the bolt axis (dimensionless)."""
    a = ufl.as_vector(np.asarray(axis, dtype=float) / np.linalg.norm(axis))
    return -ufl.outer(a, a)


def assemble_eigenstrain_load(V, material: Material, dx_region, axis=(0.0, 0.0, 1.0)) -> PETSc.Vec:
    """Load vector f(v) = ∫ C:eps0 : eps(v) of a unit axial shortening eigenstrain over a region (N).

    The load is self-equilibrated: it does no work on rigid-body motions.
    """
    v = ufl.TestFunction(V)
    L = dolfinx.fem.form(ufl.inner(stress(axial_eigenstrain(axis), material), strain(v)) * dx_region)
    f = dolfinx.fem.petsc.assemble_vector(L)
    f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return f


def von_mises_dg0(u, material: Material, eigen_scale: float = 0.0, dx_eig_marker=None, cell_tags=None):
    """Cell-wise von Mises stress (MPa) as a DG0 function.

    Args:
        u: displacement function (mm).
        material: material.
        eigen_scale: eigenstrain magnitude applied on cells tagged ``dx_eig_marker`` (sigma = C:(eps - eps0)).
        dx_eig_marker: cell marker carrying the eigenstrain (e.g. 3, bolt shank), or None.
        cell_tags: the cell MeshTags (needed with ``dx_eig_marker``).
    """
    mesh = u.function_space.mesh
    W = dolfinx.fem.FunctionSpace(mesh, ("DG", 0))
    eps = strain(u)
    if dx_eig_marker is not None and eigen_scale != 0.0:
        ind = dolfinx.fem.Function(W)
        ind.x.array[:] = 0.0
        cells = cell_tags.indices[cell_tags.values == dx_eig_marker]
        ind.x.array[cells] = 1.0
        eps = eps - eigen_scale * ind * axial_eigenstrain()
    s = stress(eps, material)
    sdev = s - ufl.tr(s) / 3 * ufl.Identity(3)
    vm = ufl.sqrt(1.5 * ufl.inner(sdev, sdev))
    out = dolfinx.fem.Function(W, name="von_mises")
    out.interpolate(dolfinx.fem.Expression(vm, W.element.interpolation_points()))
    return out
