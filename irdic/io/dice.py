"""DICe (Sandia) stereo solution files ``DICe_solution_<n>.txt``: one file per frame.

Layout: optional header lines starting with ``***``, then one comma-separated
header row, then one row per subset in ``%.4E``::

    SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y,MODEL_COORDINATES_X,
    MODEL_COORDINATES_Y,MODEL_COORDINATES_Z,MODEL_DISPLACEMENT_X,MODEL_DISPLACEMENT_Y,
    MODEL_DISPLACEMENT_Z,SIGMA
    0,5.5500E+02,9.3000E+02,1.6353E-06,...

The 3-D position is model coordinates + model displacement (the model frame is
the one of the stereo calibration, in its length unit, here taken as mm).
Failed subsets have ``SIGMA`` (and ``MATCH``, ``GAMMA``) equal to -1.
"""

from __future__ import annotations

import logging
import os
import re
from typing import Any

import numpy as np
import xarray as xr

from ..errors import FormatError
from ._common import TextFile
from ._stage import extra_columns, stage_dataset
from ._tables import Header, check_unique, read_body, split_fields

__all__ = ["read_dice", "MODEL_COLUMNS"]

log = logging.getLogger(__name__)

MODEL_COLUMNS = ("MODEL_COORDINATES_X", "MODEL_COORDINATES_Y", "MODEL_COORDINATES_Z",
          "MODEL_DISPLACEMENT_X", "MODEL_DISPLACEMENT_Y", "MODEL_DISPLACEMENT_Z")
_FRAME_IN_NAME = re.compile(r"_(\d+)$")


def read_dice(path: str | os.PathLike) -> xr.Dataset:
    """Read one frame of a DICe stereo solution file.

    Parameters
    ----------
    path : path-like
        ``DICe_solution_<n>.txt`` of a stereo (3-D) analysis.

    Returns
    -------
    xarray.Dataset
        ``x(point, component)`` = MODEL_COORDINATES + MODEL_DISPLACEMENT and
        ``x_ref`` = MODEL_COORDINATES (mm), NaN rows where SIGMA is negative
        (DICe writes -1 for failed subsets) or a value is NaN. Coordinate
        ``point`` = SUBSET_ID (the row index when the column was not
        exported, ``attrs["point_id_source"] = "row"``; then, when
        COORDINATE_X/Y are present, ``attrs["point_key"]`` names them so that
        :func:`irdic.ingest.dic.ingest_dic` matches subsets between frames by
        their reference image position rather than by row). The other columns
        (SIGMA, GAMMA, image coordinates, ...) as ``(point)`` variables.
        ``attrs["frame_index"]`` from the file name. No time: DICe does not
        write one.

    Raises
    ------
    FormatError
        No header row, a 2-D solution (no MODEL_COORDINATES columns), bad
        cells (named by line and column), rows of the wrong length, no rows.
    DataError
        A SUBSET_ID occurs twice.
    """
    text = TextFile(path)
    p = text.path
    k, line = next(((i, ln) for i, ln in text.lines() if ln.strip() and not ln.lstrip().startswith("***")),
                   (None, ""))
    if k is None:
        raise FormatError("no column header row after the *** lines; expected SUBSET_ID, MODEL_COORDINATES_X, ...", p)
    header = Header.from_fields(split_fields(line, ","), k + 1, p)
    found = {b.upper() for b in header.bare}
    if not any(name in found for name in MODEL_COLUMNS):
        if {"COORDINATE_X", "DISPLACEMENT_X"} & found:
            raise FormatError(
                "this is a 2-D DICe solution (image COORDINATE_/DISPLACEMENT_ columns only); irdic needs the "
                "3-D positions of a stereo analysis: MODEL_COORDINATES_X/Y/Z and MODEL_DISPLACEMENT_X/Y/Z",
                p, k + 1,
            )
        raise FormatError(f"not a DICe solution header: found {header.describe()}; expected the comma-separated "
                          f"names SUBSET_ID, {', '.join(MODEL_COLUMNS)}, SIGMA", p, k + 1)
    j_model = header.require(MODEL_COLUMNS, what="a DICe stereo solution")
    rows = read_body(text, k + 1, header, sep=",", decimal=".", comment="***")
    j_id = header.find("SUBSET_ID")
    if j_id is not None:
        ids = rows.integers(j_id, what="SUBSET_ID")
        check_unique(ids, rows.line_nos, p, what="SUBSET_ID")
        id_source = "file"
    else:
        log.info("%s: no SUBSET_ID column; points are numbered by row", p)
        ids = np.arange(len(rows), dtype=np.int64)
        id_source = "row"
    x_ref = np.column_stack([rows.number(j) for j in j_model[:3]])
    x = x_ref + np.column_stack([rows.number(j) for j in j_model[3:]])
    j_sigma = header.find("SIGMA")
    valid = None
    if j_sigma is not None:
        sigma = rows.number(j_sigma, finite=False)
        valid = ~(sigma < 0)  # NaN sigma is caught by the NaN test of the coordinates
    skip = [*j_model] + [j for j in (j_id,) if j is not None]
    extras = extra_columns(rows, skip, strict=True)
    attrs: dict[str, Any] = {}
    if id_source == "row" and {"COORDINATE_X", "COORDINATE_Y"} <= {e[0] for e in extras}:
        # the subset centroid in the reference image names a subset in every frame
        attrs["point_key"] = "COORDINATE_X,COORDINATE_Y"
    m = _FRAME_IN_NAME.search(p.stem)
    if m:
        attrs["frame_index"] = int(m.group(1))
    return stage_dataset(ids, x, x_ref, path=p, fmt="dice", valid=valid, attrs=attrs, extras=extras,
                         point_id_source=id_source)
