"""Bolt preload with interface contact: equilibrium, complementarity, symmetry, pressure peak."""
import numpy as np
import pytest
from mpi4py import MPI

from fe_joint.fe.box_joint import build_box_joint
from fe_joint.case import Material
from fe_joint.fe.mesh import load_resonator, mesh_from_data
from fe_joint.fe.preload import solve_preload
from fe_joint.model.interface_contact import (OPEN, TIED, lap_triangles, recover_pressure,
                                              solve_interface_contact)
from geometry.resonator import ResonatorParams

F = 30000.0
COARSE = ResonatorParams(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0)


@pytest.fixture(scope="module")
def box():
    data = build_box_joint()
    return data, solve_preload(mesh_from_data(data, MPI.COMM_WORLD), Material(), F)


@pytest.fixture(scope="module")
def resonator(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("preload")) if MPI.COMM_WORLD.size == 1 else None
    fe = load_resonator(COARSE, MPI.COMM_WORLD)
    return fe.data, solve_preload(fe, Material(), F, out_dir=out), out


def _mirror_index(xyz):
    key = {tuple(np.round(p[:2], 6)): i for i, p in enumerate(xyz)}
    return np.array([key[(round(p[0], 6), round(-p[1], 6) + 0.0)] for p in xyz])


@pytest.mark.parametrize("case", ["box", "resonator"])
def test_equilibrium_and_support_reactions(case, request):
    data, res = request.getfixturevalue(case)[:2]
    assert res.pair_normal_force.sum() == pytest.approx(F, rel=1e-6)
    assert res.pair_raw_force[:, 2].sum() == pytest.approx(F, rel=1e-6)  # before pressure recovery
    if case == "box":  # mirror symmetry about y = 0: no net interface shear in y
        assert abs(res.pair_raw_force[:, 1].sum()) < 1e-6 * F
    assert np.abs(res.support_reactions).max() < 1e-6 * F  # 3-2-1 support carries nothing
    # independent measure: axial force in the free shank span from the stress field
    assert res.shank_force == pytest.approx(F, rel=0.01)


@pytest.mark.parametrize("case", ["box", "resonator"])
def test_contact_complementarity(case, request):
    data, res = request.getfixturevalue(case)[:2]
    closed = res.closed
    assert 0 < closed.sum() < len(closed)
    assert np.all(res.pair_normal_force >= 0)  # no pair in tension
    assert np.all(res.pair_normal_force[~closed] == 0)
    raw_n = res.pair_raw_force[:, 2]
    tied = res.pair_status == TIED
    assert raw_n[tied].min() > -1e-9 * F  # tied pairs are not pulled
    assert np.all(res.pair_gap[closed] == 0)  # no closed pair with a gap
    assert np.all(res.pair_gap[~closed] > 0)  # open pairs are open, not penetrating


def test_box_pressure_mirror_symmetric_and_peaks_at_hole(box):
    data, res = box
    mir = _mirror_index(data.pair_xyz)
    p = res.pair_pressure
    assert np.abs(p - p[mir]).max() < 1e-6 * p.max()  # the fixture mesh is exactly mirror-symmetric
    dist_hole = np.max(np.abs(data.pair_xyz[:, :2]), axis=1) - data.params["hole_half"]
    assert dist_hole[np.argmax(p)] <= data.params["cell"] + 1e-9


def test_resonator_pressure_symmetric_and_peaks_next_to_hole(resonator):
    data, res, out = resonator
    xyz, N = data.pair_xyz, res.pair_normal_force
    # the lap faces are meshed mirror-symmetrically, the volume mesh only nearly so
    from scipy.spatial import cKDTree
    dist, mir = cKDTree(xyz[:, :2]).query(xyz[:, :2] * [1.0, -1.0])
    assert dist.max() < 1e-3
    p = res.pair_pressure
    assert np.linalg.norm(p - p[mir]) < 0.01 * np.linalg.norm(p)
    assert np.abs(p - p[mir]).max() < 0.02 * p.max()
    assert abs(np.sum(N * xyz[:, 1])) < 0.01 * np.sum(N * np.abs(xyz[:, 1]))  # no moment about x
    # (the y-halves' total loads differ by ~1 % on this coarse mesh: the lap triangulation, hence the
    # tributary areas, is not exactly mirrored even where the nodes are)
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    hole_r = COARSE.hole_diameter / 2
    assert r[np.argmax(res.pair_pressure)] < hole_r + 1.5 * COARSE.lap_mesh_size
    # falling toward the corners: mean pressure of the outer ring < a third of the inner ring
    inner = res.pair_pressure[r < hole_r + COARSE.lap_mesh_size].mean()
    outer = res.pair_pressure[r > 12.0].mean()
    assert outer < inner / 3
    if out is not None:
        import os
        assert os.path.getsize(os.path.join(out, "preload_pressure.png")) > 10000
        assert os.path.exists(os.path.join(out, "preload.xdmf"))


def test_pressure_recovery_exact_for_uniform_pressure(box):
    data, _ = box
    tri = lap_triangles(data)
    xyz = data.pair_xyz
    # consistent P2 nodal forces of p = 7 MPa: vertex 0, mid-edge 7 * A / 3 per triangle
    p3 = xyz[tri[:, :3]]
    area = 0.5 * np.linalg.norm(np.cross(p3[:, 1] - p3[:, 0], p3[:, 2] - p3[:, 0]), axis=1)
    F_nodes = np.zeros(len(xyz))
    np.add.at(F_nodes, tri[:, 3:].ravel(), np.repeat(7.0 * area / 3, 3))
    p = recover_pressure(tri, xyz, F_nodes)
    assert np.abs(p - 7.0).max() < 1e-12
    assert np.sum(p * data.pair_area) == pytest.approx(7.0 * area.sum(), rel=1e-12)


def test_contact_solver_two_springs_analytic():
    # two pairs between a rigid-ish block B (DOFs 3..5 / 9..11 tied by stiff springs) and ground A:
    # 1D check in z: pair 0 is pushed closed by f, pair 1 is pulled open
    k = 100.0
    n = 18  # DOFs 12..17: unloaded extra node(s) carrying the support
    S = np.eye(n) * k
    f = np.zeros(n)
    f[2], f[5] = 50.0, -50.0      # A0 pushed up into B0 (closing), B0 pushed down
    f[8], f[11] = -30.0, 30.0     # A1 pulled down, B1 pulled up: opening
    pa, pb = np.array([[0, 1, 2], [6, 7, 8]]), np.array([[3, 4, 5], [9, 10, 11]])
    sol = solve_interface_contact(S, f, pa, pb, support=np.arange(12, 18))
    assert list(sol.status) == [TIED, OPEN]
    assert sol.force[0, 2] == pytest.approx(50.0)        # the whole push goes through the contact
    assert sol.force[1, 2] == 0.0
    assert -sol.relative[1, 2] == pytest.approx(60.0 / k)  # gap = 30/k + 30/k


def test_toggling_pair_is_frozen_closed_untied():
    # one pair whose normal and tangential motion are coupled (W_xz != 0): tied, the shear tie pulls
    # it into tension (N < 0); released, it penetrates (d_z > 0) -> plain PDAS cycles forever
    W = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.0], [0.5, 0.0, 1.0]])
    d0 = np.array([1.0, 0.0, 0.1])
    S = np.eye(9)
    S[:3, :3] = np.linalg.inv(W)
    f = np.zeros(9)
    f[:3] = S[:3, :3] @ d0  # free A-node displacement = d0
    pa, pb = np.array([[0, 1, 2]]), np.array([[3, 4, 5]])
    sol = solve_interface_contact(S, f, pa, pb, support=np.array([3, 4, 5, 6, 7, 8]))
    assert sol.n_toggled == 1 and sol.status[0] == 2  # closed, untied
    assert sol.force[0, 2] == pytest.approx(0.1 / W[2, 2])  # closes the normal gap exactly
    assert sol.force[0, 0] == 0.0 and sol.force[0, 1] == 0.0
    assert sol.relative[0, 2] == pytest.approx(0.0, abs=1e-14)
