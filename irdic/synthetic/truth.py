"""Every truth quantity of a synthetic experiment at material points and times.

:func:`point_truth` evaluates, for DIC points given by their material
coordinates ``(s, h)`` and for a list of times, the closed-form quantities of
the specimen and, through the true camera, their images. The result is one
:class:`xarray.Dataset` on ``(time, point)`` whose variables carry ``units``
and ``long_name``:

=========================  ======================  =========================================================
variable                   dims                    meaning
=========================  ======================  =========================================================
``s``, ``h``               point                   material surface coordinates (mm)
``x_ref``                  point, component        reference position (mm)
``edge_distance``          point                   distance to the specimen edge along the reference surface (mm)
``patch_edge_distance``    point                   distance to the border of the DIC patch (mm) (when given)
``x``                      time, point, component  current position (mm)
``velocity``               time, point, component  dx/dt at fixed material point (mm/s)
``normal``                 time, point, component  outward unit normal, current configuration
``temperature``            time, point             Theta (degC)
``temperature_gradient``   time, point, component  in-plane gradient, current configuration (K/mm)
``temperature_rate``       time, point             material rate dTheta/dt at fixed (s, h) (K/s)
``strain``                 time, point, i, j       Green-Lagrange E in the reference basis (e_s, e_h) (1)
``strain_max/min``         time, point             principal values of E (1)
``direction_max/min``      time, point, component  principal directions, REFERENCE configuration (unit)
``direction_max/min_cur``  time, point, component  the same directions pushed forward, F N / |F N|,
                                                   i.e. principal directions of the left stretch (unit)
``pixel``                  time, point, pix        projection (u, v) through the true camera (px)
``pixel_velocity``         time, point, pix        d(u, v)/dt of the material point (px/s)
``visible``                time, point             seen by the camera (in front, on the sensor, not occluded)
``in_window``              time, point             projects inside the IR crop window (when given)
``dT_du``, ``dT_dv``       time, point             pixel gradient of the ray-cast IR field (K/px)
``dT_dt_pixel``            time, point             local rate of the ray-cast field at the fixed pixel (K/s)
=========================  ======================  =========================================================

Identities that hold exactly (and are tested): ``temperature_rate =
dT_dt_pixel + (dT_du, dT_dv) . pixel_velocity``, and ``temperature_gradient
= P J^T (dT_du, dT_dv)`` with ``J`` the projection Jacobian and ``P`` the
tangent projector. Directions are NaN where both principal strains are equal
(e.g. the undeformed state) and signed towards +h.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..errors import ConfigError
from ..validation import as_finite
from .camera import TrueCamera
from .render import check_window, pixel_derivatives, visibility

__all__ = ["point_truth"]


def _unit(a):
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    return a / n


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def point_truth(specimen, camera: TrueCamera, s, h, times, *, ids=None, window=None, patch=None,
                max_rays: int = 150_000) -> xr.Dataset:
    """Closed-form truth at material points ``(s, h)`` and ``times``.

    Parameters
    ----------
    specimen : Specimen
        :class:`~irdic.synthetic.specimens.HalfShell` or
        :class:`~irdic.synthetic.specimens.Tube`.
    camera : TrueCamera
    s, h : array_like, shape (N,)
        Material coordinates of the points (mm).
    times : array_like, shape (T,)
        Times (s).
    ids : array_like of int, shape (N,), optional
        Point IDs (coordinate ``point``; default ``0..N-1``).
    window : (u0, v0, width, height), optional
        IR crop window; adds ``in_window``.
    patch : (s_min, s_max, h_min, h_max), optional
        Border of the DIC patch in material coordinates; adds
        ``patch_edge_distance``.
    max_rays : int
        Points x times per batch of ray casting (bounds memory).

    Returns
    -------
    xarray.Dataset
        See the module docstring.
    """
    s = as_finite(s, "s").ravel()
    h = as_finite(h, "h").ravel()
    if s.shape != h.shape:
        raise ConfigError(f"`s` and `h` must have the same length; got {s.size} and {h.size}")
    times = as_finite(times, "times").ravel()
    ids = np.arange(s.size) if ids is None else np.asarray(ids)
    if ids.shape != (s.size,):
        raise ConfigError(f"Expected `ids` to have shape ({s.size},); got {ids.shape}")
    data = _material_truth(specimen, s, h, times)
    data.update(_image_truth(specimen, camera, data["x"][1], data["velocity"][1], times, max_rays))
    uv = data["pixel"][1]
    if window is not None:
        u0, v0, w, hh = check_window(window, camera)
        with np.errstate(invalid="ignore"):
            inw = (uv[..., 0] >= u0) & (uv[..., 0] <= u0 + w - 1) & (uv[..., 1] >= v0) & (uv[..., 1] <= v0 + hh - 1)
        data["in_window"] = (_TP, inw, {"long_name": "projects inside the IR crop window (between its pixel centres)"})
    if patch is not None:
        s0, s1, h0, h1 = (float(q) for q in patch)
        ped = np.minimum(np.minimum(s - s0, s1 - s), np.minimum(h - h0, h1 - h))
        data["patch_edge_distance"] = (("point",), ped, {"units": "mm", "long_name": "distance to the border of the DIC patch"})
    ds = xr.Dataset(data, coords={"time": ("time", times, {"units": "s", "long_name": "time"}),
                                  "point": ("point", ids, {"long_name": "DIC point ID"}),
                                  "component": ["x", "y", "z"], "pix": ["u", "v"], "i": ["s", "h"], "j": ["s", "h"]})
    ds.attrs.update({"specimen": specimen.name, "directions": "direction_*: reference configuration; "
                     "direction_*_cur: current configuration; NaN where the principal strains are equal"})
    return ds


#: dimensions of per-point and per-point vector truth over time
_TP = ("time", "point")
_TPC = ("time", "point", "component")


def _material_truth(specimen, s: np.ndarray, h: np.ndarray, times: np.ndarray) -> dict:
    """Variables of the specimen alone (geometry, motion, temperature, strain) at points ``(s, h)``, ``times``."""
    S, Hh, Tt = s[None, :], h[None, :], times[:, None]
    x = specimen.position(S, Hh, Tt)
    vel = specimen.velocity(S, Hh, Tt)
    a_s, a_h = specimen.tangents(S, Hh, Tt)
    nrm = specimen.normal(S, Hh, Tt)
    temp = specimen.temperature(S, Hh, Tt)
    grad = specimen.temperature_gradient(S, Hh, Tt)
    rate = specimen.temperature_rate(S, Hh, Tt)
    E = specimen.green_lagrange(S, Hh, Tt)
    e_max, e_min, n_max, n_min = specimen.principal_strains(S, Hh, Tt)
    E_s, E_h = specimen.reference_basis(s, h)
    # the push-forward F N = (A^α · N) a_α: the reference tangents need not be orthonormal
    A_s, A_h = specimen.tangents(s, h, np.full(s.shape, specimen.reference_time))
    G = np.stack([np.stack([_dot(A_s, A_s), _dot(A_s, A_h)], -1), np.stack([_dot(A_s, A_h), _dot(A_h, A_h)], -1)], -2)
    Gi = np.linalg.inv(G)
    dual = (Gi[..., 0, 0, None] * A_s + Gi[..., 0, 1, None] * A_h, Gi[..., 1, 0, None] * A_s + Gi[..., 1, 1, None] * A_h)
    dirs = {}
    for key, n in (("max", n_max), ("min", n_min)):
        dirs[key] = n[..., :1] * E_s + n[..., 1:] * E_h
        dirs[key + "_cur"] = _unit(_dot(dual[0], dirs[key])[..., None] * a_s + _dot(dual[1], dirs[key])[..., None] * a_h)
    x_ref = specimen.position(s, h, specimen.reference_time)
    return {
        "s": (("point",), s, {"units": "mm", "long_name": "material arc-length coordinate"}),
        "h": (("point",), h, {"units": "mm", "long_name": "material height coordinate"}),
        "x_ref": (("point", "component"), x_ref, {"units": "mm", "long_name": "reference position"}),
        "edge_distance": (("point",), specimen.edge_distance(s, h),
                          {"units": "mm", "long_name": "distance to the specimen edge along the reference surface"}),
        "x": (_TPC, x, {"units": "mm", "long_name": "current position"}),
        "velocity": (_TPC, vel, {"units": "mm/s", "long_name": "velocity at fixed material point"}),
        "normal": (_TPC, nrm, {"units": "1", "long_name": "outward unit normal (current)"}),
        "temperature": (_TP, temp, {"units": "°C", "long_name": "temperature"}),
        "temperature_gradient": (_TPC, grad, {"units": "K/mm",
                                             "long_name": "in-plane temperature gradient (current configuration)"}),
        "temperature_rate": (_TP, rate, {"units": "K/s", "long_name": "material temperature rate"}),
        "strain": (("time", "point", "i", "j"), E,
                   {"units": "1", "long_name": "Green-Lagrange strain in the reference basis (e_s, e_h)"}),
        "strain_max": (_TP, e_max, {"units": "1", "long_name": "maximum principal Green-Lagrange strain"}),
        "strain_min": (_TP, e_min, {"units": "1", "long_name": "minimum principal Green-Lagrange strain"}),
        "direction_max": (_TPC, dirs["max"], {"units": "1", "long_name": "direction of strain_max (reference configuration)"}),
        "direction_min": (_TPC, dirs["min"], {"units": "1", "long_name": "direction of strain_min (reference configuration)"}),
        "direction_max_cur": (_TPC, dirs["max_cur"], {"units": "1", "long_name": "direction of strain_max (current configuration)"}),
        "direction_min_cur": (_TPC, dirs["min_cur"], {"units": "1", "long_name": "direction of strain_min (current configuration)"}),
    }


def _image_truth(specimen, camera: TrueCamera, x: np.ndarray, vel: np.ndarray, times: np.ndarray,
                 max_rays: int) -> dict:
    """Variables of the IR image: projections, visibility and derivatives of the ray-cast field (batched)."""
    T, N = x.shape[:2]
    Tt = times[:, None]
    uv = camera.project(x)
    J = camera.jacobian(x)
    pix_vel = np.einsum("...ij,...j->...i", J, vel)
    vis = np.zeros((T, N), bool)
    dTu = np.full((T, N), np.nan)
    dTv = np.full((T, N), np.nan)
    dTt = np.full((T, N), np.nan)
    step = max(1, max_rays // max(N, 1))
    for i in range(0, T, step):
        sl = slice(i, i + step)
        tt = Tt[sl]  # (n, 1): one evaluation of the time functions per time
        vis[sl] = visibility(specimen, camera, x[sl], tt)
        du, dv, dt = pixel_derivatives(specimen, camera, uv[sl], tt)
        dTu[sl], dTv[sl], dTt[sl] = (np.where(vis[sl], q, np.nan) for q in (du, dv, dt))
    return {
        "pixel": (("time", "point", "pix"), uv, {"units": "px", "long_name": "projected pixel position (u, v)"}),
        "pixel_velocity": (("time", "point", "pix"), pix_vel, {"units": "px/s", "long_name": "pixel velocity of the material point"}),
        "visible": (_TP, vis, {"long_name": "seen by the IR camera"}),
        "dT_du": (_TP, dTu, {"units": "K/px", "long_name": "du derivative of the ray-cast IR field"}),
        "dT_dv": (_TP, dTv, {"units": "K/px", "long_name": "dv derivative of the ray-cast IR field"}),
        "dT_dt_pixel": (_TP, dTt, {"units": "K/s", "long_name": "local time derivative of the IR field at the fixed pixel"}),
    }
