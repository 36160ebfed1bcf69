"""Readers for the raw exports of IR cameras and DIC systems.

Public entry points (other tools and the tests rely on these names):

- :func:`read_ir` -> :class:`xarray.DataArray` of temperatures in °C, dims
  ``("v", "u")`` for one frame or ``("time", "v", "u")`` for a sequence.
  ``u``/``v`` are full-sensor pixel coordinates (column/row, 0-based, pixel
  centres on integers, ``v`` downwards): a cropped export keeps its sensor
  position. Frame time (s) in the ``time`` coordinate when known; source
  metadata in ``attrs``.
- :func:`read_dic` -> :class:`xarray.Dataset` for one DIC stage: ``x(point,
  component)`` current coordinates in mm, coordinate ``point`` = the software's
  point IDs, ``component = ["x", "y", "z"]``; invalid points are NaN; the stage
  time (s) as scalar coordinate ``time`` when the file has one.
- :func:`read_markers` -> :class:`xarray.Dataset` ``x(marker, component)`` (mm)
  of the calibration target's marker centres, coordinate ``marker`` = IDs.

Each format lives in its own module (``irbis``, ``irb``, ``flir``, ``stack``,
``nodemap``, ``dice``, ``vic``, ``table``, ``markers``); this module only
detects the format and dispatches.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import ConfigError, FormatError
from ._common import head_bytes

__all__ = ["read_ir", "read_dic", "read_markers", "detect_ir_format", "detect_dic_format",
           "IR_FORMATS", "DIC_FORMATS", "COMPONENTS"]

IR_FORMATS = ("irbis", "irb", "flir", "tiff", "npy")
DIC_FORMATS = ("nodemap", "dice", "vic", "table")
#: labels of the ``component`` dimension of DIC coordinates (``x``, ``x_ref``, marker centres)
COMPONENTS = ("x", "y", "z")


def detect_ir_format(path: str | os.PathLike) -> str:
    """Guess the IR format of ``path`` from its first bytes and its suffix."""
    p = Path(path)
    head = head_bytes(p)
    suffix = p.suffix.lower()
    if head.startswith(b"\xffIRB"):
        return "irb"
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head[:4] in (b"FFF\x00", b"AFF\x00"):
        return "flir"
    if head.startswith(b"\xff\xd8"):
        from .flir import is_radiometric_jpeg
        from .flir_jpeg import plain_jpeg_message

        if is_radiometric_jpeg(p):
            return "flir"
        raise FormatError(plain_jpeg_message(p), p)
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    text = head.lstrip(b"\xef\xbb\xbf").lstrip()
    if text.startswith(b"[Settings]") or b"[Data]" in head or text.startswith(b"[Parameter]"):
        return "irbis"
    raise FormatError(
        f"cannot tell the IR format (suffix {suffix or 'none'!r}); expected an IRBIS text export "
        "(starting with [Settings]), an InfraTec .irb file, a FLIR .seq/.csq/.fff file or "
        "radiometric JPEG, a TIFF stack or a .npy array, "
        "or set the format explicitly",
        p,
    )


def detect_dic_format(path: str | os.PathLike) -> str:
    """Guess the DIC export format of ``path`` from its first lines."""
    p = Path(path)
    head = head_bytes(p, 16384).decode("latin-1", errors="replace")
    lines = [ln.strip() for ln in head.splitlines() if ln.strip()]
    low = head.lower()
    if lines and lines[0].startswith("#") and ("x_undef" in low or "current_stage" in low):
        return "nodemap"
    # DICe may be exported without SUBSET_ID; its MODEL_* column pair is specific enough
    if lines and (lines[0].startswith("***") or "model_coordinates" in low
                  and ("subset_id" in low or "model_displacement" in low)):
        return "dice"
    if lines and lines[0].startswith('"') and "sigma" in low:
        return "vic"
    raise FormatError(
        "cannot tell the DIC export format; expected a ZEISS/ARAMIS nodemap (# header with x_undef), "
        "a DICe solution file (SUBSET_ID, MODEL_COORDINATES_*) or a VIC-3D CSV (quoted header with sigma); "
        "for other CSV exports set format: table and give the column mapping",
        p,
    )


def read_ir(path: str | os.PathLike, format: str = "auto", **kwargs):
    """Read an IR export as temperatures in °C.

    Parameters
    ----------
    path : path-like
        One file: an IRBIS text export (one frame), an ``.irb`` image or
        sequence, a FLIR ``.seq``/``.csq``/``.fff`` file or radiometric JPEG,
        a multi-page TIFF or a ``.npy`` stack of temperatures.
    format : {"auto", "irbis", "irb", "flir", "tiff", "npy"}
        File format; ``"auto"`` detects it from the content.
    **kwargs
        Passed to the format's reader (``emissivity`` and
        ``reflected_temperature`` for ``"flir"``).

    Returns
    -------
    xarray.DataArray
        float32 temperatures (°C), dims ``("v", "u")`` or ``("time", "v", "u")``.
    """
    fmt = detect_ir_format(path) if format == "auto" else format
    if fmt == "irbis":
        from .irbis import read_irbis as reader
    elif fmt == "irb":
        from .irb import read_irb as reader
    elif fmt == "flir":
        from .flir import read_flir as reader
    elif fmt == "tiff":
        from .stack import read_tiff as reader
    elif fmt == "npy":
        from .stack import read_npy as reader
    else:
        raise ConfigError(f"unknown IR format {format!r}; expected one of auto, {', '.join(IR_FORMATS)}")
    return reader(path, **kwargs)


def read_dic(path: str | os.PathLike, format: str = "auto", **kwargs):
    """Read one DIC stage export.

    Parameters
    ----------
    path : path-like
        One stage file.
    format : {"auto", "nodemap", "dice", "vic", "table"}
        Export format; ``"table"`` is a generic CSV and needs ``columns=``.
    **kwargs
        Passed to the format's reader (``columns`` for ``"table"``).

    Returns
    -------
    xarray.Dataset
        ``x(point, component)`` in mm (NaN for invalid points).
    """
    fmt = detect_dic_format(path) if format == "auto" else format
    if fmt == "nodemap":
        from .nodemap import read_nodemap as reader
    elif fmt == "dice":
        from .dice import read_dice as reader
    elif fmt == "vic":
        from .vic import read_vic as reader
    elif fmt == "table":
        from .table import read_table as reader
    else:
        raise ConfigError(f"unknown DIC format {format!r}; expected one of auto, {', '.join(DIC_FORMATS)}")
    return reader(path, **kwargs)


def read_markers(path: str | os.PathLike, **kwargs):
    """Read the marker centres of a calibration target (ID, x, y, z in mm).

    Returns
    -------
    xarray.Dataset
        ``x(marker, component)`` in mm, coordinate ``marker`` = marker IDs.
    """
    from .markers import read_markers as reader

    return reader(path, **kwargs)
