"""Writer of DICe stereo solution files, read by :func:`irdic.io.dice.read_dice`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError
from ...io.dice import MODEL_COLUMNS

__all__ = ["write_dice"]


def write_dice(path: str | os.PathLike, ids: Any, model_coordinates: Any, model_displacement: Any, *,
               sigma: Any = None, image_coordinates: Any = None, header_lines: Any = None) -> Path:
    """Write a DICe-style stereo solution file (for tests and demos).

    Parameters
    ----------
    path : path-like
    ids : array_like of int, shape (n,)
        SUBSET_ID values.
    model_coordinates, model_displacement : array_like, shape (n, 3)
        mm. Rows with NaN in either are written as DICe writes failed
        subsets: displacement 0 and SIGMA -1.
    sigma : array_like, shape (n,), optional
        Matching uncertainty; 0.01 where not given.
    image_coordinates : array_like, shape (n, 2), optional
        COORDINATE_X/Y in px; written (with zero DISPLACEMENT_X/Y) when given.
    header_lines : sequence of str, optional
        Text written as ``*** <line>`` before the header row.

    Returns
    -------
    Path
    """
    ids_arr = np.asarray(ids)
    if ids_arr.ndim != 1 or not np.issubdtype(ids_arr.dtype, np.integer):
        raise ConfigError(f"ids must be a 1-D integer array, got dtype {ids_arr.dtype} shape {ids_arr.shape}")
    n = ids_arr.size
    mc = np.asarray(model_coordinates, dtype=np.float64)
    md = np.asarray(model_displacement, dtype=np.float64)
    for name, a in (("model_coordinates", mc), ("model_displacement", md)):
        if a.shape != (n, 3):
            raise ConfigError(f"{name} must have shape ({n}, 3), got {a.shape}")
    sg = np.full(n, 0.01) if sigma is None else np.asarray(sigma, dtype=np.float64)
    if sg.shape != (n,):
        raise ConfigError(f"sigma must have shape ({n},), got {sg.shape}")
    failed = ~(np.isfinite(mc).all(1) & np.isfinite(md).all(1))
    mc = np.where(np.isfinite(mc), mc, 0.0)
    md = np.where(failed[:, None], 0.0, md)
    sg = np.where(failed, -1.0, sg)
    names = ["SUBSET_ID"]
    cols = []
    if image_coordinates is not None:
        ic = np.asarray(image_coordinates, dtype=np.float64)
        if ic.shape != (n, 2):
            raise ConfigError(f"image_coordinates must have shape ({n}, 2), got {ic.shape}")
        names += ["COORDINATE_X", "COORDINATE_Y", "DISPLACEMENT_X", "DISPLACEMENT_Y"]
        cols += [ic, np.zeros((n, 2))]
    names += [*MODEL_COLUMNS, "SIGMA"]
    cols += [mc, md, sg[:, None]]
    values = np.column_stack(cols)
    fmt = "%d," + ",".join(["%.4E"] * values.shape[1])
    head = [f"*** {ln}" for ln in (header_lines or [])]
    body = [fmt % (i, *row) for i, row in zip(ids_arr.tolist(), values.tolist())]
    out = Path(path)
    out.write_text("\n".join(head + [",".join(names)] + body) + "\n", encoding="utf-8", newline="\n")
    return out
