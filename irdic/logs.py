"""Logging for stage scripts and the CLI.

:func:`stage_logging` sends irdic's log records to a file (the Snakemake
``log:`` of the rule) and to stderr, and turns an :class:`~irdic.errors.IrdicError`
into one readable line in the log and a non-zero exit instead of a traceback;
it also limits BLAS and OpenMP to the threads the stage was given
(:func:`irdic.threads.stage_threads`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import warnings
from typing import Iterator

from .errors import IrdicError
from .threads import stage_threads

__all__ = ["stage_logging", "configure"]

_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def configure(log_path: str | os.PathLike | None = None, level: int = logging.INFO) -> logging.Logger:
    """Send the ``irdic`` logger to stderr and, if given, to ``log_path``."""
    logger = logging.getLogger("irdic")
    logger.setLevel(level)
    for h in list(logger.handlers):
        logger.removeHandler(h)
    fmt = logging.Formatter(_FORMAT, datefmt="%H:%M:%S")
    stream = logging.StreamHandler(sys.stderr)
    stream.setFormatter(fmt)
    logger.addHandler(stream)
    if log_path is not None:
        os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
        fh = logging.FileHandler(log_path, mode="w", encoding="utf-8")
        fh.setFormatter(fmt)
        logger.addHandler(fh)
    logging.captureWarnings(True)
    wlog = logging.getLogger("py.warnings")
    for h in logger.handlers:
        if h not in wlog.handlers:
            wlog.addHandler(h)
    return logger


@contextlib.contextmanager
def stage_logging(log_path: str | os.PathLike | None, stage: str, *,
                  threads: int | None = None) -> Iterator[logging.Logger]:
    """Run a stage with logging to ``log_path``; exit(1) with a clear line on an irdic error.

    ``threads``: CPU threads the stage was given (Snakemake's ``threads``);
    None: all cores.
    """
    logger = configure(log_path)
    try:
        with stage_threads(threads) as n, warnings.catch_warnings():
            logger.info("irdic %s: start (%d thread%s)", stage, n, "" if n == 1 else "s")
            warnings.simplefilter("default")
            yield logger
    except IrdicError as exc:
        logger.error("%s failed: %s", stage, exc)
        raise SystemExit(f"irdic {stage} failed: {exc}") from None
    logger.info("irdic %s: done", stage)
