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
    N, T = s.size, times.size
    ids = np.arange(N) if ids is None else np.asarray(ids)
    if ids.shape != (N,):
        raise ConfigError(f"Expected `ids` to have shape ({N},); got {ids.shape}")

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
    dirs = {}
    for key, n in (("max", n_max), ("min", n_min)):
        dirs[key] = n[..., :1] * E_s + n[..., 1:] * E_h
        dirs[key + "_cur"] = _unit(n[..., :1] * a_s + n[..., 1:] * a_h)
    x_ref = specimen.position(s, h, specimen.reference_time)

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

    comp = ["x", "y", "z"]
    tpa = ("time", "point")
    tpc = ("time", "point", "component")
    data = {
        "s": (("point",), s, {"units": "mm", "long_name": "material arc-length coordinate"}),
        "h": (("point",), h, {"units": "mm", "long_name": "material height coordinate"}),
        "x_ref": (("point", "component"), x_ref, {"units": "mm", "long_name": "reference position"}),
        "edge_distance": (("point",), specimen.edge_distance(s, h),
                          {"units": "mm", "long_name": "distance to the specimen edge along the reference surface"}),
        "x": (tpc, x, {"units": "mm", "long_name": "current position"}),
        "velocity": (tpc, vel, {"units": "mm/s", "long_name": "velocity at fixed material point"}),
        "normal": (tpc, nrm, {"units": "1", "long_name": "outward unit normal (current)"}),
        "temperature": (tpa, temp, {"units": "°C", "long_name": "temperature"}),
        "temperature_gradient": (tpc, grad, {"units": "K/mm",
                                             "long_name": "in-plane temperature gradient (current configuration)"}),
        "temperature_rate": (tpa, rate, {"units": "K/s", "long_name": "material temperature rate"}),
        "strain": (("time", "point", "i", "j"), E,
                   {"units": "1", "long_name": "Green-Lagrange strain in the reference basis (e_s, e_h)"}),
        "strain_max": (tpa, e_max, {"units": "1", "long_name": "maximum principal Green-Lagrange strain"}),
        "strain_min": (tpa, e_min, {"units": "1", "long_name": "minimum principal Green-Lagrange strain"}),
        "direction_max": (tpc, dirs["max"], {"units": "1", "long_name": "direction of strain_max (reference configuration)"}),
        "direction_min": (tpc, dirs["min"], {"units": "1", "long_name": "direction of strain_min (reference configuration)"}),
        "direction_max_cur": (tpc, dirs["max_cur"], {"units": "1", "long_name": "direction of strain_max (current configuration)"}),
        "direction_min_cur": (tpc, dirs["min_cur"], {"units": "1", "long_name": "direction of strain_min (current configuration)"}),
        "pixel": (("time", "point", "pix"), uv, {"units": "px", "long_name": "projected pixel position (u, v)"}),
        "pixel_velocity": (("time", "point", "pix"), pix_vel, {"units": "px/s", "long_name": "pixel velocity of the material point"}),
        "visible": (tpa, vis, {"long_name": "seen by the IR camera"}),
        "dT_du": (tpa, dTu, {"units": "K/px", "long_name": "du derivative of the ray-cast IR field"}),
        "dT_dv": (tpa, dTv, {"units": "K/px", "long_name": "dv derivative of the ray-cast IR field"}),
        "dT_dt_pixel": (tpa, dTt, {"units": "K/s", "long_name": "local time derivative of the IR field at the fixed pixel"}),
    }
    if window is not None:
        u0, v0, w, hh = check_window(window, camera)
        with np.errstate(invalid="ignore"):
            inw = (uv[..., 0] >= u0) & (uv[..., 0] <= u0 + w - 1) & (uv[..., 1] >= v0) & (uv[..., 1] <= v0 + hh - 1)
        data["in_window"] = (tpa, inw, {"long_name": "projects inside the IR crop window (between its pixel centres)"})
    if patch is not None:
        s0, s1, h0, h1 = (float(q) for q in patch)
        ped = np.minimum(np.minimum(s - s0, s1 - s), np.minimum(h - h0, h1 - h))
        data["patch_edge_distance"] = (("point",), ped, {"units": "mm", "long_name": "distance to the border of the DIC patch"})
    ds = xr.Dataset(data, coords={"time": ("time", times, {"units": "s", "long_name": "time"}),
                                  "point": ("point", ids, {"long_name": "DIC point ID"}),
                                  "component": comp, "pix": ["u", "v"], "i": ["s", "h"], "j": ["s", "h"]})
    ds.attrs.update({"specimen": specimen.name, "directions": "direction_*: reference configuration; "
                     "direction_*_cur: current configuration; NaN where the principal strains are equal"})
    return ds
