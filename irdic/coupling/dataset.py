"""The content of ``points.zarr``: the coupled values with their CF attributes, and the gather of its chunks."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from ..chunks import gathered
from ..footprint.visibility import Projection
from ..noise import IRNoise
from ..vocabulary import COMPONENTS, PIXEL_AXES, Status, cf_attrs, status_attrs

__all__ = ["count_attrs", "gathered_points", "points_dataset"]


def _pixel_uncertainty(camera, pr: Projection, pix_out: np.ndarray) -> np.ndarray:
    """The calibration's share of the position error (px, (n_t, M)), for the uncertainty budget downstream."""
    n_t, M = pr.valid.shape
    pix_std = np.full(n_t * M, np.nan)
    if camera.covariance is not None and pr.front.any():
        pix_std[pr.front] = camera.projection_uncertainty(pr.flat_x[pr.front])
    return np.where(np.isfinite(pix_out[..., 0]), pix_std.reshape(n_t, M), np.nan)


def points_dataset(dic, calibration, camera, pr: Projection, t_ir, counts, noise, gains, *, theta, gu, gv, rate, edge,
                    status, visible, masks) -> xr.Dataset:
    """The content of ``points.zarr``: variables with their CF attributes, calibration summary in ``attrs``."""
    pix_out = np.where(pr.valid[..., None] & np.isfinite(pr.pix), pr.pix, np.nan)
    geo = camera.decompose()
    a = lambda name: cf_attrs("points", name)  # noqa: E731
    tp, tpa = ("time", "point"), ("time", "point", "axis")
    return xr.Dataset(
        {
            "temperature": (tp, theta.astype(np.float32), a("temperature")),
            "pixel": (tpa, pix_out, a("pixel")),
            "pixel_std": (tp, _pixel_uncertainty(camera, pr, pix_out), a("pixel_std")),
            "temperature_pixel_gradient": (tpa, np.stack([gu, gv], axis=-1), a("temperature_pixel_gradient")),
            "temperature_local_rate": (tp, rate, a("temperature_local_rate")),
            "visible": (tp, visible, a("visible")),
            "edge_distance": (tp, edge, a("edge_distance")),
            "status": (tp, status, status_attrs()),
            "x": (("time", "point", "component"), pr.x, a("x")),
            "mask_pixels": (("time",), masks.sum(axis=(1, 2)).astype(np.int64), a("mask_pixels")),
        },
        coords={"time": ("time", dic["time"].values.astype(float), a("time")),
                "point": dic["point"].values, "component": np.array(COMPONENTS, dtype=object),
                "axis": np.array(PIXEL_AXES, dtype=object)},
        attrs={
            "calibration_rms_px": float(calibration["rms_px"]) if "rms_px" in calibration else np.nan,
            "calibration_projection_matrix": np.asarray(camera.M).ravel().tolist(),
            "calibration_camera_centre_mm": np.asarray(geo.C).tolist(),
            "calibration_focal_length_px": float(geo.focal_length_px),
            "ir_time_span_s": [float(t_ir[0]), float(t_ir[-1])],
            "ir_frames": int(t_ir.size),
            **{f"count_{k}": v for k, v in counts.items()},
            "ir_noise_k": float(noise.level), "ir_noise_temporal_k": float(noise.temporal),
            "ir_noise_spatial_k": float(noise.spatial), "ir_quantisation_k": float(noise.quantisation),
            # white pixel noise sigma -> sigma * gain at the point (irdic.noise.interpolation_noise_gains)
            "ir_noise_gain_temperature": float(gains.temperature),
            "ir_noise_gain_gradient_per_px": float(gains.gradient), "ir_noise_gain_rate_per_s": float(gains.rate),
        },
    )


def count_attrs(status: np.ndarray) -> dict:
    """``count_<status>`` attributes of ``points.zarr``: how many (time, point) pairs have each status."""
    return {f"count_{s.name.lower()}": int((status == s).sum()) for s in Status}


def gathered_noise(attrs: Sequence[Mapping]) -> dict:
    """The ``ir_noise*`` attributes of the gathered ``points.zarr`` from those of its chunks.

    Each chunk estimated the noise on its own IR window; the record's
    estimate is the median of the chunks' (finite) estimates, component by
    component, so one chunk with a hot spot or few specimen pixels does not
    decide it. ``ir_noise_k`` is then the temporal median, failing that the
    spatial one (:attr:`irdic.noise.IRNoise.level`). The gains are the same
    in every chunk (computed from the record's frame times).
    """
    def median(key):
        v = np.array([float(a.get(key, np.nan)) for a in attrs])
        v = v[np.isfinite(v)]
        return float(np.median(v)) if v.size else float("nan")

    noise = IRNoise(median("ir_noise_temporal_k"), median("ir_noise_spatial_k"), median("ir_quantisation_k"), 0)
    return {"ir_noise_k": float(noise.level), "ir_noise_temporal_k": noise.temporal,
            "ir_noise_spatial_k": noise.spatial, "ir_quantisation_k": noise.quantisation}


def gathered_points(stores: Sequence[xr.Dataset]) -> tuple[xr.Dataset, list[xr.Dataset]]:
    """The record's ``points.zarr`` from its time chunks' stores (in time order): the first chunk with the
    record's attributes, and the other chunks to append (:func:`irdic.chunks.gathered`).

    The status counts are summed over the chunks, one chunk's status at a
    time; the noise is the chunks' median (:func:`gathered_noise`).
    """
    counts = {}
    for c in stores:
        for k, v in count_attrs(c["status"].values).items():
            counts[k] = counts.get(k, 0) + v
    ds, rest = gathered(stores)
    ds.attrs = {k: v for k, v in ds.attrs.items() if not k.startswith("count_") and k != "chunk"}
    ds.attrs.update(counts)
    ds.attrs.update(gathered_noise([c.attrs for c in stores]))
    return ds, rest
