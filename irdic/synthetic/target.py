"""Open-book calibration target: geometry, exact perspective rendering, truth.

The target (:class:`OpenBook`) is two planar wings meeting at a vertical
hinge, opened by 90 deg towards the cameras (a "V" whose inside faces +z). The
hinge runs through (0, 0, -27) mm of the DIC frame, so the markers are centred
near (0, 0, -5) mm where the specimens later stand. Each wing is 62 x 56 mm
and carries 7 x 6 circular markers of radius 1.6 mm on an 8 mm pitch (columns
7..55 mm from the hinge, rows y = -20..20 mm): 84 markers. Their IDs are
unique integers in 1..299, shuffled (DIC software numbers markers in the
order it finds them, not in grid order).

IR appearance (the target is not heated; markers differ in emissivity): the
wings at 24.0 degC, markers 2.5 K darker (``polarity="dark"``) or brighter,
room background 20.0 degC, Gaussian noise (0.04 K by default). A plate heated
from one side is modelled by ``gradient_k``: a temperature rise linear in the
DIC ``x`` coordinate of the hit point, ``gradient_k`` kelvin from one wing tip
to the other, on wings and markers alike (the marker contrast is unchanged).

Rendering is exact under perspective (and distortion). Pixels outside the
box that holds the projected wing outlines see the room; inside it, every
pixel whose 5 x 5 neighbourhood sees more than one surface in the
centre-sampled label image is AREA-SAMPLED with ``supersample x supersample``
rays spread uniformly over the pixel square, each intersected with the wing
planes and tested against the marker circles; other pixels are uniform and
take the value of their centre ray. The recorded value is the area-weighted mean of
the apparent temperatures (a linear mixing model). Hence the imaged centre of
a marker (centroid of its imaged area) is not the image of its 3D centre:
both are part of the truth (``marker_centroid`` vs ``marker_pixel``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy import ndimage

from ..errors import ConfigError
from ..validation import as_finite, as_int, choice, positive
from ._geometry import TAU_MIN, nearest
from .camera import TrueCamera

__all__ = ["OpenBook", "TargetImage", "open_book_target", "camera_dataset", "clicked_seeds"]


@dataclass
class OpenBook:
    """Geometry of the open-book target (mm, DIC frame; see module docstring).

    Parameters
    ----------
    hinge_point : array_like, shape (3,)
        A point of the hinge line at the height of the middle marker row.
    opening_deg : float
        Angle between the wings (deg).
    yaw_deg : float
        Turn of the target about the vertical hinge towards +x (deg): 10 deg
        lets both wings face the IR camera (17.5 deg to +x) about equally.
    rotation : array_like, shape (3, 3), optional
        Extra rotation of the whole target about ``hinge_point``.
    wing_length, wing_height : float
        Wing size (mm).
    n_cols, n_rows : int
        Markers per wing along the wing and up it.
    pitch, first, radius : float
        Marker pitch, distance of the first column from the hinge, radius (mm).
    id_seed : int
        Seed of the shuffled marker IDs.
    unpainted : tuple of (wing, row, col)
        Grid positions left without a marker. Real targets break the
        symmetry of the open book this way (or with coded markers), so that an
        automatic marker assignment is unique; the default is the full
        symmetric grid.
    """

    hinge_point: tuple = (0.0, 0.0, -27.0)
    opening_deg: float = 90.0
    yaw_deg: float = 10.0
    rotation: np.ndarray | None = None
    wing_length: float = 62.0
    wing_height: float = 56.0
    n_cols: int = 7
    n_rows: int = 6
    pitch: float = 8.0
    first: float = 7.0
    radius: float = 1.6
    id_seed: int = 7
    unpainted: tuple = ()
    ids: np.ndarray = field(init=False)

    def __post_init__(self):
        self.hinge_point = as_finite(self.hinge_point, "hinge_point", (3,))
        op = positive(self.opening_deg, "opening_deg")
        if not 10.0 <= op <= 170.0:
            raise ConfigError(f"`opening_deg` must lie in [10, 170] deg; got {op}")
        Q = np.eye(3) if self.rotation is None else as_finite(self.rotation, "rotation", (3, 3))
        if not np.allclose(Q @ Q.T, np.eye(3), atol=1e-9):
            raise ConfigError("`rotation` must be orthonormal within 1e-9")
        yaw = math.radians(float(self.yaw_deg))
        Q = Q @ np.array([[math.cos(yaw), 0.0, math.sin(yaw)], [0.0, 1.0, 0.0], [-math.sin(yaw), 0.0, math.cos(yaw)]])
        self.rotation = Q
        for name in ("n_cols", "n_rows"):
            as_int(getattr(self, name), name)
        for name in ("wing_length", "wing_height", "pitch", "radius"):
            positive(getattr(self, name), name)
        half = math.radians(op) / 2
        sa, ca = math.sin(half), math.cos(half)
        # wing 0 = left (x < 0), wing 1 = right; w along the wing, n = front normal (into the V)
        self.w = np.array([Q @ [-sa, 0.0, ca], Q @ [sa, 0.0, ca]])
        self.n = np.array([Q @ [ca, 0.0, sa], Q @ [-ca, 0.0, sa]])
        self.up = Q @ np.array([0.0, 1.0, 0.0])
        a = self.first + self.pitch * np.arange(self.n_cols)
        b = self.pitch * (np.arange(self.n_rows) - (self.n_rows - 1) / 2)
        if a[-1] + self.radius > self.wing_length or abs(b[0]) + self.radius > self.wing_height / 2:
            raise ConfigError("the marker grid does not fit on the wings; enlarge `wing_length`/`wing_height`")
        self._a, self._b = a, b
        wing, row, col = np.meshgrid(np.arange(2), np.arange(self.n_rows), np.arange(self.n_cols), indexing="ij")
        self.marker_wing, self.marker_row, self.marker_col = wing.ravel(), row.ravel(), col.ravel()
        self.ids = np.random.default_rng(self.id_seed).choice(np.arange(1, 300), self.n_markers, replace=False)
        self.painted = np.ones(self.n_markers, dtype=bool)
        for w, r, c in self.unpainted:
            if not (0 <= w < 2 and 0 <= r < self.n_rows and 0 <= c < self.n_cols):
                raise ConfigError(f"`unpainted` position {(w, r, c)} is outside the 2 x {self.n_rows} x {self.n_cols} grid")
            self.painted[(w * self.n_rows + r) * self.n_cols + c] = False

    @property
    def n_markers(self) -> int:
        return 2 * self.n_rows * self.n_cols

    def centres(self) -> np.ndarray:
        """Marker centres (n_markers, 3) in mm, in the order of :attr:`ids`."""
        w = self.w[self.marker_wing]
        return self.hinge_point + self._a[self.marker_col, None] * w + self._b[self.marker_row, None] * self.up

    def marker_normals(self) -> np.ndarray:
        """Front normals (n_markers, 3) of the wings carrying the markers."""
        return self.n[self.marker_wing]

    def marker_axes(self):
        """Two orthonormal in-plane axes of each marker (each (n_markers, 3))."""
        return self.w[self.marker_wing], np.broadcast_to(self.up, (self.n_markers, 3))

    def trace(self, o, d):
        """Cast rays at the target.

        Returns
        -------
        tau : numpy.ndarray
            Distance to the hit (NaN: background).
        label : numpy.ndarray of int
            -1 background, 0 wing body, ``k + 1`` marker ``k`` (index into :attr:`ids`).
        """
        o = np.asarray(o, np.float64)
        d = np.asarray(d, np.float64)
        rel = o - self.hinge_point
        taus, locs, fronts = [], [], []
        for k in range(2):
            # all dot products via one small matmul; the origin terms are scalars for a camera
            dd = d @ np.stack([self.n[k], self.w[k], self.up], axis=-1)
            dn, dw, du = dd[..., 0], dd[..., 1], dd[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                tau = -(rel @ self.n[k]) / dn
            a = rel @ self.w[k] + tau * dw
            b = rel @ self.up + tau * du
            ok = (tau > TAU_MIN) & (a >= 0) & (a <= self.wing_length) & (np.abs(b) <= self.wing_height / 2)
            taus.append(np.where(ok, tau, np.nan))
            locs.append((a, b))
            fronts.append(dn < 0)
        idx, tau = nearest(taus)
        a = np.where(idx == 1, locs[1][0], locs[0][0])
        b = np.where(idx == 1, locs[1][1], locs[0][1])
        front = np.where(idx == 1, fronts[1], fronts[0])
        col = np.clip(np.rint((a - self.first) / self.pitch), 0, self.n_cols - 1).astype(np.int64)
        row = np.clip(np.rint((b - self._b[0]) / self.pitch), 0, self.n_rows - 1).astype(np.int64)
        r2 = (a - self._a[col]) ** 2 + (b - self._b[row]) ** 2
        marker = (np.maximum(idx, 0) * self.n_rows + row) * self.n_cols + col
        inside = front & (r2 <= self.radius**2) & (idx >= 0) & self.painted[marker]
        label = np.where(idx < 0, -1, np.where(inside, marker + 1, 0))
        return tau, label


@dataclass
class TargetImage:
    """What :func:`open_book_target` returns.

    Attributes
    ----------
    image : xarray.DataArray
        float32 temperatures (deg C), dims ``("v", "u")``, full-sensor coords.
    markers : xarray.Dataset
        ``x(marker, component)`` (mm), coordinate ``marker`` = IDs, as
        :func:`irdic.io.read_markers` returns it.
    truth : xarray.Dataset
        The camera (:func:`camera_dataset`) and per marker: ``marker_x``,
        ``marker_pixel`` (projection of the 3D centre), ``marker_centroid``
        (centroid of the imaged marker area), ``marker_radius_px``,
        ``marker_visible``.
    book : OpenBook
    camera : TrueCamera
    """

    image: xr.DataArray
    markers: xr.Dataset
    truth: xr.Dataset
    book: OpenBook
    camera: TrueCamera


def camera_dataset(camera: TrueCamera) -> xr.Dataset:
    """The true camera as a Dataset (what ``setup/truth.zarr`` stores).

    Variables: ``projection_matrix(row, col)`` (normalised M, px per mm
    homogeneous), ``K(row, kcol)`` (px), ``R(row, component)``,
    ``C(component)`` (mm), scalars ``f, cx, cy`` (px), ``k1, k2`` (1),
    ``width, height`` (px).
    """
    comp = ["x", "y", "z"]
    return xr.Dataset(
        {
            "projection_matrix": (("row", "col"), camera.matrix(),
                                  {"units": "px/mm (homogeneous)", "long_name": "normalised pinhole projection matrix M = K[R|-RC]"}),
            "K": (("row", "kcol"), camera.K, {"units": "px", "long_name": "intrinsic matrix"}),
            "R": (("row", "component"), camera.R,
                  {"units": "1", "long_name": "rotation, rows = image right, image down, viewing direction"}),
            "C": (("component",), camera.C, {"units": "mm", "long_name": "camera centre (DIC frame)"}),
            "f": ((), camera.f, {"units": "px", "long_name": "focal length"}),
            "cx": ((), camera.cx, {"units": "px", "long_name": "principal point u"}),
            "cy": ((), camera.cy, {"units": "px", "long_name": "principal point v"}),
            "k1": ((), camera.k1, {"units": "1", "long_name": "radial distortion k1"}),
            "k2": ((), camera.k2, {"units": "1", "long_name": "radial distortion k2"}),
            "width": ((), camera.width, {"units": "px", "long_name": "sensor width"}),
            "height": ((), camera.height, {"units": "px", "long_name": "sensor height"}),
        },
        coords={"row": [0, 1, 2], "col": [0, 1, 2, 3], "kcol": [0, 1, 2], "component": comp},
    )


def _polygon_centroid(uv):
    """Area centroid of closed polygons ``uv`` (..., n, 2) (shoelace formula)."""
    x, y = uv[..., 0], uv[..., 1]
    x1, y1 = np.roll(x, -1, axis=-1), np.roll(y, -1, axis=-1)
    cross = x * y1 - x1 * y
    A = 0.5 * cross.sum(-1)
    cx = ((x + x1) * cross).sum(-1) / (6 * A)
    cy = ((y + y1) * cross).sum(-1) / (6 * A)
    return np.stack([cx, cy], axis=-1), np.abs(A)


def _marker_truth(book: OpenBook, camera: TrueCamera, n_boundary: int = 2048):
    X = book.centres()
    e1, e2 = book.marker_axes()
    ang = 2 * np.pi * np.arange(n_boundary) / n_boundary
    ring = X[:, None, :] + book.radius * (np.cos(ang)[:, None] * e1[:, None, :] + np.sin(ang)[:, None] * e2[:, None, :])
    uv_ring = camera.project(ring)
    centroid, area = _polygon_centroid(uv_ring)
    # seen when the centre and every boundary point are the first hit and on the sensor
    pts = np.concatenate([X[:, None, :], ring[:, ::16, :]], axis=1)
    dvec = pts - camera.C
    dist = np.linalg.norm(dvec, axis=-1)
    tau, _ = book.trace(camera.C, dvec / dist[..., None])
    front = np.einsum("ij,ij->i", camera.C - X, book.marker_normals()) > 0
    seen = np.all(np.abs(tau - dist) < 1e-6, axis=1) & front
    seen &= np.all(camera.in_frame(camera.project(pts)), axis=1)
    return camera.project(X), centroid, np.sqrt(area / np.pi), seen


def _footprint(book: OpenBook, camera: TrueCamera):
    """Pixel box ``(u0, u1, v0, v1)`` (end exclusive) that holds the image of the wings.

    The wing outlines are projected densely (0.3 mm steps) and the box grown by
    3 px; outside it only the room is seen. The whole sensor when part of the
    target is behind the camera.
    """
    a = np.linspace(0.0, book.wing_length, int(book.wing_length / 0.3) + 2)
    b = np.linspace(-book.wing_height / 2, book.wing_height / 2, int(book.wing_height / 0.3) + 2)
    pts = []
    for k in range(2):
        for aa, bb in ((a, np.full_like(a, b[0])), (a, np.full_like(a, b[-1])),
                       (np.full_like(b, a[0]), b), (np.full_like(b, a[-1]), b)):
            pts.append(book.hinge_point + aa[:, None] * book.w[k] + bb[:, None] * book.up)
    uv = camera.project(np.concatenate(pts))
    if not np.isfinite(uv).all():
        return 0, camera.width, 0, camera.height
    u0 = int(np.clip(np.floor(uv[:, 0].min()) - 3, 0, camera.width))
    u1 = int(np.clip(np.ceil(uv[:, 0].max()) + 4, 0, camera.width))
    v0 = int(np.clip(np.floor(uv[:, 1].min()) - 3, 0, camera.height))
    v1 = int(np.clip(np.ceil(uv[:, 1].max()) + 4, 0, camera.height))
    return u0, max(u1, u0), v0, max(v1, v0)


def open_book_target(camera: TrueCamera, *, noise: float = 0.04, polarity: str = "dark", seed: int = 0,
                     supersample: int = 8, book: OpenBook | None = None, body: float = 24.0,
                     contrast: float = 2.5, background: float = 20.0, gradient_k: float = 0.0) -> TargetImage:
    """Render the IR image of the open-book target and return it with its truth.

    Parameters
    ----------
    camera : TrueCamera
        Any pose, with or without distortion.
    noise : float
        Standard deviation of the Gaussian pixel noise (K).
    polarity : {"dark", "bright"}
        Whether markers appear colder or warmer than the wings.
    seed : int
        Seed of the noise.
    supersample : int
        Rays per pixel side at edges (8 -> 64 rays per edge pixel).
    book : OpenBook, optional
        Target geometry (default :class:`OpenBook`).
    body, contrast, background : float
        Apparent temperatures: wings ``body``, markers ``body -+ contrast``,
        room ``background`` (deg C).
    gradient_k : float
        Temperature difference across the target (K), linear in the DIC
        ``x`` coordinate from the left wing tip to the right one (a plate
        heated from one side); 0 = isothermal.

    Returns
    -------
    TargetImage
    """
    if not isinstance(camera, TrueCamera):
        raise ConfigError(f"`camera` must be a TrueCamera; got {type(camera).__name__}")
    noise = positive(noise, "noise", allow_zero=True)
    choice(polarity, "polarity", ("dark", "bright"))
    n = as_int(supersample, "supersample")
    book = OpenBook() if book is None else book
    gradient_k = float(as_finite(gradient_k, "gradient_k", ()))
    T_marker = body - contrast if polarity == "dark" else body + contrast
    temp = _temperature_model(book, body, T_marker, background, gradient_k)
    img = _render(book, camera, temp, background, n)
    if noise > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    image = xr.DataArray(
        img.astype(np.float32), dims=("v", "u"),
        coords={"v": np.arange(camera.height), "u": np.arange(camera.width)}, name="temperature",
        attrs={"units": "°C", "long_name": "apparent temperature of the open-book target", "noise_K": noise,
               "polarity": polarity, "supersample": n, "gradient_K": gradient_k},
    )
    markers, truth = _marker_datasets(book, camera)
    truth.attrs.update({"marker_polarity": polarity, "marker_temperature": T_marker, "body_temperature": body,
                        "background_temperature": background, "noise_K": noise,
                        "marker_contrast": float(contrast), "gradient_K": gradient_k})
    return TargetImage(image=image, markers=markers, truth=truth, book=book, camera=camera)


def _temperature_model(book: OpenBook, body: float, T_marker: float, background: float, gradient_k: float):
    """``temp(label, o, d, tau)``: apparent temperature (°C) of rays ``o + tau d`` that hit ``label``.

    Labels are those of :meth:`OpenBook.trace` (-1 room, 0 wing, >0 marker);
    the gradient is linear in ``x`` from the left wing tip to the right one.
    """
    tips = book.hinge_point + book.wing_length * book.w
    x_lo, x_hi = float(tips[:, 0].min()), float(tips[:, 0].max())

    def temp(label, o, d, tau):
        T = np.where(label < 0, background, np.where(label == 0, body, T_marker))
        if gradient_k == 0.0:
            return T
        x = o[..., 0] + np.nan_to_num(tau) * d[..., 0]
        return T + np.where(label < 0, 0.0, gradient_k * (x - x_lo) / (x_hi - x_lo))

    return temp


def _render(book: OpenBook, camera: TrueCamera, temp, background: float, n: int) -> np.ndarray:
    """Noise-free image (H, W), °C: one ray per pixel, ``n x n`` rays per pixel near label edges."""
    W, H = camera.width, camera.height
    u0, u1, v0, v1 = _footprint(book, camera)
    uu, vv = np.meshgrid(np.arange(u0, u1, dtype=np.float64), np.arange(v0, v1, dtype=np.float64))
    lab = np.full((H, W), -1, np.int64)
    o, d = camera.ray(uu, vv)
    tau, lab[v0:v1, u0:u1] = book.trace(o, d)
    img = np.full((H, W), background, np.float64)
    img[v0:v1, u0:u1] = temp(lab[v0:v1, u0:u1], o, d, tau)
    edge = ndimage.maximum_filter(lab, size=5) != ndimage.minimum_filter(lab, size=5)
    ev, eu = np.nonzero(edge)
    off = (np.arange(n) + 0.5) / n - 0.5
    ou, ov = np.meshgrid(off, off)
    ou, ov = ou.ravel(), ov.ravel()
    chunk = max(1, 2_000_000 // (n * n))
    for i in range(0, ev.size, chunk):
        su = eu[i:i + chunk, None] + ou
        sv = ev[i:i + chunk, None] + ov
        o, d = camera.ray(su, sv)
        tau_s, sl = book.trace(o, d)
        img[ev[i:i + chunk], eu[i:i + chunk]] = temp(sl, o, d, tau_s).mean(axis=1)
    return img


def _marker_datasets(book: OpenBook, camera: TrueCamera) -> tuple[xr.Dataset, xr.Dataset]:
    """The painted markers as DIC exports them, and the camera with the markers' imaged truth."""
    X = book.centres()
    markers = xr.Dataset(
        {"x": (("marker", "component"), X, {"units": "mm", "long_name": "marker centre"})},
        coords={"marker": book.ids.astype(np.int64), "component": ["x", "y", "z"]},
    )
    proj, cen, rad, seen = _marker_truth(book, camera)
    truth = camera_dataset(camera)
    truth = truth.assign_coords(marker=book.ids.astype(np.int64), pix=["u", "v"])
    truth["marker_x"] = (("marker", "component"), X, {"units": "mm", "long_name": "marker centre (DIC frame)"})
    truth["marker_pixel"] = (("marker", "pix"), proj,
                             {"units": "px", "long_name": "projection of the 3D marker centre (true camera)"})
    truth["marker_centroid"] = (("marker", "pix"), cen,
                                {"units": "px", "long_name": "area centroid of the imaged marker"})
    truth["marker_radius_px"] = (("marker",), rad, {"units": "px", "long_name": "radius of the disc of equal imaged area"})
    truth["marker_visible"] = (("marker",), seen, {"long_name": "marker fully seen by the camera"})
    # only painted markers exist for the DIC system; list them by ID, as DIC
    # software exports them (the IDs do not follow the grid)
    markers = markers.isel(marker=book.painted).sortby("marker")
    truth = truth.isel(marker=book.painted).sortby("marker")
    return markers, truth


def clicked_seeds(target: TargetImage, n: int = 8, *, sigma_px: float = 2.0, seed: int = 0) -> dict:
    """Seeds as a user clicks them: ``n`` visible markers, true projections + N(0, sigma_px).

    The markers are spread over both wings (every wing gets half of them,
    picked at random among its visible markers).

    Parameters
    ----------
    target : TargetImage
    n : int
        Number of seeds (>= 6).
    sigma_px : float
        Standard deviation of the click error per axis, px.
    seed : int
        Seed of the choice and of the click errors.

    Returns
    -------
    dict
        ``{marker_id: [u, v]}`` (px, full sensor).
    """
    n = as_int(n, "n")
    sigma_px = positive(sigma_px, "sigma_px", allow_zero=True)
    rng = np.random.default_rng(seed)
    tr = target.truth
    ids = tr.marker.values
    wing = target.book.marker_wing[target.book.painted][np.argsort(target.book.ids[target.book.painted])]
    seen = tr.marker_visible.values
    pick = []
    for w, k in ((0, n // 2), (1, n - n // 2)):
        cand = np.flatnonzero(seen & (wing == w))
        if len(cand) < k:
            raise ConfigError(f"wing {w} shows only {len(cand)} markers; {k} seeds were asked for on it")
        pick.extend(rng.choice(cand, k, replace=False).tolist())
    pix = tr.marker_pixel.values
    return {int(ids[i]): (pix[i] + rng.normal(0.0, sigma_px, 2)).tolist() for i in sorted(pick)}
