"""Errors raised by the harmonic-balance package."""
from __future__ import annotations


class ConvergenceError(RuntimeError):
    """A nonlinear iteration (Newton, continuation, cycle closure) did not converge.

    Attributes:
        residual: the residual norm reached when the iteration stopped (the best one, where
            ``best`` is given).
        best: the best iterate reached, where the iteration can give it (``HarmonicBalance.
            newton``: a Solution with ``residual``), for a caller that can use a looser
            tolerance; else None.
    """

    def __init__(self, message: str, residual: float = float("nan"), best=None) -> None:
        super().__init__(f"{message} (residual reached: {residual:.3e})")
        self.residual = float(residual)
        self.best = best


class CycleNotClosed(ConvergenceError):
    """The AFT time march of a friction element did not reach a periodic state.

    Raised by the residual evaluation itself (not by a Newton iteration), so a continuation
    treats it as a failed trial point and shortens its step instead of ending the branch.
    """
