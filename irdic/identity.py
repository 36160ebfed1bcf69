"""Whether the stores handed to a stage belong together.

Each store says which stage wrote it (:func:`irdic.store.open_store` checks
the kind); this module checks what ties two stores: ``points.zarr`` records
the projection matrix of the calibration it was coupled with, and every
store of an experiment after ingest carries the DIC point IDs and times.
A store of another experiment or setup would otherwise run through and give
numbers that look plausible (a rotated camera changes the convective rate
by ~15 %).
"""

from __future__ import annotations

import os

import numpy as np
import xarray as xr

from .camera import load_camera
from .errors import DataError
from .store import open_store

__all__ = ["same_calibration", "same_points", "projection_fingerprint", "fields_inputs"]

#: Relative difference of two normalised projection matrices still taken for the same calibration (the
#: matrix goes through float64 JSON text, which keeps it to the last bit; 1e-9 leaves room for nothing else)
SAME_PROJECTION = 1e-9


def projection_fingerprint(M: np.ndarray) -> np.ndarray:
    """A 3x4 projection matrix as 12 numbers independent of its arbitrary scale and sign (unit norm, M[2,3] >= 0)."""
    M = np.asarray(M, dtype=float).reshape(3, 4)
    M = M / np.linalg.norm(M)
    return (M if M[2, 3] >= 0 else -M).ravel()


def same_calibration(points: xr.Dataset, points_path: str | os.PathLike, M: np.ndarray,
                     calibration_path: str | os.PathLike) -> None:
    """Refuse a calibration other than the one ``points`` was coupled with.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``, with its ``calibration_projection_matrix`` attribute (12 numbers).
    M : ndarray, shape (3, 4)
        Projection matrix of the calibration handed to the stage.

    Raises
    ------
    DataError
        Naming both stores and how far the projections differ.
    """
    recorded = points.attrs.get("calibration_projection_matrix")
    if recorded is None:
        return  # points from a release before the record: nothing to compare with
    a, b = projection_fingerprint(recorded), projection_fingerprint(M)
    diff = float(np.linalg.norm(a - b))
    if not diff <= SAME_PROJECTION:
        raise DataError(f"{calibration_path}: is not the calibration {points_path} was coupled with (the projection "
                        f"matrices differ by {diff:.3g}, relative); give the calibration.zarr of the experiment's "
                        "setup, or couple again with this one")


def same_points(a: xr.Dataset, a_path: str | os.PathLike, b: xr.Dataset, b_path: str | os.PathLike) -> None:
    """Refuse two stores of one experiment that hold different DIC points or times.

    Raises
    ------
    DataError
        Naming both stores and the first difference (point count, IDs or times).
    """
    for coord in ("point", "time"):
        if coord not in a.coords or coord not in b.coords:
            continue
        va, vb = a[coord].values, b[coord].values
        if va.shape != vb.shape:
            raise DataError(f"{b_path}: has {vb.size} {coord}s, {a_path} has {va.size}; the two stores are not of "
                            "the same experiment (or one is out of date): run the stages again")
        if coord == "time":
            differ = ~np.isclose(va.astype(float), vb.astype(float), rtol=0, atol=1e-9)
        else:
            differ = va != vb
        if differ.any():
            k = int(np.flatnonzero(differ)[0])
            unit = " s" if coord == "time" else ""
            raise DataError(f"{b_path}: {coord} {k} is {_plain(vb[k])}{unit}, in {a_path} it is "
                            f"{_plain(va[k])}{unit}; the two stores are not of the same experiment (or one is out "
                            "of date): run the stages again")


def _plain(value) -> str:
    """A numpy scalar as the user wrote it (``0.5``, ``17``), not its repr."""
    return str(value.item() if isinstance(value, np.generic) else value)


def fields_inputs(points_path, calibration_path, dic_path=None, machine_path=None) -> tuple:
    """The stores of the fields stage, opened and checked to belong together.

    Returns
    -------
    tuple
        ``(points, calibration, dic or None, machine or None)`` datasets.

    Raises
    ------
    DataError
        A store of another kind (:func:`irdic.store.open_store`), a
        calibration other than the one the points were coupled with, or a
        ``dic.zarr`` of other points or times.
    """
    points, calibration = open_store(points_path, "couple"), open_store(calibration_path, "calibrate")
    same_calibration(points, points_path, load_camera(calibration).M, calibration_path)
    dic = open_store(dic_path, "ingest-dic") if dic_path is not None else None
    if dic is not None:
        same_points(points, points_path, dic, dic_path)
    machine = open_store(machine_path, "ingest-machine") if machine_path is not None else None
    return points, calibration, dic, machine
