"""geometry.resonator: volumes, matched lap pairs, tributary areas, connectivity, validation."""
import dataclasses
import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from geometry import (HEAD, LAP_A, LAP_B, MARKER_NAMES, NUT, PART_A, PART_B, SHANK, WASHER_HEAD,
                      WASHER_NUT, ResonatorParams, build_resonator, cell_volumes, scaled_jacobian,
                      nominal_interface_area, nominal_volumes)

COARSE = ResonatorParams(lap_mesh_size=4.0, body_mesh_size=14.0, leaf_mesh_size=6.0)


@pytest.fixture(scope="module")
def default_mesh():
    return build_resonator(ResonatorParams())


@pytest.fixture(scope="module")
def coarse_mesh():
    return build_resonator(COARSE)


def _tri_area(x, tri):
    """Area of planar tri3/tri6 triangles: straight triangle plus, for each curved (parabolic)
    edge with chord c and mid-node offset d, the segment area -(2/3) (c x d)·n (Green's theorem)."""
    v0, v1, v2 = (x[tri[:, k]] for k in range(3))
    cr = np.cross(v1 - v0, v2 - v0)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    if tri.shape[1] == 6:
        n = cr / np.linalg.norm(cr, axis=1)[:, None]
        for i, j, m in ((0, 1, 3), (1, 2, 4), (2, 0, 5)):
            c = x[tri[:, j]] - x[tri[:, i]]
            d = x[tri[:, m]] - 0.5 * (x[tri[:, i]] + x[tri[:, j]])
            area -= (2 / 3) * np.einsum("ni,ni->n", np.cross(c, d), n)
    return area


def test_nominal_volumes_by_hand():
    # hand calculation for the default parameters (mm³)
    hole = math.pi * 4.25 ** 2 * 8
    v = nominal_volumes(ResonatorParams())
    assert v["part_a"] == pytest.approx(40 * 20 * 8 - hole + 8 * 20 * 40 + 50 ** 3, rel=1e-12)
    assert v["part_b"] == pytest.approx(35 * 20 * 8 - hole + 50 ** 3, rel=1e-12)
    assert v["shank"] == pytest.approx(math.pi * 16 * 22.5, rel=1e-12)
    assert v["head"] == pytest.approx(math.pi * 6.5 ** 2 * 5.3, rel=1e-12)
    assert v["nut"] == pytest.approx(math.pi * (6.5 ** 2 - 16) * 6.5, rel=1e-12)


@pytest.mark.parametrize("which", ["default", "coarse"])
def test_volumes_per_part(which, default_mesh, coarse_mesh):
    m = default_mesh if which == "default" else coarse_mesh
    vol = cell_volumes(m.points, m.cells)
    assert vol.min() > 0  # positively oriented, no inverted curved cells
    nominal = nominal_volumes(m.params)
    for marker, name in MARKER_NAMES.items():
        got = vol[m.cell_markers == marker].sum()
        assert got == pytest.approx(nominal[name], rel=1e-2), name


def test_cell_volumes_p2_exact_on_curved_tet():
    # the quadratic map z -> z + c*x*z (exactly P2) has det J = 1 + c*x: volume 1/6 + c*∫x = 1/6 + c/24
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    edges = [(0, 1), (1, 2), (2, 0), (3, 0), (3, 2), (3, 1)]
    x = np.vstack([v] + [0.5 * (v[i] + v[j]) for i, j in edges])
    c = 0.3
    x[:, 2] += c * x[:, 0] * x[:, 2]
    got = cell_volumes(x, np.arange(10)[None, :])[0]
    assert got == pytest.approx(1 / 6 + c / 24, rel=1e-12)


def test_pair_count_default(default_mesh):
    # paper's converged count 340; the default lap size 2.8 mm must land within ±5 %
    assert abs(default_mesh.n_pairs - 340) <= 0.05 * 340


@pytest.mark.parametrize("which", ["default", "coarse"])
def test_pairs_coincide_and_areas_sum(which, default_mesh, coarse_mesh):
    m = default_mesh if which == "default" else coarse_mesh
    a, b = m.pair_nodes[:, 0], m.pair_nodes[:, 1]
    assert np.max(np.abs(m.points[a] - m.points[b])) <= 1e-12
    assert np.array_equal(m.pair_xyz, m.points[a])
    assert np.all(a != b)
    assert len(np.unique(a)) == len(a) and len(np.unique(b)) == len(b)
    p = m.params
    assert np.all(m.pair_xyz[:, 2] == 0.0)
    assert np.all(np.abs(m.pair_xyz[:, 0]) <= p.overlap / 2 + 1e-12)
    assert np.all(np.abs(m.pair_xyz[:, 1]) <= p.plate_width / 2 + 1e-12)
    r = np.hypot(m.pair_xyz[:, 0], m.pair_xyz[:, 1])
    assert r.min() >= p.hole_diameter / 2 - 1e-9
    assert np.all(m.pair_area > 0)
    area = p.overlap * p.plate_width - math.pi * (p.hole_diameter / 2) ** 2
    assert m.pair_area.sum() == pytest.approx(area, rel=1e-2)
    assert nominal_interface_area(p) == pytest.approx(area, rel=1e-14)
    # the pairs are exactly the nodes of the two lap faces
    lap_a = np.unique(m.facets[m.facet_markers == LAP_A])
    lap_b = np.unique(m.facets[m.facet_markers == LAP_B])
    assert np.array_equal(np.sort(a), lap_a) and np.array_equal(np.sort(b), lap_b)
    # the triangles of lap B, mapped through the pairs, are those of lap A (identical meshes)
    pos = np.full(len(m.points), -1)
    pos[b] = a
    tri_b = pos[m.facets[m.facet_markers == LAP_B]]
    tri_a = m.facets[m.facet_markers == LAP_A]
    assert np.array_equal(np.unique(np.sort(tri_a, axis=1), axis=0),
                          np.unique(np.sort(tri_b, axis=1), axis=0))
    assert len(tri_a) == len(tri_b)


def test_tributary_split_vertex_twelfth_midedge_quarter(coarse_mesh):
    # independent recomputation (exact curved-triangle areas): vertices A/12, mid-edge nodes A/4
    m = coarse_mesh
    tri = m.facets[m.facet_markers == LAP_A]
    area = _tri_area(m.points, tri)
    ref = np.zeros(len(m.points))
    for k in range(3):
        np.add.at(ref, tri[:, k], area / 12)
        np.add.at(ref, tri[:, 3 + k], area / 4)
    np.testing.assert_allclose(m.pair_area, ref[m.pair_nodes[:, 0]], rtol=1e-10)
    assert np.isclose(m.pair_area.sum(), area.sum(), rtol=1e-12)


def test_order1_areas_and_volumes():
    p = dataclasses.replace(COARSE, order=1, hole_mesh_size=1.0)
    m = build_resonator(p)
    assert m.cells.shape[1] == 4 and m.facets.shape[1] == 3
    assert m.pair_area.sum() == pytest.approx(nominal_interface_area(p), rel=1e-2)
    vol = cell_volumes(m.points, m.cells)
    assert vol.sum() == pytest.approx(nominal_volumes(p)["total"], rel=1e-2)
    assert np.max(np.abs(m.points[m.pair_nodes[:, 0]] - m.points[m.pair_nodes[:, 1]])) <= 1e-12


def test_one_body_through_bolt_cut_at_lap(coarse_mesh):
    m = coarse_mesh
    n = len(m.points)
    # node graph through the cells
    rows = np.repeat(np.arange(len(m.cells)), m.cells.shape[1])
    g = coo_matrix((np.ones(rows.size), (rows, m.cells.ravel())), shape=(len(m.cells), n)).tocsr()
    adj = (g.T @ g).tocsr()
    ncomp, _ = connected_components(adj, directed=False)
    assert ncomp == 1  # A - nut annulus - nut - shank - head - plate B
    nodes = {k: np.unique(m.cells[m.cell_markers == k]) for k in MARKER_NAMES}
    assert np.intersect1d(nodes[PART_A], nodes[PART_B]).size == 0  # lap faces not connected
    # the nut shares exactly the (merged) washer annulus nodes with part A
    shared = np.intersect1d(nodes[PART_A], nodes[NUT])
    washer = np.unique(m.facets[m.facet_markers == WASHER_NUT])
    assert np.array_equal(shared, washer) and shared.size > 0
    assert np.intersect1d(nodes[PART_A], nodes[SHANK]).size == 0  # clearance in the hole
    assert np.intersect1d(nodes[HEAD], nodes[PART_B]).size > 0
    # the only coincident nodes left in the mesh are the lap pairs
    _, cnt = np.unique(np.round(m.points, 9), axis=0, return_counts=True)
    assert (cnt == 2).sum() == m.n_pairs and cnt.max() == 2


def test_washer_faces_and_excitation(coarse_mesh):
    m = coarse_mesh
    p = m.params
    t = p.plate_thickness
    r_h = p.hole_diameter / 2
    for marker, z, d in ((WASHER_HEAD, t, p.head_diameter), (WASHER_NUT, -t, p.nut_diameter)):
        tri = m.facets[m.facet_markers == marker]
        assert np.allclose(m.points[tri][..., 2], z, atol=1e-12)
        ring = math.pi * ((d / 2) ** 2 - r_h ** 2)
        assert _tri_area(m.points, tri).sum() == pytest.approx(ring, rel=1e-2)
    leaf_x0 = -p.overlap / 2 - p.plate_a_extension
    xc = leaf_x0 + p.leaf_thickness / 2
    zc = -t - p.leaf_length - p.mass_a_size / 2
    np.testing.assert_allclose(m.points[m.excitation_node], [xc - p.mass_a_size / 2, 0.0, zc],
                               atol=1e-12)
    assert m.excitation_node in m.cells[m.cell_markers == PART_A]


def test_reproducible(coarse_mesh):
    # same seed, same mesh: topology identical; gmsh's elastic high-order optimisation keeps
    # some state between sessions in one process (differences ~1e-10 mm after another build)
    again = build_resonator(COARSE)
    np.testing.assert_allclose(again.points, coarse_mesh.points, rtol=0, atol=1e-8)
    assert np.array_equal(again.cells, coarse_mesh.cells)
    assert np.array_equal(again.pair_nodes, coarse_mesh.pair_nodes)


@pytest.mark.parametrize("kw, name", [
    (dict(hole_diameter=21.0), "hole_diameter"),
    (dict(shank_diameter=8.6), "shank_diameter"),
    (dict(head_diameter=8.0), "head_diameter"),
    (dict(nut_diameter=25.0), "nut_diameter"),
    (dict(plate_thickness=-1.0), "plate_thickness"),
    (dict(overlap=float("nan")), "overlap"),
    (dict(leaf_length=float("inf")), "leaf_length"),
    (dict(order=3), "order"),
    (dict(leaf_thickness=30.0), "leaf_thickness"),
    (dict(mass_b_size=10.0), "mass_b_size"),
    (dict(lap_mesh_size=20.0), "lap_mesh_size"),
    (dict(hole_mesh_size=0.0), "hole_mesh_size"),
    (dict(leaf_length=5.0), "leaf_length"),
])
def test_validation_names_field(kw, name):
    with pytest.raises(ValueError, match=name):
        build_resonator(ResonatorParams(**kw))


def test_scaled_jacobian_detects_inverted_cell_and_mesh_is_valid(default_mesh, coarse_mesh):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    edges = [(0, 1), (1, 2), (2, 0), (3, 0), (3, 2), (3, 1)]
    x = np.vstack([v] + [0.5 * (v[i] + v[j]) for i, j in edges])
    cell = np.arange(10)[None, :]
    assert scaled_jacobian(x, cell)[0] == pytest.approx(1.0, abs=1e-14)
    x[4] = [0.2, 0.0, 0.0]  # mid-node of edge 01 pulled towards vertex 0
    # along edge 01 the P2 map is x(r) = r(2r - 1) + 4 r (1 - r) * 0.2; dx/dr(1) = 3 - 0.8 = 2.2,
    # dx/dr(0) = -1 + 0.8 = -0.2 < 0: inverted at vertex 0 with det J / det J_lin = -0.2
    assert scaled_jacobian(x, cell)[0] == pytest.approx(-0.2, abs=1e-12)
    for m in (default_mesh, coarse_mesh):
        assert scaled_jacobian(m.points, m.cells).min() > 0.05


@pytest.mark.parametrize("kw", [dict(head_diameter=14.0, nut_diameter=12.0),
                                dict(head_diameter=12.0, nut_diameter=14.0, overlap=24.0,
                                     plate_width=22.0, hole_diameter=9.0)])
def test_variant_geometries(kw):
    # head and nut of different sizes split the lap faces at three radii: still matched pairs
    p = dataclasses.replace(COARSE, **kw)
    m = build_resonator(p)
    vol = cell_volumes(m.points, m.cells)
    nominal = nominal_volumes(p)
    for marker, name in MARKER_NAMES.items():
        assert vol[m.cell_markers == marker].sum() == pytest.approx(nominal[name], rel=1e-2), name
    assert np.max(np.abs(m.points[m.pair_nodes[:, 0]] - m.points[m.pair_nodes[:, 1]])) <= 1e-12
    area = p.overlap * p.plate_width - math.pi * (p.hole_diameter / 2) ** 2
    assert m.pair_area.sum() == pytest.approx(area, rel=1e-2)
    washer = math.pi * ((p.nut_diameter / 2) ** 2 - (p.hole_diameter / 2) ** 2)
    assert _tri_area(m.points, m.facets[m.facet_markers == WASHER_NUT]).sum() == pytest.approx(
        washer, rel=1e-2)
