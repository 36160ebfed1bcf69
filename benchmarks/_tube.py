"""The moving tube of the couple benchmarks at any size: 10 Hz IR and DIC, tension-torsion all along.

:func:`tube` is the lab camera's tube (loading over 0.5-5.5 s, then still);
:func:`sweep_tube` the paper-scale tube seen from closer (~58,000 specimen
pixels) whose outline moves at a set speed every frame, for the sweep of
``bench_couple_moving.py --sweep``.
"""

from __future__ import annotations

import numpy as np

from irdic.synthetic import experiments as _ex
from irdic.synthetic.camera import lab_camera
from irdic.synthetic.specimens import Tube

#: Distance (mm) of the sweep's camera from the lab target: the tube's DIC patch covers ~58,000 px.
SWEEP_DISTANCE = 220.0
#: Full load of the sweep's cycles: axial stretch and twist of the moving grip (rad); the twist reaches
#: 0.4 rad at the DIC patch's upper end (5/6 of the free length).
SWEEP_STRETCH = 0.06
SWEEP_TWIST = 0.48


def tube(frames: int = 300, grid: tuple[int, int] = (78, 168), *, ir_noise: float = 0.05, dic_noise: float = 0.005,
         camera=None, specimen=None):
    """``frames`` IR frames and DIC stages at 10 Hz; ``grid`` DIC points (78 x 168 = 13,104)."""
    plan = _ex._PLAN["tube"]
    plan["bench"] = ((frames - 1) / 10.0, 10.0, 10.0, tuple(grid), None)
    scales = _ex.SCALES
    _ex.SCALES = scales + ("bench",)
    try:
        return _ex.tube_experiment("bench", ir_noise=ir_noise, dic_noise=dic_noise, camera=camera,
                                   specimen=specimen)
    finally:
        _ex.SCALES = scales
        del plan["bench"]


class CycledTube(Tube):
    """The tube under cycles of proportional tension-torsion at a constant load rate.

    The load ``s(t)`` runs up and down between 0 and 1 at ``rate`` (1/s), a
    triangle wave starting at 0; stretch ``1 + SWEEP_STRETCH s`` and twist
    ``SWEEP_TWIST s``. The heating is the tube's (it follows its own load
    steps; only the kinematics change).
    """

    def __init__(self, rate: float, **kw):
        super().__init__(u_max=SWEEP_STRETCH * kw.pop("L", 60.0), phi_max_deg=np.degrees(SWEEP_TWIST), **kw)
        self.rate = float(rate)

    def _load(self, t):
        x = self.rate * np.asarray(t, np.float64)
        k = np.floor(x)
        up = (k % 2) == 0
        return np.where(up, x - k, 1.0 - (x - k)), np.where(up, self.rate, -self.rate)

    def axial_displacement(self, t):
        s, ds = self._load(t)
        return self.u_max * s, self.u_max * ds

    def twist(self, t):
        s, ds = self._load(t)
        return self.phi_max * s, self.phi_max * ds


def outline_speed(specimen, camera, s, h, times) -> float:
    """Largest displacement (px) of the DIC patch's outline from one time to the next."""
    uv = camera.project(specimen.position(s[None], h[None], np.asarray(times)[:, None]))
    return float(np.nanmax(np.linalg.norm(np.diff(uv, axis=0), axis=-1)))


def sweep_tube(speed: float, frames: int = 300, grid: tuple[int, int] = (78, 168), *, ir_noise: float = 0.05,
               dic_noise: float = 0.005):
    """The tube seen from :data:`SWEEP_DISTANCE` mm whose outline moves ``speed`` px per frame (0: still).

    The load rate of :class:`CycledTube` is set so that the fastest point of
    the DIC patch's outline moves ``speed`` px from one 10 Hz frame to the next
    (measured on the rendered times; the speed varies by a few % along the cycle).
    """
    camera = lab_camera(distance=SWEEP_DISTANCE)
    base = _ex._grid("tube", Tube(), grid)
    s, h = base[0], base[1]
    ny, nx = grid[1], grid[0]
    S, Hh = s.reshape(ny, nx), h.reshape(ny, nx)
    edge = np.zeros((ny, nx), bool)
    edge[[0, -1]] = True
    edge[:, [0, -1]] = True
    s_o, h_o = S[edge], Hh[edge]
    times = np.arange(frames) / 10.0
    rate = 0.0
    if speed > 0:
        # the outline's speed is close to proportional to the load rate: two corrections
        rate = 0.01
        for _ in range(3):
            got = outline_speed(CycledTube(rate), camera, s_o, h_o, times)
            rate *= speed / got
    spec = CycledTube(rate)
    ex = tube(frames, grid, ir_noise=ir_noise, dic_noise=dic_noise, camera=camera, specimen=spec)
    ex.outline_speed = outline_speed(spec, camera, s_o, h_o, times) if speed > 0 else 0.0
    return ex


def inputs(ex):
    """(dic, ir, calibration) datasets of an experiment, in memory."""
    import xarray as xr

    from irdic.camera import CameraModel

    dic = ex.dic()
    ir = xr.Dataset({"temperature": ex.ir_stack(noise=ex.ir_noise > 0)})
    cam = ex.camera
    cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
    cal.attrs.update(sensor_width=1024, sensor_height=768)
    return dic, ir, cal


def accuracy(points, ex):
    """RMS (K) of the point temperatures against the analytic truth, over visible points."""
    tr = ex.truth().sel(point=points.point)
    vis = points.visible.values
    err = points.temperature.values - tr.temperature.values
    return float(np.sqrt(np.mean(err[vis] ** 2))), int(vis.sum())
