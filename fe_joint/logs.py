"""fe-joint's one logger, and the silencing of the libraries' chatter.

On a first run FFCx/dolfinx compile forms through cffi and distutils, which log every compiler
command at INFO on the root logger (about 60 lines between the progress lines) and reset the root
logger's level to INFO while doing so, so a level set beforehand does not hold. The handler
installed here therefore filters by record: below WARNING it passes only fe-joint's own records,
unless ``--debug``.

numpy's floating-point warnings never reach the console either (:class:`NumericWarnings`): the
command line counts them and reports them in one line.
"""
from __future__ import annotations

import logging
import sys
import warnings

#: the package's logger; modules log through ``logging.getLogger(__name__)``, its children
LOGGER = logging.getLogger("fe_joint")


class _OwnInfoOnly(logging.Filter):
    """Pass warnings and errors of everyone, and lower levels of fe-joint's loggers only."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.WARNING or record.name.split(".")[0] == "fe_joint"


def configure_logging(debug: bool = False) -> logging.Handler:
    """One stderr handler on the root logger; the libraries' INFO/DEBUG records dropped unless
    ``debug``.

    Args:
        debug: also show fe-joint's debug messages and the libraries' INFO logs.
    Returns:
        the handler installed (replacing any earlier one of this function).
    """
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_fe_joint", False):
            root.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler._fe_joint = True
    handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
    if not debug:
        handler.addFilter(_OwnInfoOnly())
    root.addHandler(handler)
    root.setLevel(logging.DEBUG if debug else logging.WARNING)
    LOGGER.setLevel(logging.DEBUG if debug else logging.INFO)
    return handler


class NumericWarnings:
    """Context manager that keeps numpy's floating-point RuntimeWarnings (overflow, invalid
    value, divide by zero) off the console: each is logged at DEBUG on fe-joint's logger and
    counted, so the command line can report them in one line. Other warnings pass unchanged.

    Attributes:
        count: warnings caught (distinct locations: Python shows each location once).
        first: the first one's message, for the one-line report.
    """

    def __init__(self) -> None:
        self.count = 0
        self.first: str | None = None
        self._ctx = warnings.catch_warnings()

    def __enter__(self) -> "NumericWarnings":
        self._ctx.__enter__()
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, RuntimeWarning):
                self.count += 1
                self.first = self.first or f"{message} ({filename.rsplit('/', 1)[-1]}:{lineno})"
                LOGGER.debug("numpy warning: %s (%s:%d)", message, filename, lineno)
                return
            shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc) -> None:
        self._ctx.__exit__(*exc)

    def summary(self) -> str:
        """One line: how many and the first, or "" when none."""
        if not self.count:
            return ""
        return (f"{self.count} numerical warning{'s' if self.count > 1 else ''} from numpy "
                f"(first: {self.first}); --debug shows them")
