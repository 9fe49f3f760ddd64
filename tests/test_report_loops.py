"""Loop areas and the energy-equivalent joint loop against closed forms."""
from __future__ import annotations

import numpy as np
import pytest

from fe_joint.report.loops import joint_equivalent_loop, loop_area
from hbm.reference import jenkins_describing_function


def _theta(n: int) -> np.ndarray:
    return 2 * np.pi * np.arange(n) / n


def test_damper_loop_area_is_pi_c_omega_x2() -> None:
    th = _theta(64)
    X, c, w, k = 0.3, 2.0, 5.0, 7.0
    u = 0.1 + X * np.cos(th)
    f = k * u - c * w * X * np.sin(th)          # spring + damper: f = k u + c du/dt
    assert loop_area(u, f) == pytest.approx(np.pi * c * w * X**2, rel=1e-12)
    assert loop_area(u, k * u) == pytest.approx(0.0, abs=1e-12)


def test_jenkins_loop_area_equals_describing_function_dissipation() -> None:
    """A Jenkins element (k_t, slip force F_s) under u = X cos θ: the sampled steady loop's area
    equals the describing function's energy 4 F_s (X − F_s / k_t) = −π X b_1."""
    kt, fs, X = 100.0, 3.0, 0.1
    th = _theta(4096)
    u = X * np.cos(th)
    # steady loop from u = X (slider at X − fs/kt): unloading branch, then loading branch
    T = np.where(th <= np.pi, np.minimum(fs, np.maximum(-fs, fs - kt * (X - u))),
                 np.maximum(-fs, np.minimum(fs, -fs + kt * (u + X))))
    _, b1, W = jenkins_describing_function(X, kt, fs)     # independent closed form
    assert loop_area(u, T) == pytest.approx(float(W), rel=1e-5)
    assert loop_area(u, T) == pytest.approx(-np.pi * X * float(b1), rel=1e-5)


def test_joint_loop_of_springs_moving_against_each_other() -> None:
    """Linear springs k_e whose slips are out of phase (a rocking joint: the mean slip is 0): the
    joint loop's stiffness is Σ k_e |û_e|² / Σ |û_e|², its area the energy given."""
    th = _theta(64)
    amp = np.array([1.0, -1.0, 0.5, -0.5])[:, None] * 1e-3
    k = np.array([10.0, 20.0, 30.0, 40.0])[:, None]
    u = amp * np.cos(th + 0.3)
    x, F, X, kj = joint_equivalent_loop(u, k * u, energy=0.02)
    assert np.mean(u, axis=0) == pytest.approx(np.zeros(64), abs=1e-18)
    assert X == pytest.approx(np.sqrt(np.sum(amp**2)), rel=1e-12)
    assert kj == pytest.approx(float(np.sum(k * amp**2) / np.sum(amp**2)), rel=1e-12)
    assert loop_area(x[:-1], F[:-1]) == pytest.approx(0.02, rel=1e-12)
