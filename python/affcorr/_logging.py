"""affcorr's logging: the library logs to the standard ``logging`` logger ``"affcorr"``
(silent unless the application configures logging); the CLI's ``-v`` / ``-q`` set its level.

    import logging
    logging.basicConfig(level=logging.INFO)   # affcorr's progress and timings on stderr
    logging.getLogger("affcorr").setLevel(logging.DEBUG)
"""

from __future__ import annotations

import logging
import sys

logger = logging.getLogger("affcorr")
logger.addHandler(logging.NullHandler())


def configure_cli(verbosity: int) -> None:
    """The CLI's logging: WARNING with ``-q`` (verbosity < 0), INFO by default, DEBUG with ``-v``;
    messages go to stderr as ``affcorr: message`` (results stay on stdout)."""
    level = logging.WARNING if verbosity < 0 else logging.INFO if verbosity == 0 else logging.DEBUG
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("affcorr: %(message)s"))
    for h in list(logger.handlers):
        if getattr(h, "_affcorr_cli", False):
            logger.removeHandler(h)
    handler._affcorr_cli = True  # type: ignore[attr-defined]
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
