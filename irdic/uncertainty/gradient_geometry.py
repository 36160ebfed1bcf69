"""The IR fields' uncertainty from the points' positions: the DIC noise and the calibration.

The temperature is sampled where a point's noisy coordinates (and the
calibration) put it (:func:`position_var`). The in-plane gradient also lies
in the tangent plane of the fitted surface (:func:`gradient_dic_var`).

The regressed gradient is ``g = θ_a a^a``: the temperature's derivatives
along the surface parameters ``θ_a`` times the dual basis ``a^a`` of the
fitted surface's tangents ``a_b = ∂x/∂ψ^b``. The DIC noise moves those
tangents (the surface fit of noisy coordinates), and with them the plane
and the length scale of the gradient, by an error of its own that the IR
probes do not see (demo barrel, seed 3: 3.9e-4 K/mm of the 7.5e-4 K/mm
noise-propagated error; without it the noise part covered 0.58 / 0.86
within 1 / 2 std, with the realised term 0.63 / 0.88).
"""

from __future__ import annotations

import numpy as np

__all__ = ["position_std", "gradient_dic_var", "position_var", "tangent_noise", "TANGENT_PROBES", "TANGENT_TIMES"]

#: DIC noise probes through the surface fit for the tangents' noise
TANGENT_PROBES = 4
#: stages (the first included) the tangents' noise is probed at; it follows the slowly changing geometry
TANGENT_TIMES = 4
#: gradient values (time x point x component) of :func:`gradient_dic_var` worked on at once
_BLOCK_VALUES = 1 << 21


def position_std(points, sf, geo, grad, g_pix, temp_std, grad_std, s_x, p, regressed, rng, ops=None):
    """Temperature (T, N) and gradient (T, N, 3) std with the points' position terms added in quadrature.

    The temperature gets :func:`position_var`; a regressed gradient
    (``regressed``) gets its tangent plane's DIC noise,
    :func:`gradient_dic_var` of :func:`tangent_noise` (probes from a stream
    of their own, spawned from ``rng``: the other probes' draws stay as they
    were). ``grad`` (T, N, 3) K/mm: the fields' gradient; ``g_pix`` (T, N,
    2) K/px: the pixel gradients; ``s_x``: the DIC noise (mm); ``p``: the
    fields settings.
    """
    temp_std = np.sqrt(temp_std ** 2 + position_var(points, g_pix, grad, s_x))
    if regressed and np.isfinite(s_x) and s_x > 0:
        x = np.asarray(points["x"].transpose("time", "point", "component").values, dtype=float)  # read only
        s2 = tangent_noise(x, sf, s_x, p, rng.spawn(1)[0], ops)
        del x
        grad_std = np.sqrt(grad_std ** 2 + gradient_dic_var(grad, geo, s2))
    return temp_std, grad_std


def position_var(points, g_pix, grad, s_x):
    """Variance (T, N) K² of the temperature from the points' positions: the calibration's projected-position
    uncertainty along the pixel gradient ``g_pix``, and the DIC noise ``s_x`` (mm) along the surface gradient
    ``grad`` (each point is sampled, and placed in the surface parameters, where its noisy coordinates put it:
    an offset of its own that no regression averages; demo barrel: 0.003 K of 0.006 K)."""
    pix_std = points["pixel_std"].values.astype(float) if "pixel_std" in points else np.zeros(g_pix.shape[:2])
    cal = np.nan_to_num(pix_std) * np.linalg.norm(np.nan_to_num(g_pix), axis=-1)
    dic = np.nan_to_num(s_x * np.linalg.norm(grad, axis=-1))
    return cal ** 2 + dic ** 2


def gradient_dic_var(grad, geo, s2):
    """Variance (K/mm)² of each gradient component from the tangents' noise, to first order.

    Parameters
    ----------
    grad : ndarray, shape (T, N, 3)
        The in-plane gradient (K/mm).
    geo : Geometry
        Its surface's dual basis ``dual`` (T, N, 2, 3) and unit normal ``normal`` (T, N, 3).
    s2 : ndarray, shape (N, 2)
        Noise variance of each Cartesian component of the tangents ``a_1``, ``a_2``
        (dimensionless²; :func:`tangent_noise`).

    Returns
    -------
    ndarray, shape (T, N, 3)
        0 where the gradient or the geometry is missing.

    Notes
    -----
    With ``θ_a`` fixed, a perturbation ``ε_b`` of the tangent ``a_b`` moves
    the dual basis by ``δa^a = -(a^a · ε_b) a^b + G^{ab} (n · ε_b) n``
    (the first keeps ``a^a · a_b = δ^a_b``, the second the dual vectors in
    the tilted plane; ``G^{ab} = a^a · a^b``), so

    .. math:: δg = -\\sum_b (g · ε_b)\\, a^b + n \\sum_b (g · a^b)(n · ε_b).

    For ``ε_b`` with independent components of variance ``s_b²`` (the DIC
    noise is white and isotropic; the two tangents come from different
    derivatives of the fit), component ``i`` has the variance
    ``Σ_b s_b² (|g|² (a^b_i)² + (g · a^b)² n_i²)``: the in-plane stretch
    and the tilt out of the plane. Only the spatial regression's gradient
    is ``θ_a a^a`` with ``θ_a`` fixed; the paper's ``L g_pix`` keeps the
    pixel gradient instead (the stretch cancels there) and is dominated by
    the IR noise: the fields stage adds this term to the regressed gradient.
    The points' noisy positions also shift their samples (``σ_x |∇Θ|``,
    :func:`position_var`), white noise that the regression averages like
    the IR noise: ``(σ_x |g| / σ_T)²`` of its variance (demo barrel 0.4 %),
    left out.
    """
    grad = np.asarray(grad, dtype=float)
    var = np.zeros(grad.shape)
    s2 = np.nan_to_num(s2)
    # a block of times at a time: the products' temporaries of the whole record are GBs at paper scale
    step = max(1, _BLOCK_VALUES // max(1, grad[0].size))
    for t0 in range(0, grad.shape[0], step):
        tb = slice(t0, t0 + step)
        g, dual, n = np.nan_to_num(grad[tb]), np.nan_to_num(geo.dual[tb]), np.nan_to_num(geo.normal[tb])
        gg = np.sum(g * g, axis=-1)[..., None]
        gd = np.einsum("tnj,tnbj->tnb", g, dual)
        for b in range(2):
            var[tb] += s2[:, b][None, :, None] * (gg * dual[:, :, b] ** 2 + gd[..., b, None] ** 2 * n ** 2)
    return var


def tangent_noise(x, sf, s_x, p, rng, ops=None):
    """Noise variance (N, 2) of each Cartesian component of the two tangents, from DIC noise probes.

    Parameters
    ----------
    x : ndarray, shape (T, N, 3)
        The DIC coordinates (mm) the surface was fitted to.
    sf : SurfaceFit
        The fitted surface (its parameters ``psi`` and the smoothing in ``info``).
    s_x : float
        DIC coordinate noise per component (mm).
    p : dict
        The fields settings (``c_space``, ``R0_space``, ``solver``).
    rng : numpy.random.Generator
    ops : dict, optional
        The stage's spatial operators (shared factorisations).

    Returns
    -------
    ndarray, shape (N, 2)
        NaN where a point has no tangents.

    Notes
    -----
    :data:`TANGENT_PROBES` draws of white noise ``s_x`` run through each
    probed stage's spatial fit (:func:`irdic.surface.fit_stages`, the
    smoothing frozen, the first stage the shape's as in the fit); the
    variance pools the probes, the probed stages and the three components.
    With a regression in time the surface's tangents average several stages:
    the spatial fit's noise is then an upper bound.
    """
    from ..surface import fit_stages

    T, N = x.shape[:2]
    sub = np.unique(np.linspace(0, T - 1, min(T, TANGENT_TIMES)).round().astype(int))
    ks = sf.info.get("smoothing", None)
    ks = None if ks is not None and ks <= 1.0 else ks
    if ks is not None and sf.info.get("smoothing_shape") not in (None, ks):
        ks = (sf.info["smoothing_shape"], ks)
    nodes = np.flatnonzero(np.isfinite(sf.x).all(axis=-1).any(axis=0))
    clean = x[sub]
    # the clean stages first, then each probe's: one evaluation of the shared operators
    stages = [clean] + [clean + rng.standard_normal(clean.shape) * s_x for _ in range(TANGENT_PROBES)]
    shapes = [np.broadcast_to(st[0], st.shape) for st in stages]
    _, tang = fit_stages(np.concatenate(stages), sf.psi, shape_stage=np.concatenate(shapes), nodes=nodes,
                         c=p["c_space"], R0=p["R0_space"], solver=p["solver"], smoothing=ks,
                         operators={} if ops is None else ops, values=False)
    tang = tang.reshape((TANGENT_PROBES + 1, sub.size) + tang.shape[1:])
    eps = tang[1:] - tang[0]  # (probes, S, N, 2, 3)
    return np.mean(np.square(eps), axis=(0, 1, 4))
