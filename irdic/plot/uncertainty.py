"""What the figures say about how far a mapped field can be trusted: its standard uncertainty against its value.

The fields stage stores a standard uncertainty beside every field
(``<field>_std``) and flags where the method's own bias dominates
(``<field>_bias_dominated``); ``points.zarr`` records the IR noise and the
interpolation's noise gains. The map figures turn those into one sentence of
their caption (which ``irdic report`` shows beside the figure): the median
standard uncertainty, which panels are noise-dominated, and how many points
are bias-dominated.

A panel is *noise-dominated* when

- for a quantity judged against zero (gradient, rate, strain), fewer than
  half of its points lie more than :data:`RESOLVED_STDS` standard
  uncertainties from zero: the pattern drawn is mostly noise;
- for the temperature (judged against its own spread), the median standard
  uncertainty exceeds :data:`RANGE_RATIO` times the 5-95 % range of the
  panel's values: the same threshold as the roughness test of
  :func:`irdic.plot.maps.noise_dominated`, for which uncorrelated noise of
  standard deviation ``σ`` has a roughness of ``1.08 σ``.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

__all__ = ["Uncertainty", "field_uncertainty", "pixel_uncertainty", "uncertainty_sentence", "resolved_fraction",
           "RESOLVED_STDS", "RANGE_RATIO"]

#: a value is resolved from zero when it lies more than this many standard uncertainties from it
RESOLVED_STDS = 2.0
#: a temperature panel is noise-dominated when its median std exceeds this fraction of its 5-95 % range
RANGE_RATIO = 0.2


class Uncertainty(NamedTuple):
    """Standard uncertainty of a mapped quantity, per panel.

    Attributes
    ----------
    stds : list of ndarray, shape (N,)
        Standard uncertainty of the mapped (scalar) value at each point, in
        the unit of the value, one array per panel.
    bias : list of ndarray of bool, shape (N,), or None
        Where the method's bias dominates (the std does not bound the error).
    source : str
        Where the std comes from, for the caption (e.g. ``fields.temperature_rate_std``).
    against : {"zero", "range"}
        What the value is judged against (see the module docstring).
    """

    stds: list
    bias: list | None
    source: str
    against: str


def field_uncertainty(fields, name, indices, *, vector: bool = False, scale: float = 1.0) -> Uncertainty | None:
    """The ``fields.zarr`` uncertainty of ``name`` at the panels' time indices, or None without one.

    Parameters
    ----------
    fields : xarray.Dataset or None
        ``fields.zarr``.
    name : str
        Field, e.g. ``"temperature_rate"``; its ``<name>_std`` (and
        ``<name>_bias_dominated``) are read.
    indices : sequence of int
        Time indices of the panels.
    vector : bool
        The field is a vector with component-wise stds and the map shows its
        magnitude: the magnitude's std is taken as the root sum of squares of
        the components' (an upper bound for independent components).
    scale : float
        Factor from the field's unit to the unit drawn (e.g. 100 for %).

    Returns
    -------
    Uncertainty or None
    """
    if fields is None or f"{name}_std" not in fields:
        return None
    stds, bias = [], []
    for i in indices:
        s = _at(fields, f"{name}_std", i).astype(float)
        stds.append(scale * (np.sqrt(np.sum(s**2, axis=-1)) if vector else s))
        if f"{name}_bias_dominated" in fields:
            b = _at(fields, f"{name}_bias_dominated", i).astype(bool)
            bias.append(b.any(axis=-1) if vector else b)
    return Uncertainty(stds, bias if bias else None, f"fields.{name}_std",
                       "range" if name == "temperature" else "zero")


def _at(ds, name, i):
    """``ds[name]`` at time index ``i``, points first (N, ...)."""
    da = ds[name]
    if "time" in da.dims:
        da = da.isel(time=int(i))
    return np.asarray(da.transpose("point", ...).values)


def pixel_uncertainty(points, gain: str, indices, n_points: int, *, factor: float = 1.0) -> Uncertainty | None:
    """The IR noise propagated by the interpolation to a ``points.zarr`` quantity (constant over the points).

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr`` with ``ir_noise_k`` and the gain attribute.
    gain : str
        ``"temperature"`` (K), ``"gradient_per_px"`` (K/px per component) or
        ``"rate_per_s"`` (K/s): ``ir_noise_gain_<gain>``.
    indices : sequence of int
        Time indices of the panels.
    n_points : int
        Points per panel.
    factor : float
        Factor on the std (``sqrt(2)`` for the magnitude of a 2-component gradient).

    Returns
    -------
    Uncertainty or None
        None when the store records no noise estimate.
    """
    try:
        sigma = float(points.attrs["ir_noise_k"]) * float(points.attrs[f"ir_noise_gain_{gain}"]) * factor
    except (KeyError, TypeError, ValueError):
        return None
    if not np.isfinite(sigma):
        return None
    return Uncertainty([np.full(n_points, sigma) for _ in indices], None,
                       "the IR noise estimated by couple, through the interpolation",
                       "range" if gain == "temperature" else "zero")


def resolved_fraction(values, stds) -> float:
    """Fraction of the points with a positive std whose value lies more than :data:`RESOLVED_STDS` stds from zero.

    Points with a zero std (the strain at the reference stage, exact by
    definition) or without a value are not counted; NaN when none is left.
    """
    v, s = np.asarray(values, dtype=float), np.asarray(stds, dtype=float)
    ok = np.isfinite(v) & np.isfinite(s) & (s > 0)
    if not ok.any():
        return float("nan")
    return float(np.mean(np.abs(v[ok]) > RESOLVED_STDS * s[ok]))


def _noisy(values, stds, against: str) -> bool:
    if against == "zero":
        f = resolved_fraction(values, stds)
        return bool(f < 0.5)
    v = np.asarray(values, dtype=float)
    s = np.asarray(stds, dtype=float)
    v, s = v[np.isfinite(v)], s[np.isfinite(s) & (s > 0)]
    if v.size < 2 or not s.size:
        return False
    spread = float(np.percentile(v, 95) - np.percentile(v, 5))
    return bool(np.median(s) > RANGE_RATIO * spread)


def uncertainty_sentence(unc: Uncertainty | None, times, vals: Sequence, unit: str) -> tuple[list[str], str]:
    """The noise-dominated panels and the caption's sentence on the uncertainty.

    Parameters
    ----------
    unc : Uncertainty or None
        From :func:`field_uncertainty` or :func:`pixel_uncertainty`.
    times : sequence of float
        Panel times, s.
    vals : sequence of ndarray, shape (N,)
        The mapped values, one array per panel.
    unit : str
        Unit of the values.

    Returns
    -------
    noisy : list of str
        Labels (``"2.5 s"``) of the noise-dominated panels.
    sentence : str
        '' without an uncertainty.
    """
    if unc is None:
        return [], ""
    noisy = [f"{float(t):g} s" for t, v, s in zip(times, vals, unc.stds) if _noisy(v, s, unc.against)]
    allstd = np.concatenate([np.ravel(s) for s in unc.stds]) if unc.stds else np.zeros(0)
    allstd = allstd[np.isfinite(allstd) & (allstd > 0)]
    if not allstd.size:
        return noisy, ""
    text = f"Standard uncertainty ({unc.source}): median {np.median(allstd):.3g} {unit}"
    if unc.against == "zero":
        fr = [resolved_fraction(v, s) for v, s in zip(vals, unc.stds)]
        fr = [f for f in fr if np.isfinite(f)]
        if fr:
            text += (f"; {100 * min(fr):.0f}-{100 * max(fr):.0f} % of the points per panel lie more than "
                     f"{RESOLVED_STDS:g} std from zero")
    if unc.bias is not None:
        nb = sum(int(np.sum(b)) for b in unc.bias)
        n = sum(int(np.size(b)) for b in unc.bias)
        if nb:
            text += (f"; at {100 * nb / n:.0f} % of the points the method's bias (mask edge, series end, export "
                     "rounding) dominates and the std does not bound the error")
    return noisy, text + "."
