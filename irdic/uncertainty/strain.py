"""Standard uncertainty of the max principal strain.

DIC noise probes run through the surface fit (smoothing frozen at the chosen
values) and the strain, as for the other fields
(:mod:`irdic.uncertainty.model`). What the probes give is the noise
covariance of the strain TENSOR: its mean ``m = (E11 + E22)/2`` and its
deviatoric 2-vector ``d = ((E11 - E22)/2, E12)``, per point. The max
principal strain ``e_max = m + |d|`` is not a smooth function of them where
``|d|`` is near 0 (a static or unloaded region, the first stages, an
equi-biaxial state): there the noisy ``|d̂|`` is biased upwards (a Rice
distribution, as the magnitude of a noisy MR signal) and its spread about the
noisy estimate, which the probes measured before, is not its error's RMS
(demo barrel, true strain 0, seeds 1, 3, 5, 7: the noise part of the error
1.17-1.54 x that spread, 0.47-0.55 within it, while each tensor component's
noise error is 0.9-1.3 x the probes' std). :func:`max_principal_rms`
therefore estimates the true ``|d|`` by the method of moments and takes the
RMS error of ``e_max`` at that tensor, the upward bias included; far from
degeneracy it is the linearised std. The surface regression's bias is
estimated on the tensor too (:func:`strain_std`).
"""

from __future__ import annotations

import numpy as np

from ..numerics.threads import parallel_map, worker_slices
from ..strain import strain_components
from ..surface import fit_surface
from .probes import BIAS_PROBES, PROBE_GROUP, PROBES, probe_times, spread
from .regression_bias import BIAS_Z, local_bias, reference_spacing, strain_reference_options

__all__ = ["strain_std", "max_principal_rms", "tensor_components", "below_noise_floor", "noise_floor_note"]

#: Gauss-Hermite nodes per dimension of the 2-D quadrature over the deviatoric noise
QUADRATURE_NODES = 8
#: the linearised variance where the estimated |d|² exceeds this many times the deviatoric noise's tr C_d
LINEAR_BEYOND = 100.0
#: points per block of the quadrature (its memory is the block times QUADRATURE_NODES²)
QUADRATURE_BLOCK = 16384
#: the strain is below its noise floor where |e_max| is under this many of its stds
NOISE_FLOOR_STDS = 2.0


def tensor_components(E2):
    """Mean and deviatoric components ``(m, d1, d2)`` (..., 3) of symmetric 2 x 2 tensors ``E2`` (..., 2, 2).

    Notes
    -----
    ``m = (E11 + E22)/2``, ``d1 = (E11 - E22)/2``, ``d2 = E12``: the principal
    values are ``m ± |d|`` (:func:`irdic.strain.principal_2d`).
    """
    E2 = np.asarray(E2, dtype=float)
    return np.stack([0.5 * (E2[..., 0, 0] + E2[..., 1, 1]), 0.5 * (E2[..., 0, 0] - E2[..., 1, 1]),
                     0.5 * (E2[..., 0, 1] + E2[..., 1, 0])], axis=-1)


def max_principal_rms(comp, cov):
    """RMS error of the max principal value ``m + |d|`` of a noisy tensor, about the true tensor's.

    Parameters
    ----------
    comp : ndarray, shape (..., 3)
        The estimated components ``(m, d1, d2)`` (:func:`tensor_components`).
    cov : ndarray, shape (..., 3, 3)
        Their noise covariance (zero-mean Gaussian noise assumed).

    Returns
    -------
    ndarray, shape (...)
        ``sqrt(E[(m̂ + |d̂| - m - |d|)²])`` at the method-of-moments estimate
        of the true tensor; NaN where an input is not finite.

    Notes
    -----
    With ``C_d`` the deviatoric block of ``cov``, ``E|d̂|² = |d|² + tr C_d``
    and, at ``d = 0``, ``|d̂|²`` scatters by ``sqrt(2 tr C_d²)``; the true
    magnitude is taken as resolved only beyond :data:`~irdic.uncertainty.regression_bias.BIAS_Z`
    such standard errors, ``|d|² ≈ max(|d̂|² - tr C_d - z sqrt(2 tr C_d²),
    0)``, along ``d̂``, and ``m ≈ m̂``. (With the moments alone, ``z = 0``, a
    zero tensor's largest noise draws got the smallest std: 0.57 / 0.87
    within 1 / 2 std; with ``z = 1``, 0.64 / 0.94.) With
    ``C_d = V Λ Vᵀ`` the deviatoric noise is ``L z`` (``L = V Λ^½``, ``z``
    standard normal in 2-D) and the mean's ``βᵀ z + σ_e z₃`` (``β = L⁺
    C_dm``, ``σ_e² = C_mm - |β|²``). Then

        MSE = σ_e² + E_z[(βᵀ z + |d + L z| - |d|)²],

    evaluated by a :data:`QUADRATURE_NODES`² Gauss-Hermite product rule
    (within 1 % in std of the Rice distribution's closed form). Far from
    degeneracy (``|d|² > LINEAR_BEYOND tr C_d``) it is the linearised variance
    ``C_mm + 2 uᵀ C_dm + uᵀ C_d u`` (``u = d/|d|``), which is used there; at
    ``d = 0``, ``C_d = σ² I`` and ``C_dm = 0`` it is ``C_mm + 2 σ²``: the
    upward bias ``σ √(π/2)`` of the Rayleigh magnitude included.
    """
    comp, cov = np.asarray(comp, dtype=float), np.asarray(cov, dtype=float)
    lead = comp.shape[:-1]
    c, C = comp.reshape(-1, 3), np.broadcast_to(cov, lead + (3, 3)).reshape(-1, 3, 3)
    out = np.full(c.shape[0], np.nan)
    ok = np.isfinite(c).all(axis=1) & np.isfinite(C).all(axis=(1, 2))
    idx = np.flatnonzero(ok)
    z, w = _nodes()
    for s in range(0, idx.size, QUADRATURE_BLOCK):
        i = idx[s:s + QUADRATURE_BLOCK]
        out[i] = np.sqrt(_mse(c[i], C[i], z, w))
    return out.reshape(lead)


def _nodes():
    """2-D probabilists' Gauss-Hermite nodes (K, 2) and weights (K,) for a standard normal ``z``."""
    x, wx = np.polynomial.hermite_e.hermegauss(QUADRATURE_NODES)
    wx = wx / wx.sum()
    z = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    return z, np.outer(wx, wx).ravel()


def _mse(c, C, z, w):
    """Mean squared error of ``m + |d|`` (see :func:`max_principal_rms`) for points ``c`` (n, 3), ``C`` (n, 3, 3)."""
    Cd, Cdm = C[:, 1:, 1:], C[:, 1:, 0]
    lam, V = np.linalg.eigh(0.5 * (Cd + np.swapaxes(Cd, -1, -2)))
    lam = np.maximum(lam, 0.0)
    L = V * np.sqrt(lam)[:, None, :]
    # β = Λ^-½ Vᵀ C_dm, 0 along a direction without noise
    proj = np.einsum("nji,nj->ni", V, Cdm)
    beta = np.divide(proj, np.sqrt(lam), out=np.zeros_like(proj), where=lam > 0)
    resid = np.maximum(C[:, 0, 0] - np.sum(beta ** 2, axis=1), 0.0)
    d_hat = c[:, 1:]
    r_hat = np.hypot(d_hat[:, 0], d_hat[:, 1])
    r = resolved_magnitude(c, C)
    d = d_hat * np.divide(r, r_hat, out=np.zeros_like(r), where=r_hat > 0)[:, None]
    # far from degeneracy the linearised variance (the quadrature's to < 0.3 % in std)
    u = np.divide(d, r[:, None], out=np.zeros_like(d), where=r[:, None] > 0)
    out = C[:, 0, 0] + 2 * np.sum(u * Cdm, axis=1) + np.einsum("ni,nij,nj->n", u, Cd, u)
    near = np.flatnonzero(~(r ** 2 > LINEAR_BEYOND * lam.sum(axis=1)))
    # written out per component on (n, K) arrays: einsum over these small axes took 6 x longer
    z0, z1 = z[:, 0], z[:, 1]
    col = lambda a: a[near, None]  # noqa: E731
    x0 = col(d[:, 0]) + col(L[:, 0, 0]) * z0 + col(L[:, 0, 1]) * z1
    x1 = col(d[:, 1]) + col(L[:, 1, 0]) * z0 + col(L[:, 1, 1]) * z1
    err = np.hypot(x0, x1) - col(r) + col(beta[:, 0]) * z0 + col(beta[:, 1]) * z1
    out[near] = resid[near] + np.square(err) @ w
    return out


def resolved_magnitude(comp, cov):
    """The method-of-moments magnitude of the deviatoric part (...) of :func:`max_principal_rms` (Notes): 0 where
    ``|d̂|²`` is within :data:`~irdic.uncertainty.regression_bias.BIAS_Z` standard errors of its noise mean."""
    Cd = np.asarray(cov)[..., 1:, 1:]
    noise = np.trace(Cd, axis1=-2, axis2=-1) + BIAS_Z * np.sqrt(2 * np.sum(np.square(Cd), axis=(-2, -1)))
    return np.sqrt(np.maximum(np.sum(np.square(np.asarray(comp)[..., 1:]), axis=-1) - noise, 0.0))


def _e_max_part(base, cov):
    """``c -> `` the part (...) of tensor differences ``c`` (..., 3) that moves ``e_max`` at the estimate ``base``:
    ``c_m + uᵀ c_d`` (``u`` along ``base``'s deviatoric part) where its magnitude is resolved
    (:func:`resolved_magnitude`), the norm ``|c|`` where not (the direction is noise there, and a bias ``b``
    of a zero tensor moves ``e_max`` by ``b_m + |b_d|``).

    Notes
    -----
    Linear in ``c`` where resolved: its noise is the probes' (the difference
    of two max principal values holds their magnitudes' noise bias), and far
    from degeneracy it is the linearised difference of ``e_max`` the bias
    was estimated from before. The norm alone counted ``e_min``'s bias too
    (tiny tube: 0.86 within 1 std).
    """
    r = np.linalg.norm(base[..., 1:], axis=-1, keepdims=True)
    u = np.divide(base[..., 1:], r, out=np.zeros_like(base[..., 1:]), where=r > 0)
    resolved = resolved_magnitude(base, cov) > 0
    return lambda c: np.where(resolved, c[..., 0] + np.sum(c[..., 1:] * u, axis=-1), np.linalg.norm(c, axis=-1))


def below_noise_floor(e_max, std):
    """Where the max principal strain is not resolved from zero: ``|e_max| < NOISE_FLOOR_STDS x std`` (a positive
    std only; the reference stage's is 0 by definition)."""
    e, s = np.asarray(e_max, dtype=float), np.asarray(std, dtype=float)
    with np.errstate(invalid="ignore"):
        return (s > 0) & (np.abs(e) < NOISE_FLOOR_STDS * s)


def noise_floor_note(e_max, std) -> str | None:
    """The store's note where the max principal strain ``e_max`` (T, N) is below its noise floor
    (:func:`below_noise_floor` of its ``std``) somewhere; None where nowhere."""
    if not below_noise_floor(e_max, std).any():
        return None
    # no count: a time chunk's note becomes the gathered store's
    return (f"max_principal_strain: below its noise floor where |max_principal_strain| < {NOISE_FLOOR_STDS:g} "
            "max_principal_strain_std (a static or unloaded region, the first stages, an equi-biaxial state): there "
            "the value is mostly noise, biased upwards as the max principal value of a noisy tensor, and the std is "
            "its RMS error about the true strain with that bias")


def strain_std(points, sf, t, p, s_x, rng, window=None, trusted=None, ops=None):
    """Standard uncertainty (T, N) of the max principal strain from the DIC noise ``s_x`` (mm) and the surface
    regression's bias; NaN when the DIC noise is unknown or zero.

    The probes (:func:`_probe_tensors`) give each point's noise covariance of
    the tensor components, :func:`max_principal_rms` the RMS error of
    ``e_max`` from it; the regression's bias is estimated
    (:func:`~irdic.uncertainty.regression_bias.local_bias`) from the tensor's
    difference to the reference spacing's, the part of it that moves
    ``e_max`` (:func:`_e_max_part`).

    Notes
    -----
    Demo scenes (``benchmarks/bench_noisy_fields.py``, seeds 1, 3, 5, 7),
    within 1 / 2 std, before -> after: static barrel 0.86 / 0.98 -> 0.82 /
    0.98, 0.79 / 0.95 -> 0.72 / 0.95, 0.57 / 0.85 -> 0.61 / 0.90, 0.67 /
    0.92 -> 0.69 / 0.95; the tube (far from degeneracy) unchanged. The bias
    against the half-spacing reference, which is as biased
    (:func:`~irdic.uncertainty.regression_bias.strain_reference_options`): the
    local estimate alone covered the tube's errors 0.69 / 0.91 pooled over
    those seeds, with the halved, pooled one 0.74 / 0.94 (barrel 0.71 /
    0.94 -> 0.70 / 0.95).
    """
    T, N = sf.x.shape[:2]
    if not (np.isfinite(s_x) and s_x > 0):
        return np.full((T, N), np.nan)
    sub, near = probe_times(T)
    base, samples, bases, regressed, smoothing = _probe_tensors(points, sf, t, p, s_x, rng, window, ops, sub)
    dev = np.array(samples[0]) - base
    cov = np.einsum("ksni,ksnj->snij", dev, dev) / dev.shape[0]
    std = max_principal_rms(base, cov)
    if regressed:
        k = len(samples[1])
        e_max_part = _e_max_part(base, cov)
        null = np.square(e_max_part((np.array(samples[0][:k]) - base) - (np.array(samples[1]) - bases[1])))
        std = np.hypot(std, local_bias(e_max_part(base - bases[1]), null.mean(axis=0), sf.psi,
                                       None if trusted is None else trusted[sub], null, smoothing,
                                       **strain_reference_options(smoothing)))
    std = spread(std, near)
    # the strain is zero by definition at the reference stage (stage 0 of the record): no uncertainty there,
    # whatever rounding the probes leave
    t_ref = t[0] if window is None else window.t_ref[0]
    std[np.asarray(t) == t_ref] = 0.0
    return std


def _probe_tensors(points, sf, t, p, s_x, rng, window, ops, sub):
    """The tensor components (S, N, 3) at the probed times ``t[sub]``: the fit's own, the probes' (list per
    operator: the fit's and, for a regression, the reference spacing's first ones), the reference's own
    without noise; whether the fit regresses, and its spatial spacing(s)."""
    x = np.asarray(points["x"].transpose("time", "point", "component").values, dtype=float)  # read only
    base = tensor_components(strain_components(sf.tangents[sub], sf.ref_tangents))
    kw = dict(c=p["c_space"], R0=p["R0_space"], c_t=p["c_time"], R0_t=p["R0_time"], solver=p["solver"],
              smoothing=sf.info.get("smoothing", None), smoothing_t=sf.info.get("smoothing_t", None))
    kw = {k: (None if k.startswith("smoothing") and v is not None and v <= 1.0 else v) for k, v in kw.items()}
    if kw["smoothing"] is not None and sf.info.get("smoothing_shape") not in (None, sf.info["smoothing"]):
        # the fit's own pair of spacings (shape, motion), so that the probes regress as the fit did
        kw["smoothing"] = (sf.info["smoothing_shape"], sf.info["smoothing"])
    # every probe fits the same points: the spatial factorisations are shared (with the fields stage's own)
    kw["operators"] = {} if ops is None else ops
    # a surface regression's bias: against the regression with half the spacing (see local_bias)
    regressed = kw["smoothing"] is not None or kw["smoothing_t"] is not None
    kws = [kw, {**kw, "smoothing": reference_spacing(kw["smoothing"]), "smoothing_t": None}] if regressed else [kw]
    probe = _StrainProbe(x, sf, t, sub, window)
    # the reference's own result (no noise) first: its regressions are factorised before any probe stack is
    # held (at 26,000 points a design matrix and its QR, 0.7 GB at once)
    bases = [base] + ([probe.tensors(kws[1], [probe.zero])[0]] if regressed else [])
    samples = [[] for _ in kws]
    for start in range(0, PROBES, PROBE_GROUP):
        draws = [probe.draw(rng, s_x) for _ in range(min(PROBE_GROUP, PROBES - start))]
        # the group's probes split over the stage's threads (its memory, not more), each block through the
        # fit's operator and, for the first probes, the reference's; a probe that refits the whole record
        # (a regression in time) is GBs at paper scale: those one at a time
        blocks = worker_slices(len(draws)) if probe.stagewise else [slice(None)]
        jobs = [(i, draws[b]) for i in range(1 + (regressed and start < BIAS_PROBES)) for b in blocks]

        def tensors(job):
            return probe.tensors(kws[job[0]], job[1])

        done = parallel_map(tensors, jobs) if probe.stagewise else list(map(tensors, jobs))
        for (i, _), got in zip(jobs, done):
            samples[i] += got
    return base, samples, bases, regressed, kw["smoothing"]


#: values of the record-length noise of a strain probe drawn at once (:meth:`_StrainProbe.draw`)
_DRAW_BLOCK = 1 << 21


class _StrainProbe:
    """The strain tensor's components at the probed times ``t[sub]`` of the surface fit with DIC noise added.

    Without a regression in time (the usual case) the surface at a stage's
    own time is that stage's spatial fit (:func:`irdic.surface.fit_stages`):
    only the probed stages and the reference stage are fitted, all probes of
    a group in one evaluation. With one, each probe refits the whole record
    (or the chunk's window, :func:`_window_probe`) as the fields stage does.
    """

    def __init__(self, x, sf, t, sub, window):
        self.x, self.sf, self.t, self.sub, self.window = x, sf, t, sub, window
        src_t = t if window is None else window.t
        self.idx = np.searchsorted(src_t, t[sub])
        self.shape = x.shape if window is None else window.x.shape
        self.stagewise = sf.info.get("smoothing_t") in (None, 1.0) and bool(np.asarray(sf.stage_used)[self.idx].all())
        self.nodes = np.flatnonzero(np.isfinite(sf.x).all(axis=-1).any(axis=0))
        self.zero = (0.0, None if window is None else 0.0)

    def draw(self, rng, s_x):
        """One probe's coordinate noise: (window or record, reference stages), kept at the stages it needs."""
        if self.stagewise:
            # the record's draw a block of stages at a time (the generator's stream is the same), the probed kept
            dx = np.empty((self.idx.size,) + self.shape[1:])
            step = max(1, _DRAW_BLOCK // max(1, int(np.prod(self.shape[1:]))))
            for s0 in range(0, self.shape[0], step):
                block = rng.standard_normal((min(step, self.shape[0] - s0),) + self.shape[1:])
                at = (self.idx >= s0) & (self.idx < s0 + step)
                dx[at] = block[self.idx[at] - s0] * s_x
        else:
            dx = rng.standard_normal(self.shape) * s_x
        dref = rng.standard_normal(self.window.x_ref.shape) * s_x if self.window is not None else None
        return dx, dref

    def tensors(self, kw, draws):
        """Tensor components (S, N, 3) (:func:`tensor_components`) at the probed times of each probe of ``draws``."""
        from ..surface import fit_stages

        sf, w = self.sf, self.window
        if not self.stagewise:
            out = []
            for dx, dref in draws:
                pf = (fit_surface(self.x + dx, self.t, psi=sf.psi, t_eval=self.t[self.sub], **kw) if w is None
                      else _window_probe(w, self.t[self.sub], sf.psi, kw, dx, dref))
                out.append(tensor_components(strain_components(pf.tangents, pf.ref_tangents)))
            return out
        stages, shapes = [], []
        for dx, dref in draws:
            if w is None:  # the probed times include stage 0, the reference and the shape stage
                st = self.x[self.sub] + dx
                x0 = st[0]
            else:
                x0 = w.x_ref[0] + (dref[0] if np.ndim(dref) else 0.0)
                st = np.concatenate([x0[None], w.x[self.idx] + dx])
            stages.append(st)
            shapes.append(np.broadcast_to(x0, st.shape))
        kws = {k: v for k, v in kw.items() if k not in ("c_t", "R0_t", "smoothing_t")}
        _, tang = fit_stages(np.concatenate(stages), sf.psi, shape_stage=np.concatenate(shapes), nodes=self.nodes,
                             values=False, **kws)
        tang = tang.reshape((len(draws), -1) + tang.shape[1:])
        first = 0 if w is None else 1
        return [tensor_components(strain_components(g[first:], g[0])) for g in tang]


def _window_probe(window, t, psi, kw, dx, dref):
    """A surface fit of a chunk as the fields stage fits it, with the coordinate noise ``dx`` (window) and
    ``dref`` (the record's first two stages) added: over its window, at its times ``t``, with the strain's
    reference from the record's first two stages."""
    dref = np.zeros(window.x_ref.shape) + (0.0 if dref is None else dref)
    pf = fit_surface(window.x + dx, window.t, psi, t_eval=t, record_times=window.record,
                     shape_stage=window.x_ref[0] + dref[0], **kw)
    if window.t[0] > window.t_ref[0]:
        ref = fit_surface(window.x_ref + dref, window.t_ref, psi,
                          t_eval=window.t_ref[:1], **{**kw, "smoothing_t": None})
        pf = pf._replace(ref_x=ref.ref_x, ref_tangents=ref.ref_tangents)
    return pf
