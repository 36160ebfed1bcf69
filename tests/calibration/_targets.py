"""Helpers for the calibration tests: marker order, erased markers, detected centres."""

import numpy as np


def book_order(tg):
    """Index into the book's grid-ordered arrays for each marker of the Dataset (sorted by ID)."""
    pos = {int(i): k for k, i in enumerate(tg.book.ids)}
    return np.array([pos[int(i)] for i in tg.markers.marker.values])


def erase(tg, keep):
    """Paint the markers with ``keep == False`` over with the wing temperature (same noise level)."""
    img = tg.image.values.astype(np.float64).copy()
    vv, uu = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    rng = np.random.default_rng(99)
    body = tg.truth.attrs["body_temperature"]
    for (u, v), r in zip(tg.truth.marker_centroid.values[~keep], tg.truth.marker_radius_px.values[~keep]):
        disc = np.hypot(uu - u, vv - v) <= 2 * r + 3
        img[disc] = body + rng.normal(0, 0.04, disc.sum())
    return tg.image.copy(data=img.astype(np.float32))



def uv_of(det):
    return np.column_stack([det.u.values, det.v.values])

