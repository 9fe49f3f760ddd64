"""Mapping of exceptions to the CLI's one-line messages and exit statuses."""
from __future__ import annotations

from .stages import StageNotBuilt


class JobFailed(RuntimeError):
    """A study job failed on some MPI rank; raised on every rank with the original's exit class.

    Attributes:
        job: name of the failed job.
        code: exit status of the original exception (see :func:`classify`).
    """

    def __init__(self, job: str, code: int, message: str) -> None:
        super().__init__(f"{job}: {message}")
        self.job, self.code = job, int(code)


def classify(e: BaseException) -> tuple[int, str]:
    """Exit status and one-line message for an exception that reached the CLI.

    Returns:
        (2, msg) for bad input (``ValueError`` and subclasses, e.g. ``CaseError``),
        (3, msg) for non-convergence (any ``ConvergenceError`` of the packages; the message
        carries the residual reached), (4, msg) for a stage not built yet, (1, msg) otherwise.
    """
    msg = " ".join(str(e).split()) or type(e).__name__
    if isinstance(e, JobFailed):
        return e.code, msg
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
