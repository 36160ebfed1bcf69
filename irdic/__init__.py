"""irdic: couple stereo DIC point clouds with infrared thermography.

Temperatures, in-plane temperature gradients, temperature rates and strains at
material points of curved surfaces, after the projection-and-interpolation
method of the accompanying paper (see ``docs/method.md``).
"""

from importlib.metadata import PackageNotFoundError, version as _pkg_version

try:
    __version__ = _pkg_version("irdic")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

from .errors import (  # noqa: E402
    CalibrationError,
    ConfigError,
    DataError,
    FormatError,
    GeometryError,
    IrdicError,
    IrdicWarning,
)

__all__ = [
    "__version__",
    "IrdicError",
    "FormatError",
    "DataError",
    "ConfigError",
    "CalibrationError",
    "GeometryError",
    "IrdicWarning",
]
