"""Regular cell-centred grid on which surfaces, pressures and tractions live."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import positive_scalar


@dataclass(frozen=True)
class Grid:
    """Rectangular grid of ``shape = (nx, ny)`` cells covering ``size = (lx, ly)`` mm.

    Arrays on the grid have shape (nx, ny) and are indexed ``[i, j]`` = cell centred at
    ``(origin[0] + (i + 0.5) dx, origin[1] + (j + 0.5) dy)``.

    Args:
        shape: number of cells (nx, ny), each >= 1.
        size: physical extent (lx, ly) in mm, each > 0.
        origin: lower-left corner (x0, y0) in mm.
    """

    shape: tuple[int, int]
    size: tuple[float, float]
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        try:
            nx, ny = (int(s) for s in self.shape)
        except (TypeError, ValueError):
            raise ValueError(f"shape: expected two integers (nx, ny), got {self.shape!r}") from None
        if nx < 1 or ny < 1 or (nx, ny) != tuple(self.shape):
            raise ValueError(f"shape: cell counts must be integers >= 1, got {self.shape!r}")
        try:
            lx, ly = self.size
        except (TypeError, ValueError):
            raise ValueError(f"size: expected two lengths (lx, ly) in mm, got {self.size!r}") from None
        lx = positive_scalar("size[0]", lx)
        ly = positive_scalar("size[1]", ly)
        ox, oy = (float(o) for o in self.origin)
        if not (np.isfinite(ox) and np.isfinite(oy)):
            raise ValueError(f"origin: must be finite, got {self.origin!r}")
        object.__setattr__(self, "shape", (nx, ny))
        object.__setattr__(self, "size", (lx, ly))
        object.__setattr__(self, "origin", (ox, oy))

    @property
    def dx(self) -> float:
        """Cell size along x (mm)."""
        return self.size[0] / self.shape[0]

    @property
    def dy(self) -> float:
        """Cell size along y (mm)."""
        return self.size[1] / self.shape[1]

    @property
    def cell_size(self) -> tuple[float, float]:
        """(dx, dy) in mm."""
        return (self.dx, self.dy)

    @property
    def cell_area(self) -> float:
        """Area of one cell (mm²)."""
        return self.dx * self.dy

    @property
    def area(self) -> float:
        """Total grid area (mm²)."""
        return self.size[0] * self.size[1]

    @property
    def x(self) -> np.ndarray:
        """Cell-centre x coordinates (nx,) in mm."""
        return self.origin[0] + (np.arange(self.shape[0]) + 0.5) * self.dx

    @property
    def y(self) -> np.ndarray:
        """Cell-centre y coordinates (ny,) in mm."""
        return self.origin[1] + (np.arange(self.shape[1]) + 0.5) * self.dy

    def meshgrid(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates X, Y, each (nx, ny), ``indexing='ij'``."""
        return np.meshgrid(self.x, self.y, indexing="ij")

    def check_field(self, name: str, value, *, allow_none: bool = False):
        """Validate a finite (nx, ny) field on this grid (ValueError otherwise)."""
        from .errors import finite_array
        return finite_array(name, value, self.shape, allow_none=allow_none)
