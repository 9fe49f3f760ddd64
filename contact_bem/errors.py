"""Exceptions and input validation shared by the contact_bem modules."""
from __future__ import annotations

import numpy as np


class ConvergenceError(RuntimeError):
    """An iterative contact solve did not reach its tolerance.

    Attributes:
        residual: error measure reached at the last iteration (dimensionless).
        iterations: iterations performed.
    """

    def __init__(self, message: str, residual: float = float("nan"), iterations: int = 0):
        super().__init__(f"{message} (residual reached {residual:.3e} after {iterations} iterations)")
        self.residual = float(residual)
        self.iterations = int(iterations)


class GrossSlipError(ValueError):
    """The requested tangential force reaches the Coulomb limit mu*P (no stick zone can exist)."""


def finite_array(name: str, value, shape: tuple | None = None, *, allow_none: bool = False,
                 dtype=float) -> np.ndarray | None:
    """Convert ``value`` to a finite float array, checking its shape.

    Args:
        name: argument name used in the error message.
        value: array-like input.
        shape: required shape (``None`` entries are wildcards), or None for any.
        allow_none: return None instead of raising when value is None.
        dtype: target dtype.

    Returns:
        The converted array.

    Raises:
        ValueError: wrong shape or non-finite entries.
    """
    if value is None:
        if allow_none:
            return None
        raise ValueError(f"{name}: required, got None")
    arr = np.asarray(value, dtype=dtype)
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s is None or s == a for s, a in zip(shape, arr.shape))
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    if dtype is float and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite (no NaN/inf)")
    return arr


def positive_scalar(name: str, value, *, allow_zero: bool = False, upper: float | None = None,
                    upper_open: bool = False) -> float:
    """Check a finite scalar is > 0 (or >= 0) and optionally below ``upper``.

    Raises:
        ValueError: naming the argument and the allowed range.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    lo_ok = v >= 0 if allow_zero else v > 0
    hi_ok = True if upper is None else (v < upper if upper_open else v <= upper)
    if not (np.isfinite(v) and lo_ok and hi_ok):
        lo = "[0" if allow_zero else "(0"
        hi = "inf)" if upper is None else (f"{upper})" if upper_open else f"{upper}]")
        raise ValueError(f"{name}: must be in {lo}, {hi}, got {value!r}")
    return v
