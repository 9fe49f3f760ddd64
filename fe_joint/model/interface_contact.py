"""Bolt preload contact on the condensed interface (numpy): active set, pressure recovery, scaling.

Method (docs/design.md, "Preload"):

1. The bolt pretension is an axial shortening eigenstrain eps0 = -e (e_z ⊗ e_z) in the shank. The
   problem is homogeneous (matched pairs start with zero gap), so the active set does not depend on
   e: solve for e = 1 and scale so the clamping force equals the target preload.
2. The structure is condensed on the interface (boundary DOFs = pair nodes + excitation/response
   nodes; the same constraint modes as the Craig–Bampton reduction): S u_B = f_B.
3. Free–free: a statically determinate 3-2-1 support on three A-side pair nodes removes the rigid
   motion. The loads (eigenstrain, pair forces) are self-equilibrated, so the six support reactions
   must vanish; they are reported as a check.
4. Contact in pair space: with W = D S⁻¹ Dᵀ (relative flexibility of the pairs, D u = u_A - u_B) the
   relative displacement is d = d0 - W r, r the pair force (on B +r, on A -r; r_z = N >= 0 is
   compression). Primal–dual active set: closed pairs are tied (d = 0, all three components), open
   pairs carry nothing; a closed pair opens when N < 0, an open pair closes when d_z > 0.
5. Toggling pairs: with P2 elements the consistent nodal force of a smooth pressure is ~0 at vertex
   nodes, so a vertex pair can be slightly tensile when tied yet penetrate when released, and the
   active set cycles. When a set repeats, the pairs that changed within the cycle are frozen as
   *closed but untied*: the normal constraint d_z = 0 is kept, the tangential tie removed, and they
   are never reopened. The set can then only shrink finitely often, so the iteration terminates.
6. Pair normal loads: the raw nodal forces are turned into a pressure by the consistent P2 L2
   recovery of :func:`recover_pressure` (vertex forces handed to the adjacent mid-edge nodes,
   vertex pressure averaged from them), clipped to p >= 0 on closed pairs and 0 on open ones, times
   the tributary area, and rescaled so their sum is exactly the clamping force (the vertex/mid-edge
   split of the tributary area differs from the consistent P2 weights, O(h²)).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import ConvergenceError

OPEN, TIED, CLOSED_UNTIED, CLOSED_VERTEX = 0, 1, 2, 3

# consistent P2 triangle mass matrix / area, gmsh tri6 order (v0, v1, v2, m01, m12, m20)
_TRI6_MASS = np.array([[6, -1, -1, 0, -4, 0], [-1, 6, -1, 0, 0, -4], [-1, -1, 6, -4, 0, 0],
                       [0, 0, -4, 32, 16, 16], [-4, 0, 0, 16, 32, 16], [0, -4, 0, 16, 16, 32]]) / 180.0


@dataclass
class ContactSolution:
    """Solution of the condensed contact problem.

    Attributes:
        u: (n,) boundary displacements, mm (support DOFs are 0).
        force: (n_pairs, 3) pair forces r (on B +r, on A -r; z = normal, > 0 compressive), N.
        relative: (n_pairs, 3) relative displacement u_A - u_B, mm (z > 0 would be penetration).
        status: (n_pairs,) 0 open, 1 closed and tied, 2 closed untied (frozen toggling pair),
            3 closed vertex pair (set by :func:`preload_from_condensed`).
        reactions: (6,) support reactions, N.
        iterations: active-set iterations.
        n_toggled: pairs frozen as closed-untied.
    """

    u: np.ndarray
    force: np.ndarray
    relative: np.ndarray
    status: np.ndarray
    reactions: np.ndarray
    iterations: int
    n_toggled: int


def choose_321_support(pair_xyz: np.ndarray, pair_a: np.ndarray) -> np.ndarray:
    """Six boundary DOFs of a 3-2-1 support on A-side pair nodes.

    P1 (min x) fixes x, y, z; P2 (max x, nearest P1 in y) fixes y, z; P3 (farthest from the line
    P1-P2) fixes z: statically determinate for any non-collinear choice.

    Returns:
        (6,) boundary indices.
    """
    xyz = np.asarray(pair_xyz)
    i1 = int(np.lexsort((np.abs(xyz[:, 1]), xyz[:, 0]))[0])
    right = np.nonzero(xyz[:, 0] >= xyz[:, 0].max() - 1e-9 * np.ptp(xyz[:, 0]))[0]
    i2 = int(right[np.argmin(np.abs(xyz[right, 1] - xyz[i1, 1]))])
    e = xyz[i2] - xyz[i1]
    e /= np.linalg.norm(e)
    rel = xyz - xyz[i1]
    dist = np.linalg.norm(rel - np.outer(rel @ e, e), axis=1)
    i3 = int(np.argmax(dist))
    if dist[i3] <= 1e-9 * np.linalg.norm(xyz[i2] - xyz[i1]):
        raise ValueError("pair nodes are collinear: no 3-2-1 support possible")
    return np.array([pair_a[i1, 0], pair_a[i1, 1], pair_a[i1, 2], pair_a[i2, 1], pair_a[i2, 2], pair_a[i3, 2]])


def solve_interface_contact(S: np.ndarray, f: np.ndarray, pair_a: np.ndarray, pair_b: np.ndarray,
                            support: np.ndarray, max_iter: int = 200) -> ContactSolution:
    """Frictionless unilateral contact, tied where closed, on a condensed interface (PDAS).

    Args:
        S: (n, n) condensed stiffness, N/mm (singular free–free; made regular by ``support``).
        f: (n,) condensed load, N (self-equilibrated).
        pair_a, pair_b: (n_pairs, 3) indices of the A / B DOFs (x, y, z = normal) of each pair.
        support: (6,) indices fixed by the 3-2-1 support.
        max_iter: active-set iteration limit.

    Returns:
        ContactSolution.

    Raises:
        ConvergenceError: the active set did not settle within ``max_iter``.
    """
    S, f = np.asarray(S, float), np.asarray(f, float)
    n = len(f)
    if S.shape != (n, n) or not np.all(np.isfinite(S)) or not np.all(np.isfinite(f)):
        raise ValueError(f"S must be finite (n, n) and f finite (n,), got {S.shape}, {f.shape}")
    npair = len(pair_a)
    free = np.setdiff1d(np.arange(n), support)
    pos = -np.ones(n, dtype=np.int64)
    pos[free] = np.arange(len(free))
    cho = sla.cho_factor(S[np.ix_(free, free)])
    # D^T as a dense (n_free, 3 n_pairs) block: +1 at the A DOF, -1 at the B DOF
    Dt = np.zeros((len(free), 3 * npair))
    cols = np.arange(3 * npair)
    pa, pb = pos[pair_a.ravel()], pos[pair_b.ravel()]
    Dt[pa[pa >= 0], cols[pa >= 0]] = 1.0
    Dt[pb[pb >= 0], cols[pb >= 0]] = -1.0
    GDt = sla.cho_solve(cho, Dt)
    W = Dt.T @ GDt
    W = 0.5 * (W + W.T)
    u0 = sla.cho_solve(cho, f[free])
    d0 = Dt.T @ u0
    scale_d = max(np.abs(d0).max(), 1e-300)
    status = np.full(npair, TIED)
    history = [status.tobytes()]
    r = np.zeros(3 * npair)
    for it in range(1, max_iter + 1):
        comp = np.zeros((npair, 3), dtype=bool)
        comp[status == TIED] = True
        comp[status == CLOSED_UNTIED, 2] = True
        c = np.nonzero(comp.ravel())[0]
        r = np.zeros(3 * npair)
        if len(c):
            r[c] = sla.solve(W[np.ix_(c, c)], d0[c], assume_a="pos")
        d = d0 - W @ r
        N, dz = r[2::3], d[2::3]
        scale_n = max(np.abs(N).max(), 1e-300)
        new = status.copy()
        new[(status == TIED) & (N < -1e-12 * scale_n)] = OPEN
        new[(status == OPEN) & (dz > 1e-12 * scale_d)] = TIED
        key = new.tobytes()
        if np.array_equal(new, status):
            break
        if key in history:  # cycle: freeze every pair that changed within it as closed-untied
            start = history.index(key)
            seen = np.array([np.frombuffer(h, dtype=status.dtype) for h in history[start:]] + [new])
            toggling = np.any(seen != seen[0], axis=0) | (new != status)
            new[toggling] = CLOSED_UNTIED
        history.append(new.tobytes())
        status = new
    else:
        raise ConvergenceError(f"contact active set still changing after {max_iter} iterations "
                               f"({int(np.sum(new != status))} pairs flipping)")
    u = np.zeros(n)
    u[free] = u0 - GDt @ r
    contact = np.zeros(n)
    np.add.at(contact, pair_a.ravel(), r)
    np.add.at(contact, pair_b.ravel(), -r)
    reactions = (S @ u - f + contact)[support]
    return ContactSolution(u=u, force=r.reshape(npair, 3), relative=d.reshape(npair, 3), status=status,
                           reactions=reactions, iterations=it, n_toggled=int(np.sum(status == CLOSED_UNTIED)))


def lap_triangles(data, marker: int = 11) -> np.ndarray:
    """Lap-face tri6 facets of side A as pair indices, gmsh node order (v0, v1, v2, m01, m12, m20).

    The mid-edge nodes are re-identified geometrically, so any tri6 node order is accepted.
    """
    fac = np.asarray(data.facets)[np.asarray(data.facet_markers) == marker]
    if fac.ndim != 2 or fac.shape[1] != 6 or len(fac) == 0:
        raise ValueError(f"mesh data needs tri6 lap facets with marker {marker}")
    pairs = np.asarray(data.pair_nodes)
    lookup = -np.ones(max(int(pairs.max()), int(fac.max())) + 1, dtype=np.int64)
    lookup[pairs[:, 0]] = np.arange(len(pairs))
    tri = lookup[fac]
    if np.any(tri < 0):
        raise ValueError("lap facets reference nodes that are not A-side pair nodes")
    pts = np.asarray(data.points)
    # order the mid-edge nodes as m01, m12, m20 by matching edge midpoints
    v = pts[fac[:, :3]]
    mids = np.stack([(v[:, 0] + v[:, 1]) / 2, (v[:, 1] + v[:, 2]) / 2, (v[:, 2] + v[:, 0]) / 2], axis=1)
    m = pts[fac[:, 3:]]
    dist = np.linalg.norm(mids[:, :, None, :] - m[:, None, :, :], axis=3)  # (nf, edge, node)
    pick = np.argmin(dist, axis=2)
    return np.hstack([tri[:, :3], np.take_along_axis(tri[:, 3:], pick, axis=1)])


def recover_pressure(tri6: np.ndarray, xyz: np.ndarray, nodal_force: np.ndarray) -> np.ndarray:
    """Pressure from raw P2 nodal normal forces, conservative and non-negative for F >= 0.

    The consistent P2 load of a smooth pressure puts ~nothing on vertex nodes (weight 0) and A/3
    on each mid-edge node, so F / (tributary area) is useless at vertices. Here each vertex force
    is handed to its adjacent mid-edge nodes (in proportion to their consistent weight), the
    mid-edge pressure is force / consistent weight (sum of A/3 over adjacent triangles), and a
    vertex takes the weight-averaged pressure of its adjacent mid-edge nodes.

    Args:
        tri6: (n_tri, 6) pair-index triangles (gmsh order v0, v1, v2, m01, m12, m20).
        xyz: (n_pairs, 3) coordinates, mm.
        nodal_force: (n_pairs,) raw nodal normal forces, N.

    Returns:
        (n_pairs,) pressure, MPa (nodes outside every triangle get 0).
    """
    n = len(xyz)
    p3 = xyz[tri6[:, :3]]
    area = 0.5 * np.linalg.norm(np.cross(p3[:, 1] - p3[:, 0], p3[:, 2] - p3[:, 0]), axis=1)
    # vertex -> mid-edge adjacency (each vertex touches two mid-edge nodes per triangle)
    adj_v = tri6[:, [0, 0, 1, 1, 2, 2]].ravel()
    adj_m = tri6[:, [3, 5, 3, 4, 4, 5]].ravel()
    w_adj = np.repeat(area / 3, 6)
    A = sp.coo_matrix((w_adj, (adj_v, adj_m)), shape=(n, n)).tocsr()
    A.sum_duplicates()
    wv = np.asarray(A.sum(axis=1)).ravel()
    is_vertex = wv > 0
    share = sp.diags(np.where(is_vertex, 1.0 / np.where(is_vertex, wv, 1.0), 0.0)) @ A  # rows sum to 1
    weight_m = np.zeros(n)
    np.add.at(weight_m, tri6[:, 3:].ravel(), np.repeat(area / 3, 3))
    force_m = np.where(weight_m > 0, nodal_force, 0.0) + share.T @ np.where(is_vertex, nodal_force, 0.0)
    p = np.where(weight_m > 0, force_m / np.where(weight_m > 0, weight_m, 1.0), 0.0)
    return np.where(is_vertex, share @ p, p)


@dataclass
class PreloadResult:
    """Preloaded state of the joint (all arrays in ORIGINAL pair order).

    Attributes:
        bolt_force: target clamping force = sum of pair normal forces, N.
        eigenstrain: axial shortening eigenstrain applied in the shank (dimensionless).
        shank_force: mean axial force in the shank (1/L)∫sigma_zz dV, N (independent check).
        pair_normal_force: (n_pairs,) N, pressure x tributary area (sum = bolt_force).
        pair_pressure: (n_pairs,) MPa (0 on open pairs).
        pair_gap: (n_pairs,) normal gap, mm (0 on closed pairs, >= 0 on open ones).
        pair_raw_force: (n_pairs, 3) raw nodal pair forces (x, y, z), N.
        pair_status: (n_pairs,) 0 open, 1 closed tied, 2 closed untied (toggling, frozen),
            3 closed vertex pair inside the contact zone (released by the node-to-node solve with a
            nanometre gap; its pressure is interpolated from the adjacent mid-edge pairs).
        support_reactions: (6,) 3-2-1 support reactions, N (≈ 0).
        u_boundary: (n_B,) boundary displacements, mm.
        iterations, n_toggled: active-set statistics.
    """

    bolt_force: float
    eigenstrain: float
    shank_force: float
    pair_normal_force: np.ndarray
    pair_pressure: np.ndarray
    pair_gap: np.ndarray
    pair_raw_force: np.ndarray
    pair_status: np.ndarray
    support_reactions: np.ndarray
    u_boundary: np.ndarray
    iterations: int
    n_toggled: int
    displacement: object = field(default=None, repr=False)

    @property
    def closed(self) -> np.ndarray:
        """(n_pairs,) bool, pair in contact."""
        return self.pair_status != OPEN


def preload_from_condensed(S: np.ndarray, f_unit: np.ndarray, layout, data, preload_force: float):
    """Solve the condensed contact problem for a unit eigenstrain and scale it to the preload.

    ``preload_force`` (N, > 0) is checked by the public entry :func:`fe_joint.fe.preload.solve_preload`.

    Returns:
        (scale = eigenstrain, ContactSolution scaled, pair_pressure, pair_normal_force).
    """
    xyz = np.asarray(data.pair_xyz, dtype=float)
    support = choose_321_support(xyz, layout.pair_a)
    sol = solve_interface_contact(S, f_unit, layout.pair_a, layout.pair_b, support)
    total = sol.force[:, 2].sum()
    if not total > 0:
        raise ValueError("the bolt eigenstrain does not clamp the lap faces (total contact force <= 0); "
                         "check that the shank (marker 3) joins the two plates")
    s = preload_force / total
    sol.u *= s
    sol.force *= s
    sol.relative *= s
    sol.reactions *= s
    tri6 = lap_triangles(data)
    # P2 node-to-node artefact: a vertex pair inside the contact zone can come out released with a
    # nanometre gap (its consistent share of a smooth pressure is ~0 or negative). A vertex pair
    # whose adjacent mid-edge pairs are all closed is in contact: status CLOSED_VERTEX, gap 0, and
    # the recovered (interpolated) pressure.
    n_open_mid = np.zeros(len(xyz))
    vert = tri6[:, [0, 0, 1, 1, 2, 2]].ravel()
    mids = tri6[:, [3, 5, 3, 4, 4, 5]].ravel()
    np.add.at(n_open_mid, vert, (sol.status[mids] == OPEN).astype(float))
    is_vertex = np.zeros(len(xyz), dtype=bool)
    is_vertex[tri6[:, :3].ravel()] = True
    inner = is_vertex & (sol.status == OPEN) & (n_open_mid == 0)
    sol.status[inner] = CLOSED_VERTEX
    sol.relative[inner, 2] = 0.0
    closed = sol.status != OPEN
    p = recover_pressure(tri6, xyz, sol.force[:, 2])
    p = np.where(closed, np.maximum(p, 0.0), 0.0)
    area = np.asarray(data.pair_area, dtype=float)
    force = p * area
    force *= preload_force / force.sum()
    return s, sol, force / area, force
