"""Levenberg-Marquardt refinement of a camera and leave-one-out residuals.

See :mod:`irdic.camera.model` for the camera convention and the physical
parameters.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.optimize import least_squares

from ..errors import CalibrationError, ConfigError
from .dlt import dlt, residual_info
from .model import PHYSICAL_PARAMETERS, CameraModel, pair_weights, point_pairs, project_physical, rotation_from_vector

__all__ = ["refine", "leave_one_out", "DISTORTIONS"]

log = logging.getLogger(__name__)

#: Free distortion coefficients for each ``distortion`` setting.
DISTORTIONS = {"none": (), "k1": ("k1",), "k1k2": ("k1", "k2")}


def refine(model: CameraModel, x, uv, *, distortion: str = "none", weights=None, point_covariances=None,
           max_nfev: int = 200) -> tuple[CameraModel, dict]:
    """Minimise the reprojection error by Levenberg-Marquardt from a start model.

    Free: ``f, cx, cy`` (square pixels, no skew), a rotation vector applied
    to the start rotation, the centre ``C`` and, with ``distortion``, ``k1``
    (and ``k2``); the covariance is that of :func:`_covariance`.

    Parameters
    ----------
    model : CameraModel
        Start (usually the DLT); its skew and aspect ratio are dropped.
    x : array_like, shape (N, 3)
        Points, mm.
    uv : array_like, shape (N, 2)
        Measured pixel positions, px.
    distortion : {"none", "k1", "k1k2"}
        Which radial distortion coefficients are free ("none": pinhole, k = 0).
    weights : array_like, shape (N,), optional
        Weight of each point's residual (``1 / sigma``).
    point_covariances : array_like, shape (N, 2, 2), optional
        Covariance of each measured position, px^2 (up to a common factor): the
        fit stays, its covariance is the estimator's under these (:func:`_covariance`).
    max_nfev : int
        Limit of function evaluations (per free parameter scale, see
        :func:`scipy.optimize.least_squares`).

    Returns
    -------
    model : CameraModel
        With ``covariance`` over :data:`PHYSICAL_PARAMETERS` (rows and columns
        of parameters held fixed are 0).
    info : dict
        ``residuals`` (N, 2) px, ``rms_px``, ``max_px``, ``sigma_px``,
        ``nfev``, ``message``, ``free`` (names of the free parameters).

    Raises
    ------
    CalibrationError
        Too few points, or the refinement failed or ended behind the camera.
    """
    if not isinstance(model, CameraModel):
        raise ConfigError(f"`model` must be a CameraModel, got {type(model).__name__}")
    if distortion not in DISTORTIONS:
        raise ConfigError(f"`distortion` must be one of {sorted(DISTORTIONS)}, got {distortion!r}")
    x, uv = point_pairs(x, uv)
    n = len(x)
    free_names = ("f", "cx", "cy", "rx", "ry", "rz", "Cx", "Cy", "Cz") + DISTORTIONS[distortion]
    if 2 * n <= len(free_names):
        raise CalibrationError(f"refinement of {len(free_names)} parameters needs more than {len(free_names) // 2} "
                               f"points, got {n}")
    w = pair_weights(weights, n)
    wr = None if w is None else np.repeat(w, 2)
    free = np.array([PHYSICAL_PARAMETERS.index(k) for k in free_names])
    p0, R0 = _start(model, free_names)

    def fun(q, R_base=R0, base=p0):
        p = base.copy()
        p[free] = q
        r = (project_physical(p, x, R_base) - uv).ravel()
        return r if wr is None else r * wr

    try:
        res = least_squares(fun, p0[free], method="lm", x_scale="jac", max_nfev=max_nfev * len(free))
    except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
        raise CalibrationError(f"refinement of the camera failed: {exc}") from exc
    if not np.isfinite(res.x).all() or res.status <= 0:
        raise CalibrationError(f"refinement of the camera did not converge: {res.message}")
    p = p0.copy()
    p[free] = res.x
    R = rotation_from_vector(p[3:6]) @ R0
    if p[0] <= 0:
        raise CalibrationError(f"refinement ended with a negative focal length ({p[0]:.1f} px)")
    cov, s2 = _covariance(fun, p, free, R, n, _point_covariances(point_covariances, n, wr))
    out = _physical_model(p, R, cov, x)
    resid = out.project(x) - uv
    info = residual_info(resid, np.sqrt(s2))
    info.update(nfev=int(res.nfev), message=str(res.message), free=list(free_names))
    log.debug("refine(%s): rms %.4f px after %d evaluations", distortion, info["rms_px"], res.nfev)
    return out, info


def _start(model: CameraModel, free_names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Start vector over :data:`PHYSICAL_PARAMETERS` (zero rotation vector) and the base rotation."""
    g = model.decompose()
    p0 = np.array([g.focal_length_px, g.K[0, 2], g.K[1, 2], 0, 0, 0, *g.C,
                   model.k1 if "k1" in free_names else 0.0, model.k2 if "k2" in free_names else 0.0])
    return p0, g.R


def _physical_model(p: np.ndarray, R: np.ndarray, cov: np.ndarray, x: np.ndarray) -> CameraModel:
    """The model of the parameters ``p`` with rotation ``R``; refused when a marker ``x`` is behind it."""
    K = np.array([[p[0], 0, p[1]], [0, p[0], p[2]], [0, 0, 1.0]])
    out = CameraModel(K=K, R=R, C=p[6:9], k1=p[9], k2=p[10], covariance=cov, parameters=PHYSICAL_PARAMETERS)
    if not (out.depth(x) > 0).all():
        raise CalibrationError("refinement moved the camera so that markers lie behind it; check the correspondence")
    return out


def _point_covariances(cov, n: int, wr: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    """``(C, w)``: the points' covariances (n, 2, 2) px^2 and weights (n,), checked; None without covariances."""
    if cov is None:
        return None
    c = np.asarray(cov, dtype=np.float64)
    if c.shape != (n, 2, 2) or not np.isfinite(c).all():
        raise ConfigError(f"`point_covariances` must be finite with shape ({n}, 2, 2), got {c.shape}")
    det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0]
    if not ((c[:, 0, 0] > 0) & (det > 0)).all():
        raise ConfigError("`point_covariances` must be positive definite (px^2)")
    return c, (np.ones(n) if wr is None else wr[0::2])


def _covariance(fun, p: np.ndarray, free: np.ndarray, R: np.ndarray, n: int,
                points: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, float]:
    """Covariance (11, 11) over :data:`PHYSICAL_PARAMETERS` at the solution ``p`` and the residual variance.

    ``fun(q, R_base, base)`` gives the weighted residuals (2n,) of the free
    parameters ``q`` around the rotation ``R_base``; ``points`` = ``(C, w)``,
    the measured positions' covariances (n, 2, 2) px^2 and the fit's
    weights (n,), when known.

    Notes
    -----
    The Jacobian is taken with the rotation re-based at the solution, so
    that the covariance of ``(rx, ry, rz)`` is that of a small rotation about
    the final ``R``. Without ``points``: :math:`\\Sigma = s^2 (J^T J)^{-1}`
    with :math:`s^2 = SSR / (2n - P)` (weighted residuals and Jacobian).
    With them, the covariance of the weighted least-squares estimator
    when point :math:`i` has covariance :math:`\\lambda C_i` (sandwich):

    .. math::

        \\Sigma = \\lambda A B A, \\quad
        A = (J^T J)^{-1}, \\quad
        B = \\sum_i J_i^T w_i^2 C_i J_i, \\quad
        \\lambda = \\frac{r^T r}{\\sum_i w_i^2 \\operatorname{tr} C_i - \\operatorname{tr}(A B)}

    with :math:`J_i` the point's two weighted rows and :math:`r` the
    weighted residuals: the denominator is :math:`E[r^T r]` for
    :math:`\\lambda = 1` (:math:`\\operatorname{tr}((I - H) W C)`,
    :math:`H = J A J^T`), so the scale comes from the residuals as
    :math:`s^2` does and the shape of each point's uncertainty from
    :math:`C_i`. With :math:`C_i \\propto I / w_i^2` the two agree. (Scaling
    by the whitened :math:`\\sum_i e_i^T C_i^{-1} e_i / (2n - P)` instead
    over-predicts: the weighted fit leaves residual in the directions
    where a thin marker's centre is precise.) Rows and columns of fixed
    parameters are 0.
    """
    pb = p.copy()
    pb[3:6] = 0.0
    J = np.empty((2 * n, len(free)))
    for j, k in enumerate(free):
        h = 1e-6 * max(1.0, abs(pb[k]))
        qp, qm = pb[free].copy(), pb[free].copy()
        qp[j] += h
        qm[j] -= h
        J[:, j] = (fun(qp, R, pb) - fun(qm, R, pb)) / (2 * h)
    r = fun(pb[free], R, pb)
    dof = max(2 * n - len(free), 1)
    s2 = float(r @ r) / dof
    try:
        A = np.linalg.inv(J.T @ J)
        if points is None:
            cov_free = s2 * A
        else:
            C, w = points
            Cw = C * (w**2)[:, None, None]
            Ji = J.reshape(n, 2, len(free))
            B = np.einsum("nia,nij,njb->ab", Ji, Cw, Ji)
            # E[r^T r] = tr((I - H) C_w) for the weighted residuals r, H = J A J^T
            lam = float(r @ r) / max(float(np.trace(Cw, axis1=1, axis2=2).sum() - np.trace(A @ B)), 1e-300)
            cov_free = lam * A @ B @ A
    except np.linalg.LinAlgError:
        cov_free = np.full((len(free), len(free)), np.nan)
    cov = np.zeros((len(PHYSICAL_PARAMETERS),) * 2)
    cov[np.ix_(free, free)] = cov_free
    return cov, s2


def leave_one_out(x, uv, *, method: str = "dlt", distortion: str = "none", weights=None,
                  start: CameraModel | None = None) -> np.ndarray:
    """Residual of each point when it is left out of the fit.

    A marker whose leave-one-out residual is far above the others is badly
    detected or wrongly assigned.

    Parameters
    ----------
    x, uv : array_like, shapes (N, 3) and (N, 2)
        Points (mm) and pixel positions (px).
    method : {"dlt", "refine"}
        Fit used for each subset: the DLT alone, or the DLT followed by
        :func:`refine` with ``distortion``.
    distortion : {"none", "k1", "k1k2"}
        For ``method="refine"``.
    weights : array_like (N,), optional
        As in :func:`dlt`.
    start : CameraModel, optional
        Start of each refinement (the fit to all points converges faster
        than each subset's DLT); default: the subset's DLT.

    Returns
    -------
    ndarray, shape (N,)
        Distance in px between each left-out point's measured and predicted
        position; NaN when the remaining points cannot be fitted (fewer than
        6, coplanar).
    """
    if method not in ("dlt", "refine"):
        raise ConfigError(f"`method` must be 'dlt' or 'refine', got {method!r}")
    x, uv = point_pairs(x, uv)
    n = len(x)
    w = pair_weights(weights, n) if weights is not None else None
    out = np.full(n, np.nan)
    keep = np.ones(n, dtype=bool)
    for i in range(n):
        keep[:] = True
        keep[i] = False
        wi = None if w is None else w[keep]
        try:
            if method == "refine" and start is not None:
                m, _ = refine(start, x[keep], uv[keep], distortion=distortion, weights=wi)
            else:
                m = CameraModel(dlt(x[keep], uv[keep], wi))
                if method == "refine":
                    m, _ = refine(m, x[keep], uv[keep], distortion=distortion, weights=wi)
        except CalibrationError:
            continue
        out[i] = float(np.hypot(*(m.project(x[i]) - uv[i])))
    return out
