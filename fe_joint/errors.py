"""Mapping of exceptions to the CLI's one-line messages and exit statuses."""
from __future__ import annotations

from .stages import StageNotBuilt


def classify(e: BaseException) -> tuple[int, str]:
    """Exit status and one-line message for an exception that reached the CLI.

    Returns:
        (2, msg) for bad input (``ValueError`` and subclasses, e.g. ``CaseError``),
        (3, msg) for non-convergence (any ``ConvergenceError`` of the packages; the message
        carries the residual reached), (4, msg) for a stage not built yet, (1, msg) otherwise.
    """
    msg = " ".join(str(e).split()) or type(e).__name__
    names = {c.__name__ for c in type(e).__mro__}
    if "ConvergenceError" in names:
        return 3, f"did not converge: {msg}"
    if isinstance(e, StageNotBuilt):
        return 4, msg
    if isinstance(e, (ValueError, KeyError, TypeError)):
        return 2, msg
    if isinstance(e, FileNotFoundError):
        return 2, msg
    return 1, f"{type(e).__name__}: {msg}"
