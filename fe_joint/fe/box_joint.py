"""A small bolted lap joint built from structured boxes: the test and benchmark fixture of the FE chain.

It reproduces the topology of the gmsh resonator (``geometry.resonator``) with none of its
meshing traps, so the FE physics can be tested on coarse meshes in seconds:

* plate A (marker 1) occupies z in [-T, 0], plate B (marker 2) z in [0, T], both over the square
  [-a, a]^2 minus a square hole of half-width ``hole_half``;
* a square shank (marker 3) of half-width ``shank_half`` crosses both plates without touching
  them (clearance = the rest of the hole); a head (marker 4) fills the hole over the top layer of
  plate B and a nut (marker 5) the bottom layer of plate A, so the structure is held together only
  by the bolt;
* the lap faces (z = 0 outside the hole) carry duplicated, coincident P2 nodes: the matched pairs.

The hexahedra are split into 6 tetrahedra (Kuhn split) mirrored about y = 0, so the mesh and
every field on it are mirror-symmetric about the plane y = 0. Nodes are numbered like gmsh
(tet10 / tri6 in gmsh order) and the result is a ``geometry.resonator.ResonatorMesh`` (its
``params`` is a dict of the fixture's lengths instead of ``ResonatorParams``), so
``fe_joint.fe.mesh.mesh_from_data`` distributes it like the real resonator.
"""
from __future__ import annotations

import numpy as np

from geometry.resonator import ResonatorMesh

# gmsh tet10 edge order: nodes 4..9 sit on edges (0,1), (1,2), (2,0), (3,0), (3,2), (3,1)
_TET10_EDGES = np.array([[0, 1], [1, 2], [2, 0], [3, 0], [3, 2], [3, 1]])
# gmsh tri6 edge order: nodes 3..5 on edges (0,1), (1,2), (2,0)
_TRI6_EDGES = np.array([[0, 1], [1, 2], [2, 0]])
# faces of a tet (vertex triplets) and, for each, the tet10 local indices of the tri6 nodes
_TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])


def _kuhn_tets(nx: int, ny: int, nz: int) -> np.ndarray:
    """Tet vertex connectivity of an (nx, ny, nz) hex grid, Kuhn split mirrored about the y midplane.

    Returns:
        (6 * nx * ny * nz, 4) grid-vertex indices (i * (ny+1) + j) * (nz+1) + k; the tets of hex h
        are rows 6h..6h+5.
    """
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    mirror = (j < ny // 2)  # lower half in y: mirror the local y bit so the split is symmetric

    def vid(a, b, c):
        bb = np.where(mirror, 1 - b, b)
        return ((i + a) * (ny + 1) + (j + bb)) * (nz + 1) + (k + c)

    tets = []
    for perm in ([0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]):
        bits = [0, 0, 0]
        path = [vid(*bits)]
        for ax in perm:
            bits[ax] = 1
            path.append(vid(*bits))
        tets.append(np.stack(path, axis=1))
    return np.stack(tets, axis=1).reshape(-1, 4)


def _check_lengths(half, thickness, cell, shank_half, hole_half, head) -> None:
    for name, val in (("half", half), ("thickness", thickness), ("cell", cell),
                      ("shank_half", shank_half), ("hole_half", hole_half), ("head", head)):
        if not np.isfinite(val) or val <= 0:
            raise ValueError(f"{name} must be a finite positive length in mm, got {val}")
    if not shank_half < hole_half < half or not head < thickness:
        raise ValueError("need 0 < shank_half < hole_half < half and head < thickness")


def _marked_tets(pts, nx, ny, nz, thickness, shank_half, hole_half, head):
    """Kuhn tets of the hex grid with part markers; the hole's empty annulus removed."""
    tets = _kuhn_tets(nx, ny, nz)
    hc = pts[tets].mean(axis=1)  # tet centroid; classify by the centroid of its hex instead:
    hex_c = hc.reshape(-1, 6, 3).mean(axis=1).repeat(6, axis=0)
    in_hole = (np.abs(hex_c[:, 0]) < hole_half) & (np.abs(hex_c[:, 1]) < hole_half)
    in_shank = (np.abs(hex_c[:, 0]) < shank_half) & (np.abs(hex_c[:, 1]) < shank_half)
    zc = hex_c[:, 2]
    marker = np.where(zc < 0, 1, 2)
    marker = np.where(in_hole & (zc > thickness - head), 4, marker)
    marker = np.where(in_hole & (zc < -(thickness - head)), 5, marker)
    mid = in_hole & (np.abs(zc) < thickness - head)
    marker = np.where(mid & in_shank, 3, marker)
    keep = ~(mid & ~in_shank)
    return tets[keep], marker[keep]


def _tet10(pts, tets):
    """Tet10 cells (one node per unique edge), unused nodes dropped and renumbered."""
    edges = np.sort(tets[:, _TET10_EDGES], axis=2).reshape(-1, 2)
    uedges, inv = np.unique(edges, axis=0, return_inverse=True)
    mid_pts = 0.5 * (pts[uedges[:, 0]] + pts[uedges[:, 1]])
    cells = np.hstack([tets, len(pts) + inv.reshape(-1, 6)])
    pts = np.vstack([pts, mid_pts])
    used = np.unique(cells)
    remap = -np.ones(len(pts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return pts[used], remap[cells]


def _split_lap(pts, cells, marker, on_plane):
    """Duplicate the lap nodes used by plate B (B gets copies); pairs in x-then-y order.

    Returns:
        (points, cells, pair_nodes, copy: original node → its B copy or -1).
    """
    b_nodes = np.unique(cells[marker == 2])
    lap_b_src = b_nodes[on_plane[b_nodes]]
    copy = -np.ones(len(pts), dtype=np.int64)
    copy[lap_b_src] = len(pts) + np.arange(len(lap_b_src))
    cb = cells[marker == 2]
    cells[marker == 2] = np.where(copy[cb] >= 0, copy[cb], cb)
    pts = np.vstack([pts, pts[lap_b_src]])
    pair_nodes = np.stack([lap_b_src, copy[lap_b_src]], axis=1)
    # canonical pair order: by x then y (independent of numbering details)
    order = np.lexsort((pts[pair_nodes[:, 0], 1], pts[pair_nodes[:, 0], 0]))
    return pts, cells, pair_nodes[order], copy


def _lap_facets(pts, cells, marker, on_plane, copy):
    """Tri6 lap facets of plate A (tet faces with three vertices on z = 0) and their B copies."""
    a_cells = cells[marker == 1]
    faces = a_cells[:, _TET_FACES]  # (nA, 4, 3)
    flat = np.all(on_plane[faces], axis=2)
    tri_v = faces[flat]
    # mid-edge nodes through the global edge -> node map of the A cells
    cell_edges = np.sort(np.stack([a_cells[:, _TET10_EDGES[:, 0]], a_cells[:, _TET10_EDGES[:, 1]]],
                                  axis=2), axis=2).reshape(-1, 2)
    cell_edge_nodes = a_cells[:, 4:].ravel()
    key = cell_edges[:, 0] * len(pts) + cell_edges[:, 1]
    ukey, first = np.unique(key, return_index=True)
    tri_e = np.sort(tri_v[:, _TRI6_EDGES], axis=2)
    tkey = tri_e[:, :, 0] * len(pts) + tri_e[:, :, 1]
    tri_m = cell_edge_nodes[first[np.searchsorted(ukey, tkey)]]
    tri_a = np.hstack([tri_v, tri_m])
    tri_b = np.where(copy[tri_a] >= 0, copy[tri_a], tri_a)
    return tri_a, tri_b


def _tributary_areas(pts, tri_a, pair_a):
    """Pair areas: vertex A/12, mid-edge A/4 of each lap triangle, mm²."""
    p = pts[tri_a]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    node_area = np.zeros(len(pts))
    np.add.at(node_area, tri_a[:, :3], (area / 12)[:, None])
    np.add.at(node_area, tri_a[:, 3:], (area / 4)[:, None])
    return node_area[pair_a]


def build_box_joint(half: float = 10.0, thickness: float = 4.0, cell: float = 2.0,
                    shank_half: float = 2.0, hole_half: float = 4.0,
                    head: float | None = None) -> ResonatorMesh:
    """Build the structured bolted-lap-joint fixture.

    Args:
        half: half side of the square plates, mm.
        thickness: thickness T of each plate, mm (multiple of ``cell``).
        cell: hexahedron edge length, mm (divides every other length).
        shank_half: half width of the square shank, mm.
        hole_half: half width of the square hole (> shank_half), mm.
        head: thickness of head and nut layers, mm (default ``cell``; < thickness).

    Returns:
        ResonatorMesh with tet10 cells, tri6 lap facets (11 A, 12 B), matched pairs (x-then-y order),
        tributary areas (vertex A/12, mid-edge A/4), excitation/response nodes on plate A.
    """
    head = cell if head is None else head
    _check_lengths(half, thickness, cell, shank_half, hole_half, head)
    nx = ny = int(round(2 * half / cell))
    nz = int(round(2 * thickness / cell))
    if nz % 2 or ny % 2:
        raise ValueError("cell must divide half and thickness into whole cells")
    xs = np.linspace(-half, half, nx + 1)
    zs = np.linspace(-thickness, thickness, nz + 1)
    gx, gy, gz = np.meshgrid(xs, xs, zs, indexing="ij")
    pts = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    tets, marker = _marked_tets(pts, nx, ny, nz, thickness, shank_half, hole_half, head)
    pts, cells = _tet10(pts, tets)
    on_plane = np.abs(pts[:, 2]) < 1e-9 * thickness
    pts, cells, pair_nodes, copy = _split_lap(pts, cells, marker, on_plane)
    tri_a, tri_b = _lap_facets(pts, cells, marker, on_plane, copy)
    facets = np.vstack([tri_a, tri_b])
    facet_markers = np.r_[np.full(len(tri_a), 11), np.full(len(tri_b), 12)]
    pair_area = _tributary_areas(pts, tri_a, pair_nodes[:, 0])

    def nearest(target, among):
        return int(among[np.argmin(np.linalg.norm(pts[among] - target, axis=1))])

    a_nodes = np.unique(cells[marker == 1])
    exc = nearest(np.array([-half, 0.0, -thickness]), a_nodes)
    resp = nearest(np.array([-half, 0.0, -thickness / 2]), a_nodes)
    return ResonatorMesh(points=pts, cells=cells.astype(np.int64), cell_markers=marker.astype(np.int32),
                         facets=facets.astype(np.int64), facet_markers=facet_markers.astype(np.int32),
                         pair_nodes=pair_nodes.astype(np.int64), pair_xyz=pts[pair_nodes[:, 0]].copy(),
                         pair_area=pair_area, excitation_node=exc, response_node=resp,
                         params=dict(half=half, thickness=thickness, cell=cell, shank_half=shank_half,
                                     hole_half=hole_half, head=head))
