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

FFTs use pyFFTW with plans built once per batch size and reused (threads configurable); without
pyFFTW it falls back to ``scipy.fft`` with the same number of workers. Spectra are stored transposed
(see ``_FFT2``) and the kernels carry the inverse transform's 1/N.
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
    """Unnormalised real 2D FFT pair over the last two axes of a (batch, nx, ny) field, zero-padded to
    (px, py) (DC-FFT: px = 2 nx, py = 2 ny) or not (periodic: px = nx, py = ny), plans built once.

    The spectrum is stored transposed, (batch, py//2 + 1, px), so that both complex passes run
    along contiguous rows: FFTW_ESTIMATE's in-place pass over strided columns took about twice as
    long (512², padded 1024²: 3.3 vs 1.5-1.9 ms per pass; one normal convolution 13.3 → 7.3 ms).
    Padding is pruned: the forward row pass runs on the nx rows that carry data (the padding rows
    of its output stay zero), and the inverse row pass makes only the nx rows that are kept. The
    spectral products are pointwise, so the layout only has to match the kernels'
    (``ElasticHalfSpace._build_spectra`` stores them transposed too).

    Transforms are unnormalised (``execute``): the 1/(px py) of the inverse is folded into the
    kernels, which saves a pass over the data per transform.

    Args:
        batch: leading shape of the fields, e.g. (B,) or (B, 2).
        n: grid shape (nx, ny) of the data.
        padded: transform shape (px, py), px ∈ {nx, 2 nx}, py ∈ {ny, 2 ny}.
        threads: FFTW threads.
        effort: FFTW planner flag ('FFTW_ESTIMATE' keeps results bit-identical run to run).
    """

    def __init__(self, batch: tuple[int, ...], n: tuple[int, int], padded: tuple[int, int],
                 threads: int, effort: str):
        batch = tuple(batch)
        (nx, ny), (px, py) = n, padded
        self.n, self.padded = (nx, ny), (px, py)
        ky = py // 2 + 1
        if _HAVE_FFTW:
            # real_in: the data sits in [..., :, :ny], the rest stays zero (the forward r2c
            # preserves its input); half: rows nx: stay zero (only [:nx] is ever written)
            self.real_in = pyfftw.zeros_aligned(batch + (nx, py), dtype="float64")
            self.half = pyfftw.zeros_aligned(batch + (px, ky), dtype="complex128")
            self.spec = pyfftw.zeros_aligned(batch + (ky, px), dtype="complex128")
            self.real_out = pyfftw.zeros_aligned(batch + (nx, py), dtype="float64")
            fl = (effort,)
            self._f_rows = pyfftw.FFTW(self.real_in, self.half[..., :nx, :], axes=(-1,),
                                       threads=threads, flags=fl)
            # strided read, contiguous write: FFTW handles this layout change at no extra cost
            self._f_cols = pyfftw.FFTW(np.swapaxes(self.half, -1, -2), self.spec, axes=(-1,),
                                       threads=threads, flags=fl)
            self._i_cols = pyfftw.FFTW(self.spec, self.spec, axes=(-1,), threads=threads,
                                       direction="FFTW_BACKWARD", flags=fl)
            # no FFTW_DESTROY_INPUT: with it ESTIMATE picks a plan 5x slower for this strided input
            self._i_rows = pyfftw.FFTW(np.swapaxes(self.spec[..., :nx], -1, -2), self.real_out,
                                       axes=(-1,), threads=threads, direction="FFTW_BACKWARD",
                                       flags=fl)
            # planning with MEASURE (if asked for) may scribble on the buffers
            self.real_in[...] = 0.0
            self.half[...] = 0.0
        else:  # pragma: no cover - exercised only without pyfftw
            self.real_in = np.zeros(batch + (nx, py))
            self.threads = threads

    def forward(self) -> np.ndarray:
        """Unnormalised spectrum of ``real_in`` (zero-padded), layout (..., py//2+1, px).

        Returns:
            the internal buffer ``spec`` (valid until the next call; may be modified in place
            before :meth:`inverse`).
        """
        if _HAVE_FFTW:
            self._f_rows.execute()
            self._f_cols.execute()
            return self.spec
        nx, ny = self.n  # pragma: no cover
        px, py = self.padded  # pragma: no cover
        s = _sfft.fft(_sfft.rfft(self.real_in, n=py, axis=-1, workers=self.threads), n=px, axis=-2,
                      workers=self.threads)  # pragma: no cover
        self.spec = np.ascontiguousarray(np.swapaxes(s, -1, -2))  # pragma: no cover
        return self.spec  # pragma: no cover

    def inverse(self) -> np.ndarray:
        """Unnormalised inverse of ``spec`` (overwritten), rows [:nx] of the padded field.

        Returns:
            the internal buffer ``real_out`` (..., nx, py), valid until the next call.
        """
        if _HAVE_FFTW:
            self._i_cols.execute()
            self._i_rows.execute()
            return self.real_out
        nx, ny = self.n  # pragma: no cover
        px, py = self.padded  # pragma: no cover
        c = _sfft.ifft(self.spec, n=px, axis=-1, norm="forward", workers=self.threads)  # pragma: no cover
        return _sfft.irfft(np.swapaxes(c[..., :nx], -1, -2), n=py, axis=-1, norm="forward",
                           workers=self.threads)  # pragma: no cover


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
        self._inv_size = 1.0 / (self.padded_shape[0] * self.padded_shape[1])
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
            spectra = {"zz": 2.0 / self.e_star * zz, "xx": 2.0 / g * xx, "yy": 2.0 / g * yy,
                       "xy": 2.0 / g * xy}
        else:
            ix = np.arange(px)
            iy = np.arange(py)
            ox = np.where(ix < nx, ix, ix - px) * self.grid.dx
            oy = np.where(iy < ny, iy, iy - py) * self.grid.dy
            # the tangential kernels are built on first use (normal-only solves skip their cost)
            names = ("zz",) if not tangential else ("xx", "yy", "xy")
            c = influence_coefficients(ox[:, None], oy[None, :], self.grid.dx, self.grid.dy,
                                       self.young, self.poisson, components=names)
            spectra = {name: np.fft.rfft2(c[name]) for name in names}
        self._tangential_ready = self.periodic or tangential
        for name, k in spectra.items():
            # kernels even in x and y have real spectra: real multipliers halve the product cost
            if np.iscomplexobj(k) and np.abs(k.imag).max() <= 1e-12 * np.abs(k.real).max():
                k = k.real
            # the layout of _FFT2's spectra (transposed), times the 1/(px py) its inverse leaves out
            setattr(self, "_" + name, np.ascontiguousarray(k.T) * self._inv_size)
        # a real multiplier repeated for the (re, im) pairs: the product on the complex spectrum
        # viewed as float64 is a plain real multiply (512²: 0.4 vs 1.4 ms for complex × real)
        if "zz" in spectra:
            self._zz_pairs = np.repeat(self._zz, 2, axis=-1) if not np.iscomplexobj(self._zz) else None
        if "xx" in spectra:
            # the same for the tangential kernels (xy is odd in x and in y: a real spectrum too);
            # the patch loops of the k_t definitions spent 7.7 s of 31 s in these products
            tan = (self._xx, self._yy, self._xy)
            self._tan_pairs = (None if any(np.iscomplexobj(k) for k in tan)
                               else tuple(np.repeat(k, 2, axis=-1) for k in tan))

    def _ensure_tangential(self) -> None:
        if not self._tangential_ready:
            self._build_spectra(tangential=True)

    @property
    def tangential_lipschitz(self) -> float:
        """Largest eigenvalue (mm/MPa) of the tangential operator (bound from its symbol)."""
        self._ensure_tangential()
        xx, yy, xy = (k.real / self._inv_size for k in (self._xx, self._yy, self._xy))
        return float(np.max(0.5 * (xx + yy) + np.sqrt(0.25 * (xx - yy) ** 2 + xy ** 2)))

    def _plan(self, batch: tuple[int, ...]) -> _FFT2:
        """FFT pair for a (flattened) batch shape, made on first use and kept."""
        batch = tuple(batch)
        plan = self._plans.get(batch)
        if plan is None:
            size = np.prod(batch + self.padded_shape)
            effort = self.planner if size <= 2 ** 22 else "FFTW_ESTIMATE"
            plan = _FFT2(batch, self.grid.shape, self.padded_shape, self.threads, effort)
            self._plans[batch] = plan
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
        lead = p.shape[:-2]
        # one plan per batch size: a single field and a batch of one share it
        plan = self._plan((int(np.prod(lead)),))
        plan.real_in[..., :ny] = p.reshape((-1, nx, ny))
        s = plan.forward()
        if self._zz_pairs is not None:
            sv = s.view(np.float64)
            np.multiply(sv, self._zz_pairs, out=sv)
        else:  # pragma: no cover - the Boussinesq kernel is even: its spectrum is real
            s *= self._zz
        return plan.inverse()[..., :ny].copy().reshape(lead + (nx, ny))

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
        lead = q.shape[:-3]
        plan = self._plan((int(np.prod(lead)), 2))
        plan.real_in[..., :ny] = q.reshape((-1, 2, nx, ny))
        s = plan.forward()
        if self._tan_pairs is not None:
            s = s.view(np.float64)     # real multipliers: (re, im) pairs times repeated reals
            xx, yy, xy = self._tan_pairs
        else:  # pragma: no cover - the Cerruti kernels' spectra are real
            xx, yy, xy = self._xx, self._yy, self._xy
        sx = s[:, 0]
        sy = s[:, 1]
        ux = xx * sx
        ux += xy * sy
        sy *= yy           # sy becomes u_y's spectrum in place, sx is still needed once
        sy += xy * sx
        sx[...] = ux
        return plan.inverse()[..., :ny].copy().reshape(lead + (2, nx, ny))

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
