"""contact_bem — FFT boundary-element rough contact (normal, tangential partial slip, stiffness).

Public API (docs/design.md, "Public API")::

    from contact_bem import Grid, gaussian_surface, ElasticHalfSpace, solve_normal, solve_tangential
    grid = Grid(shape=(nx, ny), size=(lx, ly))
    z = gaussian_surface(grid, rq=0.01, corr_length=0.5, seed=0)
    hs = ElasticHalfSpace(grid, young=198400.0, poisson=0.3, periodic=False)
    ns = solve_normal(hs, gap=z.max() - z, load=F)
    path = solve_tangential(hs, ns, mu=0.6, forces=[(qx, qy), ...])

Only numpy, scipy and pyfftw are imported (never dolfinx).
"""
from .errors import ConvergenceError, GrossSlipError
from .grid import Grid
from .surface import SurfaceStatistics, gaussian_surface, surface_statistics
from .halfspace import ElasticHalfSpace, influence_coefficients
from .normal import NormalSolution, solve_normal
from .tangential import TangentialState, solve_tangential
from .stiffness import (NormalStiffness, PatchStiffness, TangentialLoop, TangentialStiffness,
                        load_approach_curve, mindlin_ratio, normal_stiffness, patch_normal_stiffness,
                        patch_stiffness, patch_tangential_stiffness, tangential_loop,
                        tangential_stiffness)
from .stiffness_definitions import (LAYER_CAP, BulkStiffness, LoopStiffness, layer_stiffness,
                                    patch_bulk_stiffness, patch_loop_stiffness)
from .coupling import cell_average, extract_patches, macro_gap
from . import reference

__all__ = [
    "ConvergenceError", "GrossSlipError", "Grid", "SurfaceStatistics", "gaussian_surface",
    "surface_statistics", "ElasticHalfSpace", "influence_coefficients", "NormalSolution",
    "solve_normal", "TangentialState", "solve_tangential", "NormalStiffness", "PatchStiffness",
    "TangentialLoop", "TangentialStiffness", "load_approach_curve", "mindlin_ratio",
    "normal_stiffness", "patch_normal_stiffness", "patch_stiffness", "patch_tangential_stiffness",
    "tangential_loop", "tangential_stiffness", "cell_average", "extract_patches", "macro_gap",
    "reference", "LAYER_CAP", "BulkStiffness", "LoopStiffness", "layer_stiffness",
    "patch_bulk_stiffness", "patch_loop_stiffness",
]
