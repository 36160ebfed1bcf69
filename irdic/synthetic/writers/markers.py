"""Writer of marker-centre files in the ``;`` style read by :func:`irdic.io.markers.read_markers`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError
from ...io import COMPONENTS

__all__ = ["write_markers"]


def write_markers(path: str | os.PathLike, ids: Any, x: Any, *, decimals: int = 6) -> Path:
    """Write marker centres in the ``;`` style read by :func:`read_markers`.

    Parameters
    ----------
    path : path-like
    ids : array_like of int, shape (n,)
        Unique marker IDs.
    x : array_like, shape (n, 3)
        Marker centres, mm; NaN rows are written as ``nan`` (markers not seen).
    decimals : int
        Decimals written (mm).

    Returns
    -------
    Path
    """
    ids_arr = np.asarray(ids)
    if ids_arr.ndim != 1 or ids_arr.size == 0 or not np.issubdtype(ids_arr.dtype, np.integer):
        raise ConfigError(f"ids must be a non-empty 1-D integer array, got dtype {ids_arr.dtype} "
                          f"shape {ids_arr.shape}")
    if np.unique(ids_arr).size != ids_arr.size:
        raise ConfigError("ids must be unique")
    xs = np.asarray(x, dtype=np.float64)
    if xs.shape != (ids_arr.size, 3):
        raise ConfigError(f"x must have shape ({ids_arr.size}, 3), got {xs.shape}")
    if np.isinf(xs).any():
        raise ConfigError("x holds infinite values; use NaN for markers not seen")
    if not isinstance(decimals, (int, np.integer)) or isinstance(decimals, bool) or not 0 <= decimals <= 15:
        raise ConfigError(f"decimals must be an integer from 0 to 15, got {decimals!r}")
    head = ["# Calibration target marker centres (irdic)",
            "#" + "; ".join([f"{'ID':>9}"] + [f"{c + ' [mm]':>19}" for c in COMPONENTS])]
    fmt = "%10d; " + "; ".join([f"%19.{decimals}f"] * 3)
    body = [fmt % (i, *row) for i, row in zip(ids_arr.tolist(), xs.tolist())]
    out = Path(path)
    out.write_text("\n".join(head + body) + "\n", encoding="utf-8", newline="\n")
    return out
