"""The joint's linear (stuck) limit and the FE → BEM interface mapping, against hand solutions."""
from __future__ import annotations

import numpy as np
import pytest

from fe_joint.model.joint import JointModel, slip_onset, stuck_modes, stuck_stiffness


def _two_blocks(m1=2e-3, m2=3e-3, k_mount=1e3):
    """Two point masses (3 DOFs each), A grounded through a soft x-spring only via the joint.

    DOFs: A = 0..2, B = 3..5 (x, y, z). No structural stiffness between them: the joint alone
    couples A and B, so the stuck frequency of the relative motion is √(k(1/m1 + 1/m2)).
    """
    M = np.diag([m1] * 3 + [m2] * 3)
    K = np.zeros((6, 6))
    pair_dofs = np.array([[[0, 1, 2], [3, 4, 5]]])
    return M, K, pair_dofs


def test_stuck_stiffness_assembles_springs() -> None:
    M, K, pd = _two_blocks()
    j = JointModel("t", n0=np.array([10.0]), gap=np.zeros(1), kn=np.array([3.0]),
                   kt=np.array([2.0]), area=np.array([0.5]))
    Ks = stuck_stiffness(K, pd, j)
    k = np.array([1.0, 1.0, 1.5])       # kt·A, kt·A, kn·A
    ref = np.block([[np.diag(k), -np.diag(k)], [-np.diag(k), np.diag(k)]])
    assert np.allclose(Ks, ref, rtol=0, atol=1e-15)
    # an unloaded element adds nothing
    j0 = JointModel("t", n0=np.zeros(1), gap=np.ones(1), kn=np.array([3.0]), kt=np.array([2.0]),
                    area=np.array([0.5]))
    assert np.abs(stuck_stiffness(K, pd, j0)).max() == 0.0


def test_stuck_modes_two_masses() -> None:
    M, K, pd = _two_blocks()
    kt, A = 5e4, 2.0
    j = JointModel("t", n0=np.array([1.0]), gap=np.zeros(1), kn=np.array([2 * kt]),
                   kt=np.array([kt]), area=np.array([A]))
    lin = stuck_modes(K, M, pd, j, n_modes=6)
    m1, m2 = 2e-3, 3e-3
    f_ref = np.sqrt(kt * A * (1 / m1 + 1 / m2)) / (2 * np.pi)
    assert lin.mode_index == 3                       # three rigid translations first
    assert lin.frequency == pytest.approx(f_ref, rel=1e-10)


def test_stuck_modes_kept_only_for_the_same_inputs() -> None:
    """stuck_modes keeps its recent results: the same arrays and springs give the same object;
    other springs, or an equal copy of K (not known to be unchanged), are computed anew and
    give the analytic frequency."""
    M, K, pd = _two_blocks()
    m1, m2, A = 2e-3, 3e-3, 2.0

    def joint(kt):
        return JointModel("t", n0=np.array([1.0]), gap=np.zeros(1), kn=np.array([2 * kt]),
                          kt=np.array([kt]), area=np.array([A]))
    a = stuck_modes(K, M, pd, joint(5e4), n_modes=6)
    assert stuck_modes(K, M, pd, joint(5e4), n_modes=6) is a      # an equal joint: kept
    b = stuck_modes(K, M, pd, joint(2e4), n_modes=6)
    assert b is not a
    assert b.frequency == pytest.approx(np.sqrt(2e4 * A * (1 / m1 + 1 / m2)) / (2 * np.pi), rel=1e-10)
    c = stuck_modes(K.copy(), M, pd, joint(5e4), n_modes=6)
    assert c is not a and c.frequency == pytest.approx(a.frequency, rel=1e-12)



@pytest.mark.parametrize("n", [30, 400])
def test_lowest_modes_of_a_free_free_chain(n: int) -> None:
    """lowest_modes (Lanczos above LANCZOS_MIN_DOFS, dense eigh below) gives the analytic
    spectrum of a free-free chain of equal masses and springs, lambda_j = 4 k/m sin²(j pi / 2n),
    the rigid mode at 0, and M-orthonormal modes."""
    from fe_joint.model.reduced_model import LANCZOS_MIN_DOFS, lowest_modes
    k, m = 3.0e4, 2.0e-3
    K = np.zeros((n, n))
    i = np.arange(n - 1)
    K[i, i] += k
    K[i + 1, i + 1] += k
    K[i, i + 1] -= k
    K[i + 1, i] -= k
    M = m * np.eye(n)
    M[0, 1] = M[1, 0] = 0.1 * m                       # not diagonal: a generalized problem
    lam, phi = lowest_modes(K, M, 8)
    assert (n >= LANCZOS_MIN_DOFS) == (n == 400)
    ref = np.linalg.eigvalsh(np.linalg.solve(np.linalg.cholesky(M), np.linalg.solve(
        np.linalg.cholesky(M), K).T))[:8]            # L^-1 K L^-T: symmetric
    assert abs(lam[0]) <= 1e-9 * lam[1]
    assert np.allclose(lam[1:], ref[1:], rtol=1e-10)
    assert np.allclose(phi.T @ M @ phi, np.eye(8), atol=1e-10)
    assert np.linalg.norm(K @ phi - M @ phi * lam) <= 1e-8 * np.linalg.norm(K @ phi)
    # equal masses (M[0, 1] aside): close to the analytic chain spectrum
    j = np.arange(1, 8)
    assert np.allclose(lam[1:], 4 * k / m * np.sin(j * np.pi / (2 * n)) ** 2, rtol=0.2)

def test_slip_onset_single_element() -> None:
    """One element: onset = macroslip = μN0 / (kt A |u_t| per N) with the resonant amplitude."""
    M, K, pd = _two_blocks()
    kt, A, n0, mu, zeta = 5e4, 2.0, 100.0, 0.6, 1e-3
    j = JointModel("t", n0=np.array([n0]), gap=np.zeros(1), kn=np.array([kt]), kt=np.array([kt]),
                   area=np.array([A]))
    est = slip_onset(K, M, pd, j, excitation_dof=0, damping_ratio=zeta, mu=mu)
    m1, m2 = 2e-3, 3e-3
    w = np.sqrt(kt * A * (1 / m1 + 1 / m2))
    # mass-normalized relative mode: φ_A = c/m1, φ_B = −c/m2 with c² (1/m1 + 1/m2) = 1
    c = 1 / np.sqrt(1 / m1 + 1 / m2)
    ut_per_N = (c / m1) * (c / m1 + c / m2) / (2 * zeta * w * w)
    ref = mu * n0 / (kt * A * ut_per_N)
    assert est["first_slip"] == pytest.approx(ref, rel=1e-8)
    assert est["macroslip"] == pytest.approx(ref, rel=1e-8)
    assert est["quantile"](0.5) == pytest.approx(ref, rel=1e-8)


# ---- FE → BEM interface -------------------------------------------------------------------
from contact_bem import extract_patches
from fe_joint.study.interface import element_loads, interface_grid, patch_side, smooth_fields


def _pairs(n=9, L=20.0, W=20.0, hole=8.5):
    x, y = np.meshgrid(np.linspace(-L / 2, L / 2, n), np.linspace(-W / 2, W / 2, n), indexing="ij")
    xy = np.column_stack([x.ravel(), y.ravel()])
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) > hole / 2]
    area = np.where(np.arange(len(xy)) % 2 == 0, 1.0, 3.0)    # unequal, like P2 vertex/mid-edge
    return xy, area


def test_interface_uniform_pressure_gives_area_weighted_loads() -> None:
    xy, area = _pairs()
    ig = interface_grid(xy, 20.0, 20.0, 8.5, 64)
    # owner = nearest pair, by brute force on a sample of cells
    pts = np.column_stack([ig.xc.ravel(), ig.yc.ravel()])[::97]
    d = np.linalg.norm(pts[:, None, :] - xy[None], axis=2)
    assert np.array_equal(ig.owner.ravel()[::97], d.argmin(axis=1))
    # no cell centre inside the hole is usable
    assert not ig.mask[np.hypot(ig.xc, ig.yc) < 8.5 / 2].any()
    bolt = 30000.0
    p_s, g_s, scale = smooth_fields(ig, xy, np.full(len(xy), 50.0), np.zeros(len(xy)), bolt)
    assert p_s.sum() * ig.cell_area == pytest.approx(bolt, rel=1e-12)
    assert np.ptp(p_s[ig.mask]) < 1e-9 * p_s.max()          # uniform stays uniform
    el = element_loads(ig, p_s, g_s, area, bolt)
    assert el["n0"].sum() == pytest.approx(bolt, rel=1e-12)
    ratio = el["n0"] / area
    assert np.ptp(ratio) < 1e-9 * ratio.max()                # N0 ∝ tributary area


def test_interface_gap_of_unloaded_elements() -> None:
    xy, area = _pairs()
    ig = interface_grid(xy, 20.0, 20.0, 8.5, 64)
    p = np.where(ig.xc < 0, 10.0, 0.0) * ig.mask
    gap = np.where(ig.xc < 0, 0.0, 1e-3 * (ig.xc + 0.1))
    el = element_loads(ig, p, gap, area, 1000.0)
    own = ig.owner
    for i in np.nonzero(el["n0"] == 0)[0][:5]:
        cells = (own == i) & ig.mask
        assert el["gap"][i] == pytest.approx(gap[cells].min(), rel=1e-12)
    assert np.all(el["gap"][el["n0"] > 0] == 0)


def test_patches_resample_linear_surface_exactly() -> None:
    xy, area = _pairs()
    ig = interface_grid(xy, 20.0, 20.0, 8.5, 128)
    z = 1e-3 * ig.xc - 2e-3 * ig.yc
    s = patch_side(area)
    inner = np.all(np.abs(xy) < 10 - s, axis=1)
    P = extract_patches(z, ig.grid, xy[inner], (8, 8), (s, s))
    off = (np.arange(8) + 0.5) * s / 8 - s / 2
    ref = (1e-3 * (xy[inner, 0, None, None] + off[None, :, None])
           - 2e-3 * (xy[inner, 1, None, None] + off[None, None, :]))
    assert np.abs(P - ref).max() < 1e-12
