"""Hysteresis loops as a reader can check them: loop areas and the energy-equivalent joint loop.

The friction energy the HBM reports is the work of the force harmonics on the displacement
harmonics, W = ∮ T·du summed over elements (``hbm.ElementResults.energy``). A loop drawn from
sampled histories has the area :func:`loop_area`, computed the same way (spectrally, over one
period), so an element's x-loop plus its y-loop has exactly that element's energy.

The whole-joint loop Σ T_x against the joint's mean relative slip is *not* energy-consistent:
∮ (Σ_e T_e) d(mean_e u_e) ≠ Σ_e ∮ T_e du_e unless every element moves alike; on the resonator the
elements' slips cancel in the mean (the joint rocks and bends), which drew a multi-lobed tangle of
small area. :func:`joint_equivalent_loop` draws the loop along the joint's own slip pattern, whose
in-phase part is the energy the elements store and whose area is the energy they dissipate.
"""
from __future__ import annotations

import numpy as np


def loop_area(u: np.ndarray, f: np.ndarray) -> float:
    """Work ∮ f du over one period of periodic samples (spectral, as the HBM's energy).

    Args:
        u: (nt,) displacement samples over one period, mm (no repeated end point).
        f: (nt,) force samples at the same instants, N.
    Returns:
        the work per cycle, N·mm (positive for a loop that dissipates).
    """
    n = len(u)
    U, F = np.fft.rfft(np.asarray(u, float)) / n, np.fft.rfft(np.asarray(f, float)) / n
    h = np.arange(len(U), dtype=float)
    if n % 2 == 0:
        h[-1] = 0.0    # Nyquist bin: its cosine is sampled at its extremes, its slope is lost
    # ∫ f du/dθ dθ = 2π Σ_h i h Û_h conj(F̂_h) over ±h = 4π Σ_{h≥1} h Im(F̂_h conj(Û_h))
    return float(4.0 * np.pi * np.sum(h * np.imag(F * np.conj(U))))


def joint_equivalent_loop(elem_u: np.ndarray, elem_T: np.ndarray, energy: float,
                          n: int = 181) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The whole joint's loop along its own slip pattern, with the dissipated energy as area.

    The joint coordinate is the amplitude of the element slips' first harmonics taken together,
    X_J = ‖û‖ (û_e: element e's first-harmonic u_x), the joint force its work conjugate, so that
    the in-phase stiffness k_J = Σ_e Re(T̂_e conj û_e) / X_J² is the elastic energy the elements
    store over the cycle and the quadrature part W / (π X_J) the energy they dissipate. Unlike
    Σ T_x against the mean slip, elements moving against each other (a rocking or bending joint)
    do not cancel.

    Args:
        elem_u: (ne, nt) element u_x over one period, mm.
        elem_T: (ne, nt) element T_x, N.
        energy: dissipated energy per cycle, N·mm.
        n: points on the returned closed loop.
    Returns:
        (x, F, X_J, k_J): the closed loop about the origin (mm, N), its amplitude (mm) and
        in-phase stiffness (N/mm).
    """
    cu = 2.0 * np.fft.rfft(np.asarray(elem_u, float), axis=1)[:, 1] / elem_u.shape[1]
    cT = 2.0 * np.fft.rfft(np.asarray(elem_T, float), axis=1)[:, 1] / elem_T.shape[1]
    X = float(np.sqrt(np.sum(np.abs(cu) ** 2)))
    theta = np.linspace(0.0, 2 * np.pi, n)
    if X == 0.0:
        return np.zeros(n), np.zeros(n), 0.0, 0.0
    k = float(np.sum(np.real(cT * np.conj(cu)))) / X**2
    c = energy / (np.pi * X)
    return X * np.cos(theta), k * X * np.cos(theta) - c * np.sin(theta), X, k
