"""fe-joint's error classes and how the command line reports them.

Three kinds of failure, three exit statuses (docs/design.md, "Errors"):

* :class:`CaseError` — input rejected by validation (a case key, an option): exit 2, one line
  naming the key and the allowed range, raised before anything is written.
* a ``ConvergenceError`` of any package (this one for the FE chain, :mod:`hbm`'s,
  :mod:`contact_bem`'s): exit 3, with the residual reached.
* anything else is a bug: exit 1, "internal error: …", ``--debug`` for the traceback.

An interrupted run (Ctrl-C, SIGTERM) exits 130 or 143 with one line (:mod:`fe_joint.cli`).
"""
from __future__ import annotations

import contact_bem
import hbm

EXIT_BUG, EXIT_INPUT, EXIT_CONVERGENCE = 1, 2, 3
#: after Ctrl-C (128 + SIGINT) and after SIGTERM (128 + SIGTERM; mpirun sends it on Ctrl-C)
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


class CaseError(ValueError):
    """A case file, preset or command-line value is invalid; the message names the key."""


class ArtifactError(CaseError):
    """A file of a run's folder is missing, truncated or unreadable; the message names its path.

    Exit 2 like bad input: the folder is the input of a resumed run or of ``fe-joint report``;
    running again rebuilds the file (the stage that wrote it is rerun when its record does not
    match the file).
    """


class ConvergenceError(RuntimeError):
    """An iterative FE solve (eigen solver, contact active set) did not converge; the message
    gives the residual or state reached."""


#: every package's non-convergence (all carry the residual in their message)
CONVERGENCE_ERRORS = (ConvergenceError, hbm.ConvergenceError, contact_bem.ConvergenceError)


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
    """Exit status and one-line message for an exception that reached the command line.

    Returns:
        (2, msg) for a :class:`CaseError`, (3, "did not converge: …") for any package's
        ConvergenceError, the original status for :class:`JobFailed`, and
        (1, "internal error: … (run with --debug for the traceback)") for anything else.
    """
    msg = " ".join(str(e).split()) or type(e).__name__
    if isinstance(e, JobFailed):
        return e.code, msg
    if isinstance(e, CaseError):
        return EXIT_INPUT, msg
    if isinstance(e, CONVERGENCE_ERRORS):
        return EXIT_CONVERGENCE, f"did not converge: {msg}"
    return EXIT_BUG, f"internal error: {type(e).__name__}: {msg} (run with --debug for the traceback)"
