"""The irdic exception hierarchy.

Every problem irdic detects in user input is raised as a subclass of
:class:`IrdicError`, with a message written for the person who ran the job:
which file (and line) or which parameter, what was found and what was
expected. Code that catches ``IrdicError`` can therefore show ``str(err)``
to the user as it is.
"""

from __future__ import annotations

import os

__all__ = [
    "IrdicError",
    "FormatError",
    "DataError",
    "ConfigError",
    "CalibrationError",
    "GeometryError",
    "OutputError",
    "IrdicWarning",
]


class IrdicError(Exception):
    """Base class of every error irdic raises on purpose."""


class FormatError(IrdicError):
    """A file does not have the layout its format requires.

    Parameters
    ----------
    message : str
        What was found and what was expected.
    path : str or os.PathLike, optional
        The offending file.
    line : int, optional
        1-based line number in a text file (or record number in a binary one).
    """

    def __init__(self, message: str, path: str | os.PathLike | None = None, line: int | None = None):
        self.message = message
        self.path = None if path is None else os.fspath(path)
        self.line = line
        super().__init__(self._compose())

    def _compose(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path
            if self.line is not None:
                where += f", line {self.line}"
            where += ": "
        return where + self.message


class DataError(IrdicError):
    """Files are readable but their content is inconsistent.

    Examples: frames of different sizes in one series, non-increasing times,
    duplicate point IDs, an empty folder.
    """


class ConfigError(IrdicError):
    """A configuration value or function argument is invalid (the key is named)."""


class CalibrationError(IrdicError):
    """The camera calibration cannot be computed or is not trustworthy."""


class GeometryError(IrdicError):
    """A geometric construction failed (folded parametrisation, degenerate metric, ...)."""


class OutputError(IrdicError):
    """An output cannot be written (disk full, quota, permissions); the output is named, an older one is kept."""


class IrdicWarning(UserWarning):
    """Something in the input is suspicious but processing can go on.

    Example: a DIC export recorded with rigid body motion compensation active.
    """
