"""Bolt preload on the distributed FE model: assemble, condense, solve the interface contact
(:mod:`fe_joint.model.interface_contact`), expand, check the shank force, write the fields.

The method is described in :mod:`fe_joint.model.interface_contact` and docs/design.md.
"""
from __future__ import annotations

import numpy as np

from ..model.interface_contact import OPEN, PreloadResult, preload_from_condensed
from .assembly import assemble_joint, shank_axial_force
from .condensation import BoundaryCondensation
from .output import write_preload_fields


def solve_preload(fe, material, preload: float, comm=None, out_dir: str | None = None,
                  problem=None, condensation=None) -> PreloadResult:
    """Bolt preload of the joint with interface contact (the whole chain on a distributed mesh).

    Args:
        fe: JointFE / ResonatorFE (mesh, cell_tags, data).
        material: elasticity.Material.
        preload: target bolt force, N (> 0).
        comm: unused (the mesh carries its communicator); kept for the public signature.
        out_dir: if given, write ``preload.xdmf`` (displacement, von Mises, interface pressure) and
            ``preload_pressure.png`` there (rank 0 writes the PNG).
        problem: an already assembled JointProblem (else assembled here).
        condensation: an existing BoundaryCondensation on ``problem.layout.dofs`` (else built here).

    Returns:
        PreloadResult (identical on every rank).
    """
    if not (np.isfinite(preload) and preload > 0):
        raise ValueError(f"preload must be a finite bolt force > 0 N, got {preload}")
    if problem is None:
        problem = assemble_joint(fe, material, with_mass=False)
    own = condensation is None
    if own:
        condensation = BoundaryCondensation(problem.K, None, problem.layout.dofs)
        S = condensation.condense()["K_BB"]
    else:
        S = condensation.condensed["K_BB"]
    f_b = condensation.condense_load(problem.f_eig)
    s, sol, pressure, force = preload_from_condensed(S, f_b, problem.layout, fe.data, preload)
    f_full = problem.f_eig.copy()
    f_full.scale(s)
    u_vec = condensation.expand(sol.u, f_full)
    import dolfinx
    u = dolfinx.fem.Function(problem.V, name="displacement")
    u.vector.array[:] = u_vec.array
    u.x.scatter_forward()
    shank = shank_axial_force(problem, u, s)
    gap = np.maximum(-sol.relative[:, 2], 0.0)
    gap[sol.status != OPEN] = 0.0
    res = PreloadResult(bolt_force=float(force.sum()), eigenstrain=float(s), shank_force=float(shank),
                        pair_normal_force=force, pair_pressure=pressure, pair_gap=gap,
                        pair_raw_force=sol.force, pair_status=sol.status, support_reactions=sol.reactions,
                        u_boundary=sol.u, iterations=sol.iterations, n_toggled=sol.n_toggled,
                        displacement=u)
    if out_dir is not None:
        write_preload_fields(problem, res, out_dir)
    if own:
        condensation.destroy()
    return res
