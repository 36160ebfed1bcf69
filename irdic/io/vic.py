"""VIC-3D (Correlated Solutions) CSV exports: one file per frame.

Layout: one quoted, comma(-plus-space) separated header row, then one row per
grid point::

    "X", "Y", "Z", "U", "V", "W", "sigma", "x", "y", "u", "v", "exx", ...
    -12.345, 3.210, 0.512, 0.0012, -0.0003, 0.0101, 0.0123, 512, 384, 0.12, -0.03, ...

Upper-case ``X, Y, Z`` are the reference 3-D coordinates and ``U, V, W`` the
displacement (mm); lower-case ``x, y, u, v`` are image coordinates and
displacements in px, so names are matched case-sensitively. Spacing and
quoting differ between versions. Invalid points keep their grid row with
``sigma = -1``. There is no point ID column: points are numbered by row and
matched between frames by their reference image position ``x, y``.
"""

from __future__ import annotations

import logging
import os

import numpy as np
import xarray as xr

from ..errors import FormatError
from ._common import TextFile
from ._stage import extra_columns, stage_dataset
from ._tables import Header, read_body, split_fields
from .units import length_scale

__all__ = ["read_vic", "REQUIRED_COLUMNS"]

log = logging.getLogger(__name__)

REQUIRED_COLUMNS = ("X", "Y", "Z", "U", "V", "W")
# image-plane columns would clash with the Dataset's own x
_IMAGE_NAMES = {"x": "x_image", "y": "y_image", "u": "u_image", "v": "v_image"}


def _sep_of(header_line: str) -> str | None:
    outside = "".join(part for k, part in enumerate(header_line.split('"')) if k % 2 == 0)
    for sep in (",", ";", "\t"):
        if sep in outside:
            return sep
    return None


def read_vic(path: str | os.PathLike) -> xr.Dataset:
    """Read one frame of a VIC-3D CSV export.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    xarray.Dataset
        ``x(point, component)`` = (X+U, Y+V, Z+W) and ``x_ref`` = (X, Y, Z), mm,
        NaN rows where ``sigma`` is negative (VIC writes -1) or a value is
        NaN. Coordinate ``point`` = row index (``attrs["point_id_source"] =
        "row"``): VIC has no ID column. When the image columns ``x, y`` (the
        subset centre in the reference image) are present,
        ``attrs["point_key"] = "x_image,y_image"`` tells
        :func:`irdic.ingest.dic.ingest_dic` to match points between frames by
        them rather than by row. Other columns as ``(point)`` variables; the
        image columns x, y, u, v are renamed ``x_image``, ``y_image``,
        ``u_image``, ``v_image``.

    Raises
    ------
    FormatError
        Missing X/Y/Z/U/V/W columns (e.g. a VIC-2D export), bad cells
        (named by line and column), rows of the wrong length, no rows.
    """
    text = TextFile(path)
    p = text.path
    k, line = next(((i, ln) for i, ln in text.lines() if ln.strip()), (None, ""))
    if k is None:
        raise FormatError("file holds only blank lines; expected a VIC-3D CSV header", p)
    sep = _sep_of(line)
    header = Header.from_fields(split_fields(line, sep), k + 1, p)
    if any(header.find(n, case=True) is None for n in REQUIRED_COLUMNS):
        present = set(header.bare)
        if {"x", "y"} <= present and "Z" not in present:
            raise FormatError(
                f"no 3-D columns: found {header.describe()}; this looks like a 2-D (image plane) export, irdic "
                "needs a VIC-3D export with X, Y, Z, U, V, W in mm", p, k + 1)
    j_all = header.require(REQUIRED_COLUMNS, what="a VIC-3D export", case=True)
    rows = read_body(text, k + 1, header, sep=sep, decimal=".")

    def coord(j: int) -> np.ndarray:
        return rows.number(j) * length_scale(header.units[j], header.names[j], p, header.line)

    x_ref = np.column_stack([coord(j) for j in j_all[:3]])
    x = x_ref + np.column_stack([coord(j) for j in j_all[3:]])
    j_sigma = header.find("sigma", case=True)
    valid = None
    if j_sigma is not None:
        sigma = rows.number(j_sigma, finite=False)
        valid = ~(sigma < 0)
    else:
        log.info("%s: no sigma column; only NaN values mark invalid points", p)
    extras = extra_columns(rows, j_all, strict=True, rename=_IMAGE_NAMES, suffix="_image")
    ids = np.arange(len(rows), dtype=np.int64)
    attrs = {}
    if {"x_image", "y_image"} <= {e[0] for e in extras}:
        # the subset centre in the reference image names a grid point in every frame
        attrs["point_key"] = "x_image,y_image"
    return stage_dataset(ids, x, x_ref, path=p, fmt="vic", valid=valid, extras=extras, attrs=attrs,
                         point_id_source="row")
