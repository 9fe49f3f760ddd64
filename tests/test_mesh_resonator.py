"""fe_joint.fe.mesh: the resonator in dolfinx (serial and mpirun -n 2)."""
import csv
import math
from pathlib import Path

import numpy as np
import pytest
import ufl
from mpi4py import MPI

import dolfinx
from fe_joint.fe.mesh import load_resonator, original_node_dofs
from fe_joint.fe.output import write_mesh_artifacts
from geometry import (LAP_A, LAP_B, MARKER_NAMES, WASHER_HEAD, ResonatorParams, cell_volumes,
                      nominal_interface_area, nominal_volumes)

COARSE = ResonatorParams(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0)
COMM = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def fe():
    return load_resonator(COARSE, COMM)


def _integrate(fe, integrand):
    return COMM.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand)), op=MPI.SUM)


@pytest.mark.mpi
def test_volumes_dolfinx_vs_nominal_and_serial(fe):
    dx = ufl.Measure("dx", domain=fe.mesh, subdomain_data=fe.cell_tags,
                     metadata={"quadrature_degree": 3})  # det J of a P2 map is cubic: exact
    one = dolfinx.fem.Constant(fe.mesh, 1.0)
    nominal = nominal_volumes(COARSE)
    # serial reference: the undistributed numpy mesh (identical on every rank)
    serial = cell_volumes(fe.data.points, fe.data.cells)
    total = 0.0
    for marker, name in MARKER_NAMES.items():
        v = _integrate(fe, one * dx(marker))
        total += v
        assert v == pytest.approx(nominal[name], rel=1e-2), name
        assert v == pytest.approx(serial[fe.data.cell_markers == marker].sum(), rel=1e-10), name
    assert total == pytest.approx(_integrate(fe, one * dx), rel=1e-12)
    assert total == pytest.approx(nominal["total"], rel=1e-3)


@pytest.mark.mpi
def test_facet_tags_areas(fe):
    ds = ufl.Measure("ds", domain=fe.mesh, subdomain_data=fe.facet_tags)
    dS = ufl.Measure("dS", domain=fe.mesh, subdomain_data=fe.facet_tags)
    one = dolfinx.fem.Constant(fe.mesh, 1.0)
    lap = nominal_interface_area(COARSE)
    assert _integrate(fe, one * ds(LAP_A)) == pytest.approx(lap, rel=1e-3)
    assert _integrate(fe, one * ds(LAP_B)) == pytest.approx(lap, rel=1e-3)
    p = COARSE
    ring = math.pi * ((p.head_diameter / 2) ** 2 - (p.hole_diameter / 2) ** 2)
    assert _integrate(fe, one("+") * dS(WASHER_HEAD)) == pytest.approx(ring, rel=1e-3)
    # tributary areas sum to the lap area integrated by dolfinx
    assert fe.data.pair_area.sum() == pytest.approx(lap, rel=1e-3)


@pytest.mark.mpi
@pytest.mark.parametrize("degree", [2, 1])
def test_original_node_dofs_coordinates(fe, degree):
    V = dolfinx.fem.VectorFunctionSpace(fe.mesh, ("Lagrange", degree))
    xdof = V.tabulate_dof_coordinates()
    d = fe.data
    if degree == 2:
        nodes = np.concatenate([d.pair_nodes[:, 0], d.pair_nodes[:, 1], [d.excitation_node]])
        xyz = np.vstack([d.pair_xyz, d.pair_xyz, d.points[d.excitation_node]])
    else:  # P1: only the vertices carry dofs; take the lap vertices
        tri = d.facets[d.facet_markers == LAP_A][:, :3]
        nodes = np.unique(tri)
        xyz = d.points[nodes]
    blk, owned = original_node_dofs(V, nodes, return_owned=True)
    held = blk >= 0
    assert np.max(np.abs(xdof[blk[held]] - xyz[held]), initial=0.0) <= 1e-12
    # every node is owned by exactly one rank
    count = COMM.allreduce(owned.astype(np.int64), op=MPI.SUM)
    np.testing.assert_array_equal(count, 1)
    # a node that does not exist is -1 everywhere
    assert original_node_dofs(V, np.array([len(d.points) + 5]))[0] == -1


def test_original_node_dofs_mid_edge_on_p1_space(fe):
    V = dolfinx.fem.FunctionSpace(fe.mesh, ("Lagrange", 1))
    mid = np.unique(fe.data.facets[fe.data.facet_markers == LAP_A][:, 3:])
    assert np.all(original_node_dofs(V, mid) == -1)  # P1 has no dofs at mid-edge nodes
    with pytest.raises(ValueError, match="original_nodes"):
        original_node_dofs(V, np.array([[1, 2]]))


@pytest.mark.mpi
def test_write_mesh_artifacts(fe, tmp_path):
    out = Path(COMM.bcast(str(tmp_path), root=0))
    stats = write_mesh_artifacts(fe, out)
    d = fe.data
    assert stats["n_nodes"] == len(d.points)
    assert stats["n_cells"] == len(d.cells)
    assert stats["n_dofs"] == 3 * len(d.points)  # P2 mesh: one vector P2 node per geometry node
    assert stats["n_pairs"] == d.n_pairs
    assert stats["volumes"]["total"] == pytest.approx(nominal_volumes(COARSE)["total"], rel=1e-3)
    if COMM.rank == 0:
        for f in ("mesh.xdmf", "mesh.h5", "geometry.png", "pairs.csv", "mesh.json"):
            assert (out / f).stat().st_size > 0, f
        with open(out / "pairs.csv") as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == d.n_pairs
        xyz = np.array([[float(r["x"]), float(r["y"]), float(r["z"])] for r in rows])
        np.testing.assert_allclose(xyz, d.pair_xyz, atol=1e-9)
        assert sum(float(r["area"]) for r in rows) == pytest.approx(
            nominal_interface_area(COARSE), rel=1e-2)


def test_invalid_params_raise_before_gmsh():
    with pytest.raises(ValueError, match="hole_diameter"):
        load_resonator(ResonatorParams(hole_diameter=21.0), COMM)
