"""A family of synthetic scenes drawn from a seed: what the fields stage is judged on.

Every member is an experiment like the demo's (:class:`Scene`, an
:class:`~irdic.synthetic.experiments.Experiment` with its truth), built from
a *recipe*: a plain dict of the scene's kinds and parameters
(:func:`recipe`), free of the scale, so that one recipe gives a small member
for the tests and a larger one for the benchmark.

- :func:`draw` ``(seed, scale)``: a member drawn at random from the seed;
- :func:`member` ``(name, scale)``: one of the fixed, named members
  (:data:`FIXED`), chosen to cover the kinds and the hard cases;
- :meth:`Scene.inputs`: the DIC, IR and calibration datasets the couple
  stage takes (IR as a camera exports it: pixel noise, rounding, mixed edge
  pixels); :meth:`Scene.truth`: every truth quantity.

What a recipe draws (:func:`recipe`):

- geometry: a plane, a cylinder of radius 10-60 mm, a barrel (equator
  radius 20-60 mm, meridian radius 1-2.5 times it) or a sphere cap (radius
  30-100 mm) (:mod:`irdic.synthetic.shapes`);
- motion: static, stretch (1-4 %) or stretch and twist (0.1-0.5 rad over the
  free length, the patch turning by at most 0.25 rad, a shear of at most 0.12);
- temperature: smooth heating with the load (1-6 K), heating from the lower
  edge (10-40 K, decay length 3-8 mm growing 1.5-2.5 times), a narrow band
  (1-6 K, width 1.5-4 mm, the Gaussian's standard deviation) travelling at
  0.5-2 mm/s, a hot spot (2-10 K, width 2-6 mm) (:mod:`irdic.synthetic.patterns`);
- noise: IR 0.02-0.1 K with 2 or 3 exported decimals and mixed edge
  pixels, DIC 0.001-0.005 mm per component, 0-2 % of the points failed in
  every later stage;
- point spacing 0.3-1 mm (a grid regular in the reference's world x and y),
  the patch 1-3 mm inside the specimen's edge;
- the IR camera (the lab camera's optics) 300-600 mm from the patch,
  azimuth within +-25 deg (+-20 on cylinders and barrels), elevation within
  +-15 deg, roll within +-5 deg;
- timing: DIC at 1, 2 or 4 Hz (a band never moves more than 0.75 of its
  width between stages), IR at twice that, one IR frame dropped in half of
  the scenes.

Scales: ``tiny`` about 350 points and 7 stages, ``demo`` about 2,000
points and the recipe's 17-31 stages, ``paper`` about 10,000 points. The
patch's size follows from the points and the spacing (within the surface's
limits: a cylinder's patch spans at most +-45 deg); a band's speed is
reduced where the record would carry it out of the patch.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..errors import ConfigError
from ..validation import choice
from .camera import TrueCamera
from .experiments import Experiment, window_around
from .patterns import EdgeHeating, HotSpot, MovingBand, SmoothHeating
from .render import check_window, realistic_stack
from .scene import SceneSpecimen
from .shapes import GEOMETRIES, Motion

__all__ = ["Scene", "draw", "member", "build", "recipe", "FIXED", "FAMILY_SCALES", "KINDS"]

#: scale -> (points, DIC stages or None for the recipe's own)
FAMILY_SCALES = {"tiny": (350, 7), "demo": (2000, None), "paper": (10000, None)}

#: the kinds a recipe draws from
KINDS = {"geometry": ("plane", "cylinder", "barrel", "sphere"), "motion": ("static", "stretch", "twist"),
         "pattern": ("smooth", "edge", "band", "spot")}

#: largest angle (rad) by which the twist turns the patch's top about the axis
MAX_PATCH_TURN = 0.25
#: largest shear of the twist (the tube's: 0.11)
MAX_SHEAR = 0.12
#: a band's largest travel between DIC stages, in band widths
BAND_STEP = 0.75
#: the fraction of the patch (along the band's direction) a band crosses in the record at most
BAND_TRAVEL = 0.6


@dataclass
class Scene(Experiment):
    """A member of the family: an :class:`~irdic.synthetic.experiments.Experiment` with its recipe.

    Attributes (beyond the experiment's)
    ------------------------------------
    decimals : int
        Decimals of the IR export (:meth:`ir`).
    missing : float
        Fraction of the points failed in every later DIC stage.
    recipe : dict
        The recipe it was built from (:func:`recipe`), with what the build
        resolved (``resolved``: patch, duration, band speed).
    """

    decimals: int = 2
    missing: float = 0.0
    recipe: dict = field(default_factory=dict)

    @property
    def code(self) -> int:
        """A number of the scene's name (the noise streams' key)."""
        return zlib.crc32(self.name.encode()) % (2 ** 31)

    @property
    def kinds(self) -> tuple[str, str, str]:
        """(geometry, motion, pattern)."""
        r = self.recipe
        return r["geometry"]["kind"], r["motion"]["kind"], r["pattern"]["kind"]

    def ir_frame(self, i: int, *, noise: bool = True) -> xr.DataArray:
        """IR frame ``i`` with plain Gaussian noise (as :meth:`Experiment.ir_frame`); :meth:`ir` is the export."""
        if not 0 <= i < self.ir_times.size:
            raise ConfigError(f"frame index {i} out of range 0..{self.ir_times.size - 1}")
        rng = np.random.default_rng([self.seed, self.code, int(self.ir_frame_numbers[i])])
        frame = self.renderer(self.ir_times[i], noise=self.ir_noise if noise else 0.0, rng=rng)
        frame.attrs["frame_number"] = int(self.ir_frame_numbers[i])
        return frame

    def ir(self, offset: float = 0.0, *, realistic: bool = True) -> xr.Dataset:
        """The IR record as the camera exports it: ``temperature (time, v, u)`` float32 degC.

        ``realistic``: pixel noise, mixed edge pixels and the scene's
        decimals (:func:`~irdic.synthetic.render.realistic_stack`); else
        noise-free and unrounded. ``offset`` (s): the IR clock runs that
        much behind the DIC clock (the times written are ``t - offset``).
        """
        rng = np.random.default_rng([self.seed, self.code, 15])
        frames = realistic_stack(self.renderer, self.ir_times, rng, noise=self.ir_noise if realistic else 0.0,
                                 decimals=self.decimals if realistic else None, mixed_edges=realistic)
        r = self.renderer
        return xr.Dataset({"temperature": (("time", "v", "u"), frames, {"units": "°C"})},
                          coords={"time": self.ir_times - float(offset), "v": r.v.astype(np.int64),
                                  "u": r.u.astype(np.int64)})

    def calibration(self) -> xr.Dataset:
        """The true camera as the calibrate stage stores it."""
        from ..camera import CameraModel

        cam = self.camera
        cal = CameraModel(K=cam.K, R=cam.R, C=cam.C).to_dataset()
        cal.attrs.update(sensor_width=cam.width, sensor_height=cam.height)
        return cal

    def inputs(self, offset: float = 0.0, *, realistic: bool = True):
        """``(dic, ir, calibration)``: the couple stage's inputs (:meth:`ir`, the DIC data, the true camera)."""
        return self.dic()[["x"]], self.ir(offset, realistic=realistic), self.calibration()

    def describe(self) -> str:
        """One line: kinds, sizes, noise."""
        r, res = self.recipe, self.recipe.get("resolved", {})
        g = r["geometry"]
        size = {"cylinder": f" R {g.get('R', 0):.0f}", "barrel": f" R {g.get('R', 0):.0f}/{g.get('Rm', 0):.0f}",
                "sphere": f" R {g.get('Rs', 0):.0f}"}.get(g["kind"], "")
        p = r["pattern"]
        pat = p["kind"] + (f" w {p['width']:.1f} mm" if "width" in p else "")
        if p["kind"] == "band":
            pat += f" at {res.get('speed', p['speed']):.2f} mm/s"
        m = r["motion"]
        mot = {"static": "static", "stretch": f"stretch {100 * m['strain']:.1f} %",
               "twist": f"stretch {100 * m['strain']:.1f} % + twist {m['twist']:.2f} rad"}[m["kind"]]
        return (f"{g['kind']}{size}, {mot}, {pat}; {self.s.size} points {r['spacing']:.2f} mm apart, "
                f"{self.dic_times.size} stages at {res.get('dic_rate', r['timing']['dic_rate']):g} Hz; IR {self.ir_noise:.3f} K "
                f"{self.decimals} dec, DIC {self.dic_noise:.4f} mm, {100 * self.missing:.1f} % missing")


# ------------------------------------------------------------------------------------- recipes
def recipe(seed: int, **overrides) -> dict:
    """A recipe drawn from ``seed`` (module docstring); ``overrides`` replace top-level entries."""
    rng = np.random.default_rng([int(seed), 34])
    u = rng.uniform
    gk = KINDS["geometry"][rng.integers(4)]
    geometry = {"plane": {"kind": "plane"}, "cylinder": {"kind": "cylinder", "R": u(10, 60)},
                "sphere": {"kind": "sphere", "Rs": u(30, 100)}}.get(gk)
    if gk == "barrel":
        R = u(20, 60)
        geometry = {"kind": "barrel", "R": R, "Rm": R * u(1.0, 2.5)}
    mk = KINDS["motion"][rng.integers(3)]
    motion = {"kind": mk, "strain": 0.0 if mk == "static" else u(0.01, 0.04),
              "twist": u(0.1, 0.5) if mk == "twist" else 0.0, "load": (u(0.0, 0.2), u(0.6, 0.95)),
              "gap": u(5.0, 20.0)}
    pk = KINDS["pattern"][rng.integers(4)]
    pattern = {
        "smooth": lambda: {"kind": "smooth", "amplitude": u(1, 6), "beta": u(0.2, 0.6), "beta_s": u(0, 0.3),
                           "gamma": u(-0.1, 0.1), "load": (u(0.0, 0.2), u(0.6, 0.95))},
        "edge": lambda: {"kind": "edge", "amplitude": u(10, 40), "decay": u(3, 8), "growth": u(1.5, 2.5),
                         "tau": u(0.5, 2.0), "t_pre": u(0.1, 0.3), "beta": u(0, 0.2)},
        "band": lambda: {"kind": "band", "amplitude": u(1, 6), "width": u(1.5, 4.0), "speed": u(0.5, 2.0),
                         "angle": u(-0.5, 0.5)},
        "spot": lambda: {"kind": "spot", "amplitude": u(2, 10), "width": u(2, 6), "centre": (u(-0.4, 0.4),
                                                                                            u(-0.4, 0.4)),
                         "load": (u(0.0, 0.2), u(0.6, 0.95))},
    }[pk]()
    curved = gk in ("cylinder", "barrel")
    camera = {"distance": u(300, 600), "azimuth": u(-20, 20) if curved else u(-25, 25), "elevation": u(-15, 15),
              "roll": u(-5, 5)}
    timing = {"dic_rate": float(rng.choice([1.0, 2.0, 4.0])), "stages": int(rng.choice([17, 21, 25, 31])),
              "dropped": bool(rng.random() < 0.5)}
    noise = {"ir": u(0.02, 0.1), "decimals": int(rng.choice([2, 3])), "dic": u(0.001, 0.005),
             "missing": u(0.0, 0.02)}
    out = {"name": f"drawn-{int(seed)}", "geometry": geometry, "motion": motion, "pattern": pattern,
           "spacing": u(0.3, 1.0), "aspect": u(0.7, 1.4), "margin": u(1.0, 3.0), "T0": u(20, 30),
           "camera": camera, "timing": timing, "noise": noise}
    out.update(overrides)
    return out


def _fixed():
    """The named members: the kinds covered, the hard cases included."""
    def make(name, geometry, motion, pattern, spacing, noise, timing, camera=None, **kw):
        m = {"kind": "static", "strain": 0.0, "twist": 0.0, "load": (0.05, 0.85), "gap": 10.0}
        m.update(motion)
        cam = {"distance": 450.0, "azimuth": 17.5, "elevation": 10.0, "roll": 1.0}
        cam.update(camera or {})
        t = {"dic_rate": 2.0, "stages": 21, "dropped": True}
        t.update(timing)
        nz = {"ir": 0.05, "decimals": 2, "dic": 0.003, "missing": 0.01}
        nz.update(noise)
        return {"name": name, "geometry": geometry, "motion": m, "pattern": pattern, "spacing": spacing,
                "aspect": kw.get("aspect", 1.0), "margin": kw.get("margin", 1.0), "T0": kw.get("T0", 22.0),
                "camera": cam, "timing": t, "noise": nz}

    smooth = {"kind": "smooth", "amplitude": 4.0, "beta": 0.5, "beta_s": 0.1, "gamma": 0.04, "load": (0.05, 0.55)}
    members = [
        # the static barrel of the issue: R 40 mm heated from its lower edge
        make("shell-edge", {"kind": "cylinder", "R": 40.0}, {},
             {"kind": "edge", "amplitude": 40.0, "decay": 6.0, "growth": 2.0, "tau": 0.7, "t_pre": 0.17,
              "beta": 0.12}, 1.0, {}, {"dic_rate": 1.0, "stages": 31, "dropped": False}),
        # the tube under tension and torsion, heating with the load
        make("tube-twist", {"kind": "cylinder", "R": 15.0}, {"kind": "twist", "strain": 0.033, "twist": 0.44},
             smooth, 0.8, {}, {"dic_rate": 2.0, "stages": 21}, camera={"azimuth": 10.0}),
        # a flat strip with a 2.4 mm hot band moving at 1 mm/s (Lüders-like)
        make("strip-band", {"kind": "plane"}, {},
             {"kind": "band", "amplitude": 4.0, "width": 2.4, "speed": 1.0, "angle": 0.0}, 0.6, {},
             {"dic_rate": 2.0, "stages": 25}),
        # a 2 mm band on a stretched plate at the noise the issue asks it to be resolved at
        make("plate-band-2mm", {"kind": "plane"}, {"kind": "stretch", "strain": 0.02},
             {"kind": "band", "amplitude": 3.0, "width": 2.0, "speed": 0.8, "angle": 0.3}, 0.4, {},
             {"dic_rate": 2.0, "stages": 25}, camera={"azimuth": -15.0, "elevation": -5.0}),
        # a sphere cap, stretched, with a hot spot
        make("cap-spot", {"kind": "sphere", "Rs": 60.0}, {"kind": "stretch", "strain": 0.025},
             {"kind": "spot", "amplitude": 6.0, "width": 3.0, "centre": (0.1, -0.1), "load": (0.1, 0.8)}, 0.7,
             {"ir": 0.07, "dic": 0.004}, {"dic_rate": 1.0, "stages": 21}, camera={"distance": 380.0}),
        # a fine grid on a twisted plate at high IR noise, 3 decimals
        make("plate-fine-twist", {"kind": "plane"}, {"kind": "twist", "strain": 0.02, "twist": 0.3},
             smooth, 0.3, {"ir": 0.1, "decimals": 3, "dic": 0.002, "missing": 0.02},
             {"dic_rate": 4.0, "stages": 21}, camera={"distance": 320.0, "azimuth": -20.0}),
        # a thin tube with the narrowest band, stretched
        make("thin-tube-band", {"kind": "cylinder", "R": 10.0}, {"kind": "stretch", "strain": 0.03},
             {"kind": "band", "amplitude": 5.0, "width": 1.5, "speed": 0.5, "angle": 0.0}, 0.4,
             {"ir": 0.04, "dic": 0.002}, {"dic_rate": 2.0, "stages": 21}, aspect=0.7),
        # a barrel, stretched and twisted by 0.5 rad, heated from its edge, at the largest DIC noise
        make("barrel-twist-edge", {"kind": "barrel", "R": 30.0, "Rm": 45.0},
             {"kind": "twist", "strain": 0.02, "twist": 0.5},
             {"kind": "edge", "amplitude": 15.0, "decay": 4.0, "growth": 2.0, "tau": 1.0, "t_pre": 0.2,
              "beta": 0.05}, 0.7, {"dic": 0.005, "ir": 0.05}, {"dic_rate": 2.0, "stages": 25},
             camera={"azimuth": -12.0, "elevation": 12.0}, margin=2.0),
        # a wide shell, coarse grid, a small hot spot at the least noise
        make("wide-shell-spot", {"kind": "cylinder", "R": 60.0}, {},
             {"kind": "spot", "amplitude": 5.0, "width": 2.5, "centre": (-0.15, 0.1), "load": (0.1, 0.9)}, 1.0,
             {"ir": 0.02, "decimals": 3, "dic": 0.001, "missing": 0.0}, {"dic_rate": 1.0, "stages": 17},
             camera={"distance": 550.0, "azimuth": 20.0, "elevation": -8.0}),
    ]
    return {m["name"]: m for m in members}


#: the fixed, named members (name -> recipe)
FIXED = _fixed()


# ------------------------------------------------------------------------------------- building
def _patch(geometry, spacing, aspect, n_points):
    """Half extents (X, Y) mm in world x and y of a grid of about ``n_points`` at ``spacing``."""
    area = n_points * spacing ** 2
    X = 0.5 * math.sqrt(area * aspect)
    Y = 0.5 * math.sqrt(area / aspect)
    xm = geometry.max_half_width()
    if X > xm:
        X, Y = xm, min(area / (4 * xm), 3 * xm)
    ym = geometry.max_half_height()
    Y = min(Y, ym)
    return X, Y


def _grid(geometry, X, Y, spacing):
    """Material coordinates and IDs of the grid regular in world x and y, and the patch rectangle inside it."""
    nx, ny = int(round(2 * X / spacing)) + 1, int(round(2 * Y / spacing)) + 1
    x, y = np.linspace(-X, X, nx), np.linspace(-Y, Y, ny)
    XX, YY = np.meshgrid(x, y)  # rows = y
    s, h = geometry.material(XX.ravel(), YY.ravel())
    row, col = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    ids = (1000 * row.ravel() + col.ravel() + 1).astype(np.int64)
    # the patch: the rectangle inside the grid (a barrel's rows reach further in s away from its equator)
    s_edge = float(geometry.material(np.array([X]), np.array([0.0]))[0][0])
    return np.asarray(s, float), np.asarray(h, float), ids, (-s_edge, s_edge, -Y, Y)


def _pattern(p, patch, duration, dic_rate):
    """The pattern object of recipe entry ``p`` on ``patch`` over ``duration`` s; also the resolved band speed."""
    s0, s1, h0, h1 = patch
    D = duration
    kind = p["kind"]
    if kind == "smooth":
        return SmoothHeating(amplitude=p["amplitude"], load=(p["load"][0] * D, p["load"][1] * D),
                             size=(max(s1, 1.0), max(h1, 1.0)), beta=p["beta"], beta_s=p["beta_s"],
                             gamma=p["gamma"]), None
    if kind == "edge":
        return None, None  # needs the domain: built by the caller
    if kind == "band":
        ns, nh = math.sin(p["angle"]), math.cos(p["angle"])
        extent = abs(ns) * (s1 - s0) + abs(nh) * (h1 - h0)
        speed = min(p["speed"], BAND_TRAVEL * extent / max(D, 1e-9))
        # the band crosses the patch's middle half way through the record
        return MovingBand(amplitude=p["amplitude"], width=p["width"], speed=speed, start=-0.5 * speed * D,
                          angle=p["angle"]), speed
    if kind == "spot":
        c = (p["centre"][0] * (s1 - s0) / 2, p["centre"][1] * (h1 - h0) / 2)
        return HotSpot(amplitude=p["amplitude"], width=p["width"], centre=c,
                       load=(p["load"][0] * D, p["load"][1] * D)), None
    raise ConfigError(f"unknown pattern kind {kind!r}; expected one of {KINDS['pattern']}")


def _dic_rate(r):
    """The recipe's DIC rate, raised so that a band moves at most :data:`BAND_STEP` of its width per stage."""
    rate = float(r["timing"]["dic_rate"])
    p = r["pattern"]
    if p["kind"] == "band":
        need = p["speed"] / (BAND_STEP * p["width"])
        for cand in (1.0, 2.0, 4.0, 5.0, 8.0, 10.0, 16.0, 20.0):
            if cand >= max(rate, need):
                return cand
    return rate


def _window(spec, camera, times, margin=20):
    """Crop window around the specimen's projected rectangle over the record (px)."""
    s0, s1, h0, h1 = spec.domain
    S, H = np.meshgrid(np.linspace(s0, s1, 41), np.linspace(h0, h1, 41))
    t = np.linspace(times[0], times[-1], 11)[:, None]
    return check_window(window_around(camera.project(spec.position(S.ravel()[None], H.ravel()[None], t)), camera,
                                      margin), camera)


def _defects(rng, M, N, fraction):
    """NaN (failed: ``fraction`` of the points in every later stage) and absent (a few points in one or two
    stages) masks, (M, N) each; stage 0 is clean, and a scene without failures has none."""
    failed = np.zeros((M, N), bool)
    absent = np.zeros((M, N), bool)
    n_fail = int(round(fraction * N))
    if M < 2 or n_fail == 0:
        return failed, absent
    for k in range(1, M):
        failed[k, rng.choice(N, n_fail, replace=False)] = True
    for p in rng.choice(N, max(2, N // 600), replace=False):
        stages = rng.choice(np.arange(1, M), min(M - 1, int(rng.integers(1, 3))), replace=False)
        absent[stages, p] = True
    return failed, absent


def build(r: dict, scale: str = "demo", *, noise_seed: int = 0) -> Scene:
    """The :class:`Scene` of recipe ``r`` at ``scale`` with the noise realisation ``noise_seed``."""
    choice(scale, "scale", tuple(FAMILY_SCALES))
    n_points, stages = FAMILY_SCALES[scale]
    stages = int(r["timing"]["stages"]) if stages is None else stages
    g = dict(r["geometry"])
    geometry = GEOMETRIES[g.pop("kind")](**g)
    spacing = float(r["spacing"])
    X, Y = _patch(geometry, spacing, float(r["aspect"]), n_points)
    s, h, ids, patch = _grid(geometry, X, Y, spacing)
    margin = float(r["margin"])
    domain = (float(s.min()) - margin, float(s.max()) + margin, float(h.min()) - margin, float(h.max()) + margin)
    dic_rate = _dic_rate(r)
    ir_rate = 2.0 * dic_rate
    duration = (stages - 1) / dic_rate
    m = r["motion"]
    length = 60.0
    gap = float(m.get("gap", 10.0))
    if m["kind"] == "twist":
        # the free length keeps the patch's top within MAX_PATCH_TURN of its start and the twist's shear
        # (distance from the axis times the twist per length) within MAX_SHEAR
        reach = float(np.max(np.hypot(*(geometry.point(s, h)[:, [0, 2]] - geometry.axis).T)))
        length = max(60.0, m["twist"] * (gap + domain[3] - domain[2]) / MAX_PATCH_TURN,
                     m["twist"] * reach / MAX_SHEAR)
    motion = Motion(strain=m["strain"] if m["kind"] != "static" else 0.0,
                    twist=m["twist"] if m["kind"] == "twist" else 0.0,
                    load=(m["load"][0] * duration, m["load"][1] * duration), axis=geometry.axis,
                    y_fixed=domain[2] - gap, length=length)
    p = r["pattern"]
    pattern, speed = _pattern(p, patch, duration, dic_rate)
    if p["kind"] == "edge":
        d0 = float(p["decay"])
        pattern = EdgeHeating(amplitude=p["amplitude"], edge=domain[2], half_width=max(domain[1], 1.0),
                              beta=p["beta"], tau=p["tau"] * duration, t_pre=p["t_pre"] * duration, decay_0=d0,
                              decay_inf=d0 * p["growth"], tau_decay=1.5 * p["tau"] * duration)
    spec = SceneSpecimen(geometry, motion, pattern, domain, T0=float(r["T0"]), name=r["name"])
    c = r["camera"]
    target = motion.apply(np.zeros(3), 0.5 * duration)[0]
    a, e = math.radians(c["azimuth"]), math.radians(c["elevation"])
    centre = target + c["distance"] * np.array([math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e)])
    camera = TrueCamera.looking_at(centre, target, roll_deg=c["roll"])
    n_ir = int(round(duration * ir_rate)) + 1
    numbers = np.arange(n_ir)
    if r["timing"].get("dropped") and n_ir > 4:
        numbers = numbers[numbers != n_ir // 2 - 1]
    ir_times = numbers / ir_rate
    dic_times = np.arange(stages) / dic_rate
    window = _window(spec, camera, ir_times)
    nz = r["noise"]
    rng = np.random.default_rng([int(noise_seed), zlib.crc32(r["name"].encode()) % (2 ** 31), 1_000_000])
    x_true = spec.position(s[None], h[None], dic_times[:, None])
    x_dic = x_true + rng.normal(0.0, nz["dic"], x_true.shape)
    failed, absent = _defects(rng, dic_times.size, s.size, float(nz["missing"]))
    x_dic[failed | absent] = np.nan
    resolved = {"patch": list(patch), "domain": list(domain), "duration": duration, "dic_rate": dic_rate,
                "length": length, "speed": speed, "window": list(window)}
    return Scene(name=r["name"], scale=scale, specimen=spec, camera=camera, window=window, ir_times=ir_times,
                 ir_frame_numbers=numbers, dic_times=dic_times, ids=ids, s=s, h=h, patch=patch, x_dic=x_dic,
                 present=~absent, ir_noise=float(nz["ir"]), dic_noise=float(nz["dic"]), seed=int(noise_seed),
                 decimals=int(nz["decimals"]), missing=float(nz["missing"]),
                 recipe={**r, "resolved": resolved})


def draw(seed: int, scale: str = "demo", *, noise_seed: int | None = None) -> Scene:
    """A member drawn from ``seed`` (:func:`recipe`), its noise from ``noise_seed`` (default ``seed``)."""
    return build(recipe(seed), scale, noise_seed=int(seed) if noise_seed is None else noise_seed)


def member(name: str, scale: str = "demo", *, noise_seed: int = 0) -> Scene:
    """The fixed member ``name`` (:data:`FIXED`)."""
    choice(name, "name", tuple(FIXED))
    return build(FIXED[name], scale, noise_seed=noise_seed)

