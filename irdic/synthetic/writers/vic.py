"""Writer of VIC-3D CSV exports, read by :func:`irdic.io.vic.read_vic`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ConfigError
from ...io.vic import REQUIRED_COLUMNS

__all__ = ["write_vic"]


def write_vic(path: str | os.PathLike, x_ref: Any, displacement: Any, *, sigma: Any = None,
              spacing: str = " ") -> Path:
    """Write a VIC-3D-style CSV (for tests and demos).

    Parameters
    ----------
    path : path-like
    x_ref, displacement : array_like, shape (n, 3)
        X, Y, Z and U, V, W in mm. Rows with NaN are written as VIC writes
        invalid points: zeros and ``sigma = -1``.
    sigma : array_like, shape (n,), optional
        0.01 where not given.
    spacing : str
        Text after each comma (``" "`` as in VIC-3D 7, ``""`` in older versions).

    Returns
    -------
    Path
    """
    xr_ = np.asarray(x_ref, dtype=np.float64)
    d = np.asarray(displacement, dtype=np.float64)
    if xr_.ndim != 2 or xr_.shape[1] != 3:
        raise ConfigError(f"x_ref must have shape (n, 3), got {xr_.shape}")
    n = xr_.shape[0]
    if d.shape != (n, 3):
        raise ConfigError(f"displacement must have shape ({n}, 3), got {d.shape}")
    sg = np.full(n, 0.01) if sigma is None else np.asarray(sigma, dtype=np.float64)
    if sg.shape != (n,):
        raise ConfigError(f"sigma must have shape ({n},), got {sg.shape}")
    if spacing.strip():
        raise ConfigError(f"spacing must be whitespace, got {spacing!r}")
    bad = ~(np.isfinite(xr_).all(1) & np.isfinite(d).all(1))
    values = np.column_stack([np.where(bad[:, None], 0.0, xr_), np.where(bad[:, None], 0.0, d),
                              np.where(bad, -1.0, sg)])
    sep = "," + spacing
    head = sep.join(f'"{c}"' for c in (*REQUIRED_COLUMNS, "sigma"))
    fmt = sep.join(["%.6f"] * 7)
    body = [fmt % tuple(row) for row in values.tolist()]
    out = Path(path)
    out.write_text("\n".join([head] + body) + "\n", encoding="utf-8", newline="\n")
    return out
