"""fe-joint's one logger, and the silencing of the libraries' chatter.

On a first run FFCx/dolfinx compile forms through cffi and distutils, which log every compiler
command at INFO on the root logger (about 60 lines between the progress lines) and reset the root
logger's level to INFO while doing so, so a level set beforehand does not hold. The handler
installed here therefore filters by record: below WARNING it passes only fe-joint's own records,
unless ``--debug``.
"""
from __future__ import annotations

import logging
import sys

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
