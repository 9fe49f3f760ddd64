"""The interface-motion decomposition against rigid motions and a bending field built by hand."""
from __future__ import annotations

import numpy as np
import pytest

from fe_joint.model.interface_motion import RIGID_NAMES, decompose, relative_motion


def _grid(n: int = 9) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.linspace(-10, 10, n), np.linspace(-10, 10, n))
    xyz = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    return xyz, np.full(n * n, 4.0)


@pytest.mark.parametrize("k", range(6))
def test_each_rigid_motion_is_recognised(k: int) -> None:
    xyz, area = _grid()
    d, th = np.zeros(3), np.zeros(3)
    (d if k < 3 else th)[k % 3] = 1e-3
    u = d + np.cross(th, xyz)
    im = decompose(u, xyz, area)
    assert im.rigid[k] == pytest.approx(1.0, abs=1e-12), RIGID_NAMES[k]
    assert im.rigid.sum() + im.deformation.sum() == pytest.approx(1.0, abs=1e-12)


def test_antisymmetric_stretch_is_deformation_that_cancels_in_the_mean() -> None:
    """u_x = ε x (one plate stretching against the other): no rigid part, mean u_x = 0."""
    xyz, area = _grid()
    u = np.zeros_like(xyz)
    u[:, 0] = 1e-4 * xyz[:, 0]
    im = decompose(u, xyz, area)
    assert im.deformation[0] == pytest.approx(1.0, abs=1e-12)
    assert im.mean_over_rms[0] == pytest.approx(0.0, abs=1e-12)


def test_mean_over_rms_does_not_depend_on_the_modes_sign() -> None:
    """A uniform slide plus a stretch: |mean u_x| / rms u_x = c / sqrt(c² + ε² <x²>), the same for
    the field and its negative (a mode's sign is arbitrary)."""
    xyz, area = _grid()
    u = np.zeros_like(xyz)
    c, eps = 2e-4, 1e-5
    u[:, 0] = c + eps * xyz[:, 0]
    x2 = np.sum(area * xyz[:, 0] ** 2) / area.sum()
    expect = c / np.sqrt(c**2 + eps**2 * x2)
    for sign in (1.0, -1.0):
        assert decompose(sign * u, xyz, area).mean_over_rms[0] == pytest.approx(expect, rel=1e-12)

def test_relative_motion_rotates_local_components_to_global() -> None:
    phi = np.arange(12.0)
    pair_dofs = np.array([[[0, 1, 2], [3, 4, 5]], [[6, 7, 8], [9, 10, 11]]])
    c, s = np.cos(0.3), np.sin(0.3)
    frame = np.array([[[c, s, 0], [-s, c, 0], [0, 0, 1]]] * 2)     # rows t1, t2, n
    u = relative_motion(phi, pair_dofs, frame)
    # q_A − q_B = −3 along t1, t2 and n: −3 (t1 + t2 + n) in global components
    assert u == pytest.approx(np.array([[-3 * (c - s), -3 * (s + c), -3.0]] * 2), rel=1e-14)
