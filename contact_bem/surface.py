"""Random Gaussian rough surfaces and their statistics.

Convention (docs/design.md, "Units and conventions"): the correlation length λ is the lag at which the autocorrelation falls to
10 % of Rq², i.e. ``C(x, y) = Rq² · 10^(-(x/λx)² - (y/λy)²)`` (Patir 1978).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import positive_scalar
from .grid import Grid


def _wrapped_lags(n: int, d: float) -> np.ndarray:
    """Signed periodic lags (n,) in mm for an FFT-ordered axis."""
    k = np.arange(n)
    return np.where(k <= n // 2, k, k - n) * d


def gaussian_surface(grid: Grid, rq: float, corr_length, seed: int | None = 0) -> np.ndarray:
    """Gaussian random surface with a Gaussian autocorrelation, by FFT filtering of white noise.

    The target autocorrelation is sampled on the periodic grid, its discrete spectrum (clipped at 0)
    gives the filter, so the expected circular ACF of the result is exactly the target one. The mean
    is removed and the heights are rescaled so that the RMS is exactly ``rq``. The surface is periodic
    over the grid (usable for both periodic and non-periodic contact).

    Args:
        grid: grid of the surface.
        rq: RMS roughness Rq in mm (> 0; 0 gives a flat surface).
        corr_length: λ in mm (> 0), a scalar or (λx, λy) for an anisotropic surface.
        seed: seed of ``numpy.random.default_rng`` (same seed → same surface).

    Returns:
        Heights (nx, ny) in mm, zero mean, RMS = rq.
    """
    if not isinstance(grid, Grid):
        raise ValueError(f"grid: expected a contact_bem.Grid, got {type(grid).__name__}")
    rq = positive_scalar("rq", rq, allow_zero=True)
    lam = np.broadcast_to(np.asarray(corr_length, dtype=float), (2,)).copy() \
        if np.ndim(corr_length) <= 1 and np.size(corr_length) in (1, 2) else None
    if lam is None or not np.all(np.isfinite(lam)) or np.any(lam <= 0):
        raise ValueError(f"corr_length: must be a positive length or a pair (λx, λy) in mm, got {corr_length!r}")
    nx, ny = grid.shape
    if rq == 0.0:
        return np.zeros(grid.shape)
    lx = _wrapped_lags(nx, grid.dx)[:, None]
    ly = _wrapped_lags(ny, grid.dy)[None, :]
    acf = 10.0 ** (-((lx / lam[0]) ** 2) - (ly / lam[1]) ** 2)
    psd = np.clip(np.fft.rfft2(acf).real, 0.0, None)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(grid.shape)
    z = np.fft.irfft2(np.fft.rfft2(noise) * np.sqrt(psd), s=grid.shape)
    z -= z.mean()
    rms = np.sqrt(np.mean(z * z))
    if rms == 0.0:  # λ much smaller than a cell and a degenerate draw: nothing to scale
        raise ValueError("corr_length: too small for this grid (filtered surface is zero)")
    return z * (rq / rms)


@dataclass
class SurfaceStatistics:
    """Statistics of a surface on a grid.

    Attributes:
        rq: RMS height (mm).
        rms_slope: RMS gradient magnitude (dimensionless), central differences (periodic).
        lags_x, acf_x: lags (mm) and normalised circular autocorrelation along x (ACF(0) = 1).
        lags_y, acf_y: same along y.
        corr_length: (λx, λy) mm, lag where the ACF first falls to 10 % (linear interpolation;
            nan if it never does within half the grid).
        wavenumber: radial wavenumbers |q| (rad/mm) of the radially averaged PSD.
        psd: radially averaged power spectral density (mm⁴), normalised so that
            Σ psd_2d · Δq_x Δq_y / (2π)² = Rq².
    """

    rq: float
    rms_slope: float
    lags_x: np.ndarray
    acf_x: np.ndarray
    lags_y: np.ndarray
    acf_y: np.ndarray
    corr_length: tuple[float, float]
    wavenumber: np.ndarray
    psd: np.ndarray


def _first_crossing(lags: np.ndarray, acf: np.ndarray, level: float) -> float:
    below = np.nonzero(acf <= level)[0]
    if below.size == 0:
        return float("nan")
    i = below[0]
    if i == 0:
        return 0.0
    a0, a1 = acf[i - 1], acf[i]
    return float(lags[i - 1] + (a0 - level) / (a0 - a1) * (lags[i] - lags[i - 1]))


def surface_statistics(grid: Grid, heights) -> SurfaceStatistics:
    """Rq, RMS slope, ACF along x and y, correlation lengths and radial PSD of a surface.

    Args:
        grid: grid of the surface.
        heights: (nx, ny) heights in mm.

    Returns:
        SurfaceStatistics (see its attributes for units).
    """
    z = grid.check_field("heights", heights)
    z = z - z.mean()
    nx, ny = grid.shape
    rq = float(np.sqrt(np.mean(z * z)))
    gx = (np.roll(z, -1, 0) - np.roll(z, 1, 0)) / (2 * grid.dx)
    gy = (np.roll(z, -1, 1) - np.roll(z, 1, 1)) / (2 * grid.dy)
    rms_slope = float(np.sqrt(np.mean(gx * gx + gy * gy)))
    zh = np.fft.rfft2(z)
    acf2 = np.fft.irfft2(np.abs(zh) ** 2, s=grid.shape) / z.size
    norm = acf2[0, 0] if acf2[0, 0] > 0 else 1.0
    acf_x = acf2[: nx // 2 + 1, 0] / norm
    acf_y = acf2[0, : ny // 2 + 1] / norm
    lags_x = np.arange(nx // 2 + 1) * grid.dx
    lags_y = np.arange(ny // 2 + 1) * grid.dy
    corr = (_first_crossing(lags_x, acf_x, 0.1), _first_crossing(lags_y, acf_y, 0.1))
    # 2D PSD with continuous-FT normalisation, then radial average in bins of the coarser Δq
    psd2 = np.abs(np.fft.fft2(z)) ** 2 * grid.cell_area ** 2 / grid.area
    qx = 2 * np.pi * np.fft.fftfreq(nx, grid.dx)
    qy = 2 * np.pi * np.fft.fftfreq(ny, grid.dy)
    qr = np.hypot(qx[:, None], qy[None, :])
    dq = max(2 * np.pi / grid.size[0], 2 * np.pi / grid.size[1])
    bins = np.rint(qr / dq).astype(int)
    counts = np.bincount(bins.ravel())
    sums = np.bincount(bins.ravel(), weights=psd2.ravel())
    keep = counts > 0
    return SurfaceStatistics(rq, rms_slope, lags_x, acf_x, lags_y, acf_y, corr,
                             np.arange(counts.size)[keep] * dq, sums[keep] / counts[keep])
