"""The stages of ``fe-joint run``: thin functions that call the packages and write artifacts.

Each function takes a :class:`~fe_joint.stages.StageContext`, runs on every MPI rank, writes its
artifacts on rank 0 and returns a small JSON-able summary (kept in the stage manifest and used
by the report).
"""
from __future__ import annotations

from .stages import StageContext


def stage_mesh(ctx: StageContext) -> dict:
    """Build the gmsh resonator, load it into dolfinx, write mesh.xdmf, pairs.csv, geometry.png."""
    from .mesh import load_resonator, write_mesh_artifacts
    fe = load_resonator(ctx.case.geometry, ctx.comm)
    stats = write_mesh_artifacts(fe, ctx.path("mesh"))
    ctx.print(f"[fe-joint] mesh: {stats.get('n_nodes')} nodes, {stats.get('n_cells')} cells, "
              f"{stats.get('n_pairs')} interface pairs")
    return stats


REGISTRY = {
    "mesh": stage_mesh,
}
