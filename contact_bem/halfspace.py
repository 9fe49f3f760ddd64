"""Elastic half-space operators for two identical bodies, applied by FFT.

Influence coefficients of a uniform traction on one rectangular cell (half sides a = dx/2,
b = dy/2), from the closed-form integrals of Love (1929) / Johnson (1985, §3.2 and §3.6):

* normal (Boussinesq), relative normal displacement of the two bodies
  ``K_zz = 1/(π E*) · D[X asinh(Y/|X|) + Y asinh(X/|Y|)]``,
* tangential (Cerruti), relative tangential displacement,
  ``K_xx = 1/(π G) · D[(1-ν) X asinh(Y/|X|) + Y asinh(X/|Y|)]``,
  ``K_yy = 1/(π G) · D[X asinh(Y/|X|) + (1-ν) Y asinh(X/|Y|)]``,
  ``K_xy = ν/(π G) · D[-√(X²+Y²)]``,

where ``D[f] = f(x+a, y+b) - f(x-a, y+b) - f(x+a, y-b) + f(x-a, y-b)`` and E* = E/(2(1-ν²)) is the
composite modulus of two identical bodies. The factors include both bodies' compliances, so the
tangential stiffness of a stuck circle is 8 G* a with G* = G/(2(2-ν)). Because the bodies are identical
(Dundurs β = 0) the normal and tangential problems are uncoupled.

Non-periodic grids use DC-FFT (Liu, Wang & Liu 2000): the kernel is sampled on a (2nx, 2ny) wrapped
grid and the field zero-padded, which gives the exact linear (non-circular) convolution.
Periodic grids use the Fourier multipliers of the continuous half-space,
``2/(E*|k|)`` and ``(2/(G|k|)) (δ_αβ - ν k_α k_β/|k|²)``, times the cell shape factor and summed over
aliases, i.e. the periodic image sum of the same cell influence coefficients (so periodic and
non-periodic results differ only by periodicity), with the k = 0 term set to zero (the mean
displacement of a periodic problem is undefined; only relative values matter).

FFTs use pyFFTW with plans built once per array shape and reused (threads configurable); without
pyFFTW it falls back to ``scipy.fft`` with the same number of workers.
"""
from __future__ import annotations

import numpy as np

from .errors import positive_scalar
from .grid import Grid

try:  # pyFFTW is the fast path; scipy.fft keeps the package usable without it
    import pyfftw
    _HAVE_FFTW = True
except ImportError:  # pragma: no cover - exercised only without pyfftw
    _HAVE_FFTW = False
import scipy.fft as _sfft


def _asinh_term(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x·asinh(y/|x|), continuous and 0 at x = 0 (its mixed derivative is y²/r³)."""
    ax = np.abs(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = x * np.arcsinh(y / np.where(ax > 0, ax, 1.0))
    return np.where(ax > 0, out, 0.0)


def _corner_sum(f, x: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    return f(x + a, y + b) - f(x - a, y + b) - f(x + a, y - b) + f(x - a, y - b)


def influence_coefficients(x: np.ndarray, y: np.ndarray, dx: float, dy: float, young: float,
                           poisson: float, components=("zz", "xx", "yy", "xy")) -> dict[str, np.ndarray]:
    """Relative displacements at offsets (x, y) due to a unit uniform traction on one cell.

    Args:
        x, y: offsets from the loaded cell centre (mm), any broadcastable shapes.
        dx, dy: cell size (mm).
        young: Young's modulus E (MPa) of each (identical) body.
        poisson: Poisson ratio ν.

        components: which of 'zz', 'xx', 'yy', 'xy' to compute.

    Returns:
        dict with the requested arrays (mm per MPa): relative displacement per unit traction.
    """
    a, b = 0.5 * dx, 0.5 * dy
    e_star = young / (2.0 * (1.0 - poisson ** 2))
    g = young / (2.0 * (1.0 + poisson))
    out = {}
    if set(components) & {"zz", "xx", "yy"}:
        t1 = _corner_sum(lambda u, v: _asinh_term(u, v), x, y, a, b)   # ∫∫ y²/r³
        t2 = _corner_sum(lambda u, v: _asinh_term(v, u), x, y, a, b)   # ∫∫ x²/r³
        if "zz" in components:
            out["zz"] = (t1 + t2) / (np.pi * e_star)
        if "xx" in components:
            out["xx"] = ((1.0 - poisson) * t1 + t2) / (np.pi * g)
        if "yy" in components:
            out["yy"] = (t1 + (1.0 - poisson) * t2) / (np.pi * g)
    if "xy" in components:
        out["xy"] = poisson * _corner_sum(lambda u, v: -np.hypot(u, v), x, y, a, b) / (np.pi * g)  # ∫∫ xy/r³
    return out


class _FFT2:
    """Real 2D FFT pair over the last two axes for one array shape, plans built once."""

    def __init__(self, shape: tuple[int, ...], threads: int, effort: str):
        self.shape = tuple(shape)
        cshape = self.shape[:-1] + (self.shape[-1] // 2 + 1,)
        if _HAVE_FFTW:
            self.real_in = pyfftw.zeros_aligned(self.shape, dtype="float64")
            self.spec = pyfftw.empty_aligned(cshape, dtype="complex128")
            self.spec_in = pyfftw.empty_aligned(cshape, dtype="complex128")
            self.real_out = pyfftw.empty_aligned(self.shape, dtype="float64")
            self._fwd = pyfftw.FFTW(self.real_in, self.spec, axes=(-2, -1), threads=threads,
                                    flags=(effort,))
            self._inv = pyfftw.FFTW(self.spec_in, self.real_out, axes=(-2, -1), threads=threads,
                                    direction="FFTW_BACKWARD", flags=(effort, "FFTW_DESTROY_INPUT"))
            self.real_in[...] = 0.0  # planning with MEASURE (if asked for) may scribble on the buffers
        else:  # pragma: no cover
            self.real_in = np.zeros(self.shape)
            self.spec_in = np.zeros(cshape, dtype=complex)
            self.threads = threads

    def forward(self) -> np.ndarray:
        """rfft2 of ``self.real_in`` (returns an internal buffer, valid until the next call)."""
        if _HAVE_FFTW:
            return self._fwd()
        return _sfft.rfft2(self.real_in, workers=self.threads)  # pragma: no cover

    def inverse(self, spec: np.ndarray | None = None) -> np.ndarray:
        """irfft2 of ``spec`` or, if None, of ``self.spec_in`` (normalised; returns an internal buffer)."""
        if _HAVE_FFTW:
            if spec is not None:
                self.spec_in[...] = spec
            return self._inv()  # pyFFTW normalises the backward transform by default
        return _sfft.irfft2(self.spec_in if spec is None else spec, s=self.shape[-2:],
                            workers=self.threads)  # pragma: no cover


class _PrunedFFT2:
    """Zero-padded real 2D FFT pair for DC-FFT: the input lives in the first half of the rows of the
    padded grid and only that half of the output is needed, so the row transforms run on half the
    rows (about 25 % fewer flops than the full padded rfft2/irfft2). Same interface as _FFT2:
    ``real_in`` is (..., nx, 2ny), ``inverse`` returns (..., nx, 2ny)."""

    def __init__(self, shape: tuple[int, ...], threads: int, effort: str):
        self.shape = tuple(shape)
        batch, (px, py) = self.shape[:-2], self.shape[-2:]
        self.nx = px // 2
        cshape = batch + (px, py // 2 + 1)
        self.real_in = pyfftw.zeros_aligned(batch + (self.nx, py), dtype="float64")
        self.spec = pyfftw.zeros_aligned(cshape, dtype="complex128")
        self.spec_in = pyfftw.zeros_aligned(cshape, dtype="complex128")
        self.real_out = pyfftw.zeros_aligned(batch + (self.nx, py), dtype="float64")
        fl = (effort,)
        self._f_rows = pyfftw.FFTW(self.real_in, self.spec[..., : self.nx, :], axes=(-1,), threads=threads, flags=fl)
        self._f_cols = pyfftw.FFTW(self.spec, self.spec, axes=(-2,), threads=threads, flags=fl)
        self._i_cols = pyfftw.FFTW(self.spec_in, self.spec_in, axes=(-2,), threads=threads,
                                   direction="FFTW_BACKWARD", flags=fl)
        self._i_rows = pyfftw.FFTW(self.spec_in[..., : self.nx, :], self.real_out, axes=(-1,), threads=threads,
                                   direction="FFTW_BACKWARD", flags=fl + ("FFTW_DESTROY_INPUT",))
        self.real_in[...] = 0.0  # planning may scribble on the buffers

    def forward(self) -> np.ndarray:
        self.spec[..., self.nx:, :] = 0.0  # the in-place column pass filled the padding rows
        self._f_rows()
        self._f_cols()
        return self.spec

    def inverse(self, spec: np.ndarray | None = None) -> np.ndarray:
        if spec is not None:
            self.spec_in[...] = spec
        self._i_cols()  # pyFFTW normalises each backward pass by its own length
        return self._i_rows()


class ElasticHalfSpace:
    """Normal and tangential compliance operators of two identical elastic half-spaces on a grid.

    Args:
        grid: the contact grid.
        young: Young's modulus E (MPa) of both bodies (> 0).
        poisson: Poisson ratio ν in [0, 0.5).
        periodic: periodic FFT (exact Fourier multipliers) instead of non-periodic DC-FFT.
        threads: FFTW threads (>= 1).
        planner: FFTW planner effort; plans are made once per array shape (batch size) and reused.
            The default 'FFTW_ESTIMATE' picks the algorithm by a fixed heuristic, so the same input
            gives bit-identical results in every run; 'FFTW_MEASURE' picks it by timing, so two runs
            can differ in the last bits (contact surfaces by up to 1.5e-11 were seen), and it was
            no faster here (Hertz 256² and 512² solves within 5 %, planning included).
        alias_terms: M of the periodic alias sum (periodic only; see ``_build_spectra``).
        periodic_kernel: 'cell' (default: alias-summed cell coefficients, consistent with the
            non-periodic operator) or 'continuous' (plain 2/(E*|k|) multipliers sampled on the grid,
            the Stanley–Kato/Tamaas convention; used to compare with Tamaas).

    Attributes:
        e_star: composite modulus E/(2(1-ν²)) (MPa).
        g_star: composite shear modulus G/(2(2-ν)) (MPa) of the Mindlin solution.
        shear_modulus: G = E/(2(1+ν)) of one body (MPa).
    """

    def __init__(self, grid: Grid, young: float = 198400.0, poisson: float = 0.3, periodic: bool = False,
                 threads: int = 1, planner: str = "FFTW_ESTIMATE", alias_terms: int = 4,
                 periodic_kernel: str = "cell"):
        if not isinstance(grid, Grid):
            raise ValueError(f"grid: expected a contact_bem.Grid, got {type(grid).__name__}")
        self.grid = grid
        self.young = positive_scalar("young", young)
        self.poisson = float(poisson)
        if not (np.isfinite(self.poisson) and 0.0 <= self.poisson < 0.5):
            raise ValueError(f"poisson: must be in [0, 0.5), got {poisson!r}")
        self.periodic = bool(periodic)
        if int(threads) < 1:
            raise ValueError(f"threads: must be >= 1, got {threads!r}")
        self.threads = int(threads)
        self.planner = str(planner)
        if int(alias_terms) < 0:
            raise ValueError(f"alias_terms: must be >= 0, got {alias_terms!r}")
        self.alias_terms = int(alias_terms)
        if periodic_kernel not in ("cell", "continuous"):
            raise ValueError(f"periodic_kernel: must be 'cell' or 'continuous', got {periodic_kernel!r}")
        self.periodic_kernel = periodic_kernel
        nu = self.poisson
        self.e_star = self.young / (2.0 * (1.0 - nu ** 2))
        self.shear_modulus = self.young / (2.0 * (1.0 + nu))
        self.g_star = self.shear_modulus / (2.0 * (2.0 - nu))
        nx, ny = grid.shape
        self.padded_shape = (nx, ny) if self.periodic else (2 * nx, 2 * ny)
        self._plans: dict[tuple[int, ...], _FFT2] = {}
        self._build_spectra()

    # ------------------------------------------------------------------ kernels
    def _build_spectra(self, tangential: bool = False) -> None:
        nx, ny = self.grid.shape
        px, py = self.padded_shape
        if self.periodic:
            # Periodic sum of the same cell influence coefficients, done spectrally: the continuous
            # multiplier times the cell shape factor sinc(k_x dx/2) sinc(k_y dy/2), summed over the
            # aliases k + 2π(m/dx, n/dy), |m|, |n| ≤ M (collocation at cell centres). Without the
            # alias sum the periodic operator is a different discretisation from the DC-FFT one and
            # rough contact areas differ by ~10 % at 3 cells per correlation length.
            dx, dy = self.grid.dx, self.grid.dy
            kx0 = 2 * np.pi * np.fft.fftfreq(nx, dx)[:, None]
            ky0 = 2 * np.pi * np.fft.rfftfreq(ny, dy)[None, :]
            nu, g = self.poisson, self.shear_modulus
            shp = np.broadcast(kx0, ky0).shape
            zz, xx, yy, xy = (np.zeros(shp) for _ in range(4))
            M = self.alias_terms if self.periodic_kernel == "cell" else 0
            cell = self.periodic_kernel == "cell"
            for m in range(-M, M + 1):
                kx = kx0 + 2 * np.pi * m / dx
                sx = np.sinc(kx * dx / (2 * np.pi)) if cell else 1.0
                for n in range(-M, M + 1):
                    ky = ky0 + 2 * np.pi * n / dy
                    k2 = kx * kx + ky * ky
                    inv_k = np.divide(1.0, np.sqrt(k2), out=np.zeros(shp), where=k2 > 0)
                    w = sx * (np.sinc(ky * dy / (2 * np.pi)) if cell else 1.0) * inv_k
                    inv_k2 = inv_k * inv_k
                    zz += w
                    xx += w * (1.0 - nu * kx * kx * inv_k2)
                    yy += w * (1.0 - nu * ky * ky * inv_k2)
                    xy -= w * nu * kx * ky * inv_k2
            self._zz = 2.0 / self.e_star * zz
            self._xx = 2.0 / g * xx
            self._yy = 2.0 / g * yy
            self._xy = 2.0 / g * xy
        else:
            ix = np.arange(px)
            iy = np.arange(py)
            ox = np.where(ix < nx, ix, ix - px) * self.grid.dx
            oy = np.where(iy < ny, iy, iy - py) * self.grid.dy
            # the tangential kernels are built on first use (normal-only solves skip their cost)
            names = ("zz",) if not tangential else ("xx", "yy", "xy")
            c = influence_coefficients(ox[:, None], oy[None, :], self.grid.dx, self.grid.dy,
                                       self.young, self.poisson, components=names)
            for name in names:
                setattr(self, "_" + name, np.fft.rfft2(c[name]))
        self._tangential_ready = self.periodic or tangential
        # kernels even in x and y have real spectra: real multipliers halve the product cost
        for name in ("_zz", "_xx", "_yy", "_xy"):
            k = getattr(self, name, None)
            if k is not None and np.iscomplexobj(k) and np.abs(k.imag).max() <= 1e-12 * np.abs(k.real).max():
                setattr(self, name, np.ascontiguousarray(k.real))

    def _ensure_tangential(self) -> None:
        if not self._tangential_ready:
            self._build_spectra(tangential=True)

    @property
    def tangential_lipschitz(self) -> float:
        """Largest eigenvalue (mm/MPa) of the tangential operator (bound from its symbol)."""
        self._ensure_tangential()
        xx, yy, xy = self._xx.real, self._yy.real, self._xy.real
        return float(np.max(0.5 * (xx + yy) + np.sqrt(0.25 * (xx - yy) ** 2 + xy ** 2)))

    def _plan(self, batch: tuple[int, ...]) -> _FFT2:
        shape = tuple(batch) + self.padded_shape
        plan = self._plans.get(shape)
        if plan is None:
            effort = self.planner if np.prod(shape) <= 2 ** 22 else "FFTW_ESTIMATE"
            cls = _PrunedFFT2 if (_HAVE_FFTW and not self.periodic) else _FFT2
            plan = cls(shape, self.threads, effort)
            self._plans[shape] = plan
        return plan

    # ------------------------------------------------------------------ operators
    def displacement(self, pressure: np.ndarray) -> np.ndarray:
        """Relative normal displacement u = K * p of the two bodies.

        Args:
            pressure: (..., nx, ny) pressure in MPa (leading axes are a batch).

        Returns:
            (..., nx, ny) displacement in mm (positive = the bodies are pushed apart).
        """
        return self._apply_normal(self._checked("pressure", pressure, ()))

    def _checked(self, name: str, value, lead: tuple) -> np.ndarray:
        """Finite float array whose trailing axes are ``lead + grid.shape`` (ValueError otherwise)."""
        a = np.asarray(value, dtype=float)
        want = tuple(lead) + self.grid.shape
        if a.shape[a.ndim - len(want):] != want or a.ndim < len(want):
            raise ValueError(f"{name}: expected shape (..., {', '.join(map(str, want))}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: must be finite (no NaN/inf)")
        return a

    def _apply_normal(self, p: np.ndarray) -> np.ndarray:
        nx, ny = self.grid.shape
        plan = self._plan(p.shape[:-2])
        plan.real_in[..., :nx, :ny] = p
        np.multiply(plan.forward(), self._zz, out=plan.spec_in)
        return plan.inverse()[..., :nx, :ny].copy()

    def tangential_displacement(self, traction: np.ndarray) -> np.ndarray:
        """Relative tangential displacement u_α = K_αβ * q_β of the two bodies.

        Args:
            traction: (..., 2, nx, ny) shear traction (q_x, q_y) in MPa.

        Returns:
            (..., 2, nx, ny) tangential displacement in mm.
        """
        return self._apply_tangential(self._checked("traction", traction, (2,)))

    def _apply_tangential(self, q: np.ndarray) -> np.ndarray:
        self._ensure_tangential()
        nx, ny = self.grid.shape
        plan = self._plan(q.shape[:-2])
        plan.real_in[..., :nx, :ny] = q
        s = plan.forward()
        sx = s[..., 0, :, :]
        sy = s[..., 1, :, :]
        out = plan.spec_in
        np.multiply(self._xx, sx, out=out[..., 0, :, :])
        out[..., 0, :, :] += self._xy * sy
        np.multiply(self._xy, sx, out=out[..., 1, :, :])
        out[..., 1, :, :] += self._yy * sy
        return plan.inverse()[..., :nx, :ny].copy()

    def kernel(self, component: str = "zz") -> np.ndarray:
        """Real-space influence coefficients (non-periodic only) for inspection.

        Args:
            component: 'zz', 'xx', 'yy' or 'xy'.

        Returns:
            (nx, ny) relative displacement (mm/MPa) at offsets i·dx, j·dy from a loaded cell.
        """
        if component not in ("zz", "xx", "yy", "xy"):
            raise ValueError(f"component: must be one of 'zz', 'xx', 'yy', 'xy', got {component!r}")
        X, Y = np.meshgrid(np.arange(self.grid.shape[0]) * self.grid.dx,
                           np.arange(self.grid.shape[1]) * self.grid.dy, indexing="ij")
        return influence_coefficients(X, Y, self.grid.dx, self.grid.dy, self.young, self.poisson)[component]
