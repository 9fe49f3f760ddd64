"""Errors of the FE chain."""


class ConvergenceError(RuntimeError):
    """An iterative FE solve (eigen solver, contact active set) did not converge; the message gives
    the residual or state reached."""
