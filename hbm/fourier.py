"""Truncated Fourier series and the alternating frequency/time (AFT) transforms.

Real coefficient ordering (docs/design.md, "Units and conventions"): ``[a0, a1, b1, a2, b2, ...]`` with
``x(t) = a0 + sum_h a_h cos(h w t) + b_h sin(h w t)``; ``n_H = 2H + 1`` coefficients.
Samples are ``theta_j = 2 pi j / n_t`` (j = 0..n_t-1) over one period.
"""
from __future__ import annotations

import numpy as np


class Fourier:
    """DFT/iDFT matrices and the time-derivative operator for harmonics 0..H.

    Args:
        harmonics: highest harmonic H (>= 1).
        samples: time samples per period n_t (must exceed 2H to avoid aliasing the retained harmonics).
    """

    def __init__(self, harmonics: int, samples: int) -> None:
        if int(harmonics) != harmonics or harmonics < 1:
            raise ValueError(f"harmonics must be an integer >= 1, got {harmonics!r}")
        if int(samples) != samples or samples <= 2 * harmonics:
            raise ValueError(f"samples must be an integer > 2*harmonics = {2 * harmonics}, got {samples!r}")
        self.H = int(harmonics)
        self.nt = int(samples)
        self.nH = 2 * self.H + 1
        self.theta = 2.0 * np.pi * np.arange(self.nt) / self.nt
        h = np.arange(1, self.H + 1)
        ht = np.outer(self.theta, h)                       # (nt, H)
        E = np.empty((self.nt, self.nH))                   # inverse transform: x(t_j) = E @ X
        E[:, 0] = 1.0
        E[:, 1::2] = np.cos(ht)
        E[:, 2::2] = np.sin(ht)
        self.E = E
        # forward transform: exact inverse of E on the retained harmonics (orthogonality of samples)
        D = E.T * (2.0 / self.nt)
        D[0] *= 0.5
        self.D = D
        # d/d(theta) on coefficients: a_h cos + b_h sin -> h b_h cos - h a_h sin
        dmat = np.zeros((self.nH, self.nH))
        for k in range(1, self.H + 1):
            dmat[2 * k - 1, 2 * k] = k
            dmat[2 * k, 2 * k - 1] = -k
        self.nabla = dmat
        self.orders = np.concatenate([[0], np.repeat(h, 2)])  # harmonic order of each coefficient

    def to_time(self, X: np.ndarray) -> np.ndarray:
        """Samples over one period of a series with coefficients along the LAST axis: (..., nH) -> (..., nt)."""
        return X @ self.E.T

    def to_freq(self, x: np.ndarray) -> np.ndarray:
        """Coefficients of samples along the LAST axis: (..., nt) -> (..., nH)."""
        return x @ self.D.T

    def derivative(self, X: np.ndarray, omega: float) -> np.ndarray:
        """Coefficients of dx/dt for coefficients along the last axis (omega in rad/s)."""
        return omega * (X @ self.nabla.T)


def amplitude(X: np.ndarray, h: int = 1) -> np.ndarray:
    """Amplitude sqrt(a_h^2 + b_h^2) of harmonic h for coefficients along the FIRST axis."""
    if h == 0:
        return np.abs(X[0])
    return np.hypot(X[2 * h - 1], X[2 * h])
