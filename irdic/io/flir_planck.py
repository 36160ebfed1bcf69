"""FLIR camera-info record and the conversion of raw counts to temperature.

The camera-info record (FFF record type 0x20) holds the Planck constants of
the camera's calibration, the object parameters the operator set (emissivity,
distance, reflected apparent temperature, atmosphere, IR window) and the
frame's time stamp. Offsets from the record start (float32 unless noted; the
record's byte order is the one in which its first u16 reads 2):

==========  ==================================================================
0x20..0x3c  emissivity, distance (m), reflected apparent, atmospheric and IR
            window temperature (K), window transmission, (0x3c) relative
            humidity (fraction; values above 2 are percent)
0x58..0x60  PlanckR1, PlanckB, PlanckF
0x70..0x80  atmospheric transmission Alpha1, Alpha2, Beta1, Beta2, X
0xd4        camera model, string[32]
0x308       PlanckO (int32); 0x30c PlanckR2
0x338       RawValueMedian, RawValueRange (u16): the raw range the camera showed
0x384       u32 Unix seconds (UTC), u32 whose low 16 bits are milliseconds,
            s16 time-zone offset (minutes west of UTC)
==========  ==================================================================

The record is 2428 or 2476 bytes long in most files, 2108 in DJI Zenmuse XT
images and 1148 in the ThermaCAM EX320's, with the same offsets; the
constants end at 0x310, the fields after them are read when the record
holds them.

Counts become °C through a 65536-entry table built once per parameter set:
the conversion is exact per count (float64) and costs one table lookup per
pixel.
"""

from __future__ import annotations

import math
import struct
from typing import Mapping

import numpy as np

from ..errors import ConfigError, FormatError

__all__ = ["camera_info", "object_parameters", "parameter_attrs", "counts_table", "counts_to_celsius",
           "celsius_to_counts", "planck_signal", "OVERRIDES", "PARAMETER_ATTRS", "CAMERA_INFO_SIZE", "KELVIN"]

KELVIN = 273.15
#: smallest camera-info record that gives temperatures (PlanckR2 ends at 0x310); the raw range (to 0x33e) and the
#: time stamp (to 0x38e) are read when the record is long enough to hold them
CAMERA_INFO_SIZE = 0x310
_RANGE_END, _TIME_END = 0x33e, 0x38e

_FLOATS = {
    "emissivity": 0x20, "distance": 0x24, "reflected_k": 0x28, "atmosphere_k": 0x2c, "window_k": 0x30,
    "window_transmission": 0x34, "humidity": 0x3c, "r1": 0x58, "b": 0x5c, "f": 0x60,
    "alpha1": 0x70, "alpha2": 0x74, "beta1": 0x78, "beta2": 0x7c, "x": 0x80, "r2": 0x30c,
}
#: config keys that replace a file's object parameter -> (parameter, conversion from the config's unit)
OVERRIDES = {"emissivity": ("emissivity", float), "reflected_temperature": ("reflected_k", lambda c: c + KELVIN)}
#: store attributes (°C for temperatures) of the object parameters and constants, in :func:`parameter_attrs` order
PARAMETER_ATTRS = ("emissivity", "distance", "reflected_temp", "env_temp", "relative_humidity",
                   "ir_window_temp", "ir_window_transmission", "planck_r1", "planck_r2", "planck_b",
                   "planck_f", "planck_o")


def _order(raw: bytes) -> str:
    """Byte order of a record from its first u16 (2 when read the right way); '' if neither."""
    if len(raw) < 2:
        return ""
    if struct.unpack_from("<H", raw)[0] == 2:
        return "<"
    if struct.unpack_from(">H", raw)[0] == 2:
        return ">"
    return ""


def camera_info(raw: bytes, where: str, path) -> dict:
    """Parse a camera-info record.

    Parameters
    ----------
    raw : bytes
        The record, at least :data:`CAMERA_INFO_SIZE` bytes; a shorter one
        than 0x38e bytes has no time stamp (``seconds`` None), one shorter
        than 0x33e no raw range (``median`` and ``range`` 0).
    where : str
        "frame k" for messages.
    path : path-like
        The file, for messages.

    Returns
    -------
    dict
        ``params`` (the float fields above in SI units, kelvin, ``o`` as
        float), ``model`` (str), ``median``/``range`` (int counts),
        ``seconds`` (Unix time of the frame, s, or None when unset) and
        ``tz_minutes`` (minutes west of UTC).

    Raises
    ------
    FormatError
        Short record or no byte-order mark.
    """
    bo = _order(raw)
    if len(raw) < CAMERA_INFO_SIZE or not bo:
        raise FormatError(f"{where}: camera-info record of {len(raw)} bytes "
                          + ("has no byte-order mark (first u16 = 2)" if len(raw) >= CAMERA_INFO_SIZE else
                             f"is shorter than the {CAMERA_INFO_SIZE} bytes that hold the Planck constants")
                          + " (damaged file or a layout irdic does not know)", path)
    params = {k: float(struct.unpack_from(bo + "f", raw, off)[0]) for k, off in _FLOATS.items()}
    params["o"] = float(struct.unpack_from(bo + "i", raw, 0x308)[0])
    if params["humidity"] > 2:  # some cameras store percent
        params["humidity"] /= 100.0
    median, rng = struct.unpack_from(bo + "HH", raw, 0x338) if len(raw) >= _RANGE_END else (0, 0)
    sec, ms, tz = struct.unpack_from(bo + "IIh", raw, 0x384) if len(raw) >= _TIME_END else (0, 0, 0)
    model = raw[0xd4:0xd4 + 32].split(b"\x00", 1)[0].decode("latin-1", errors="replace").strip()
    return {"params": params, "model": model, "median": int(median), "range": int(rng),
            "seconds": sec + (ms & 0xFFFF) / 1000.0 if sec else None, "tz_minutes": int(tz)}


def object_parameters(params: Mapping[str, float], overrides: Mapping[str, float] | None, where: str,
                      path) -> dict:
    """The file's parameters with the configuration's overrides, checked.

    Parameters
    ----------
    params : mapping
        ``params`` of :func:`camera_info`.
    overrides : mapping, optional
        ``emissivity`` (0..1] and/or ``reflected_temperature`` (°C).

    Returns
    -------
    dict
        A new dict of the parameters used for the conversion.

    Raises
    ------
    ConfigError
        An override out of range or unknown.
    FormatError
        Planck constants or object parameters of the file that cannot give a
        temperature (not finite, R1, R2 or B not positive, emissivity or
        transmission outside (0, 1], negative distance).
    """
    out = dict(params)
    for key, value in (overrides or {}).items():
        if value is None:
            continue
        if key not in OVERRIDES:
            raise ConfigError(f"ir: unknown FLIR override {key!r}; expected {', '.join(OVERRIDES)}")
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"ir.{key}: expected a number, got {value!r}")
        if key == "emissivity" and not 0 < value <= 1:
            raise ConfigError(f"ir.emissivity: {value} is not in (0, 1]")
        if key == "reflected_temperature" and not value > -KELVIN:
            raise ConfigError(f"ir.reflected_temperature: {value} °C is below absolute zero")
        name, conv = OVERRIDES[key]
        out[name] = conv(value)
    bad = [k for k, v in out.items() if not math.isfinite(v)]
    problems = [f"{k} is {out[k]}" for k in bad]
    if not bad:
        problems += [f"Planck{k.upper()} = {out[k]:.6g} is not positive" for k in ("r1", "r2", "b") if out[k] <= 0]
        problems += [f"{k} = {out[k]:.6g} is not in (0, 1]" for k in ("emissivity", "window_transmission")
                     if not 0 < out[k] <= 1]
        problems += [f"{k} = {out[k]:.6g} K is not positive" for k in ("reflected_k", "atmosphere_k", "window_k")
                     if out[k] <= 0]
        problems += [f"{k} = {out[k]:.6g} K is not below 5000 K" for k in ("reflected_k", "atmosphere_k", "window_k")
                     if out[k] >= 5000]
        if not (0 <= out["distance"] < 1e6 and 0 <= out["humidity"] <= 2):
            problems.append(f"distance {out['distance']:.6g} m or relative humidity {out['humidity']:.6g} is out of "
                            "range")
    if not problems:
        gain, offset, tau = _path_terms(out)
        if not (np.isfinite(gain) and np.isfinite(offset) and 0 < tau):
            problems.append(f"the atmospheric transmission {tau:.6g} over half the {out['distance']:.6g} m path "
                            "(from Alpha1/2, Beta1/2, X) is not a positive number")
    if problems:
        raise FormatError(f"{where}: camera info cannot give temperatures ({'; '.join(problems)}); "
                          "damaged file or a layout irdic does not know", path)
    return out


def parameter_attrs(p: Mapping[str, float]) -> dict:
    """The object parameters and Planck constants as store attributes (°C, m, fractions)."""
    def dec(v):  # a float32 field as the decimal it was meant to be
        return float(f"{v:.7g}")

    def celsius(k):
        return round(dec(k) - KELVIN, 4)

    values = (dec(p["emissivity"]), dec(p["distance"]), celsius(p["reflected_k"]), celsius(p["atmosphere_k"]),
              dec(p["humidity"]), celsius(p["window_k"]), dec(p["window_transmission"]),
              dec(p["r1"]), dec(p["r2"]), dec(p["b"]), dec(p["f"]), dec(p["o"]))
    return dict(zip(PARAMETER_ATTRS, values))


def planck_signal(t_kelvin, p: Mapping[str, float]):
    """Counts a blackbody at ``t_kelvin`` gives: ``R1 / (R2 (exp(B / T) - F)) - O``."""
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # cold or damaged: inf/NaN, checked by callers
        return p["r1"] / (p["r2"] * (np.exp(p["b"] / np.asarray(t_kelvin, dtype=np.float64)) - p["f"])) - p["o"]


def _path_terms(p: Mapping[str, float]) -> tuple[float, float, float]:
    """``(gain, offset, tau)`` with ``W_obj = gain S - offset`` for measured counts ``S``.

    Notes
    -----
    Water vapour ``H = h exp(1.5587 + 0.06939 t - 0.00027816 t^2 +
    0.00000068455 t^3)`` (t = atmospheric temperature, °C); transmission of
    half the path ``tau = X exp(-sqrt(d/2) (a1 + b1 sqrt(H))) + (1 - X)
    exp(-sqrt(d/2) (a2 + b2 sqrt(H)))`` (the window sits at mid distance).
    The signal is ``S = tau tw tau [e W_obj + (1 - e) W(Tr)] + tau tw (1 -
    tau) W(Ta) + tau (1 - tw) W(Tw) + (1 - tau) W(Ta)`` (no window
    reflection), solved for ``W_obj``: FLIR's own model, as Thermimage's
    ``raw2temp`` writes it.
    """
    t = p["atmosphere_k"] - KELVIN
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # damaged parameters: checked by the caller
        h2o = p["humidity"] * np.exp(1.5587 + 0.06939 * t - 0.00027816 * t * t + 0.00000068455 * t ** 3)
        s = math.sqrt(p["distance"] / 2.0)
        x = p["x"]
        tau = float(x * np.exp(-s * (p["alpha1"] + p["beta1"] * np.sqrt(h2o)))
                    + (1 - x) * np.exp(-s * (p["alpha2"] + p["beta2"] * np.sqrt(h2o))))
        e, tw = p["emissivity"], p["window_transmission"]
        w_refl, w_atm, w_win = (float(planck_signal(p[k], p)) for k in ("reflected_k", "atmosphere_k", "window_k"))
        gain = 1.0 / (e * tau * tw * tau) if tau else math.inf
        offset = ((1 - e) / e * w_refl + (1 - tau) / (e * tau) * w_atm + (1 - tw) / (e * tau * tw) * w_win
                  + (1 - tau) / (e * tau * tw * tau) * w_atm) if tau else math.inf
    return gain, offset, tau


def counts_to_celsius(counts, p: Mapping[str, float]) -> np.ndarray:
    """Object temperature (°C, float64) of raw counts under parameters ``p``; NaN where none exists.

    ``T = B / ln(R1 / (R2 (W_obj + O)) + F) - 273.15``; counts so low that
    ``W_obj + O <= 0`` (or the logarithm is not positive) have no temperature.
    """
    gain, offset, _tau = _path_terms(p)
    w = gain * np.asarray(counts, dtype=np.float64) - offset
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = p["b"] / np.log(p["r1"] / (p["r2"] * (w + p["o"])) + p["f"])
    ok = np.isfinite(t) & (t > 0) & (w + p["o"] > 0)
    return np.where(ok, t - KELVIN, np.nan)


def celsius_to_counts(t_celsius, p: Mapping[str, float]) -> np.ndarray:
    """Raw counts (float64, not rounded) that :func:`counts_to_celsius` maps to ``t_celsius``."""
    gain, offset, _tau = _path_terms(p)
    return (planck_signal(np.asarray(t_celsius, dtype=np.float64) + KELVIN, p) + offset) / gain


def counts_table(p: Mapping[str, float]) -> np.ndarray:
    """°C of every 16-bit count under ``p``: float32 array of shape (65536,), NaN where none exists."""
    return counts_to_celsius(np.arange(65536), p).astype(np.float32)
