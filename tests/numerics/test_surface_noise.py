"""Strain at realistic DIC noise (0.003 mm) against the analytic truth."""

import numpy as np
import pytest

from irdic.noise import STRAIN_NOISE_FLOOR
from irdic.strain import strain
from irdic.surface import fit_surface
from irdic.surface.fit import gcv_displacement
from irdic.synthetic import experiment


def _strain_error(name, seed, smoothing):
    """RMS of the max principal strain error over interior points (2 mm inside, not the end stages)."""
    ex = experiment(name, "demo", ir_noise=0.0, dic_noise=0.003, seed=seed)
    spec = ex.specimen
    truth = np.array([spec.principal_strains(ex.s, ex.h, t)[0] for t in ex.dic_times])
    s0, s1, h0, h1 = ex.patch
    inner = np.minimum.reduce([ex.s - s0, s1 - ex.s, ex.h - h0, h1 - ex.h]) >= 2.0
    sf = fit_surface(ex.x_dic, ex.dic_times, smoothing=smoothing)
    e = strain(sf.tangents, sf.ref_tangents, tensors=False).e_max
    err = (e - truth)[1:-1][:, inner]
    return float(np.sqrt(np.mean(err**2))), sf.info, truth


@pytest.mark.parametrize("seed", [1, 3])
def test_tube_strain_at_dic_noise_within_1e3(seed):
    # tension-torsion tube, 0.8 mm grid, 0.003 mm noise, 1 % failed points in half the stages:
    # GCV on the positions chose 2.5 spacings (1.5e-3 RMS); on the displacements 5 (4e-4)
    rms, info, truth = _strain_error("tube", seed, "gcv")
    assert np.abs(truth).max() > 0.05  # a real signal, not a static case
    assert rms <= 1e-3, (rms, info["smoothing"], info["gcv"])
    assert info["smoothing"] >= 4


def test_static_specimen_strain_below_the_noise_floor():
    # the half-shell does not move: the displacement is noise only, GCV takes the widest spacing and the
    # strain stays below the floor at which "auto" would call a strain noise-dominated
    rms, info, truth = _strain_error("halfshell", 3, "gcv")
    assert np.all(truth == 0)
    assert rms <= STRAIN_NOISE_FLOOR, (rms, info["smoothing"], info["gcv"])
    assert info["smoothing"] >= 10


def test_gcv_displacement_uses_measured_points_and_rigid_motion_is_free():
    rng = np.random.default_rng(4)
    g = np.arange(30) * 0.8
    psi = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    n = psi.shape[0]
    X0 = np.c_[psi, 0.02 * (psi[:, 0] - 12) ** 2]  # curved reference
    # a rigid translation plus a homogeneous stretch of 1 %: the displacement is linear in psi
    X = np.stack([X0 + [0.3 * m, -0.1 * m, 0.05 * m] + 0.01 * m * np.c_[psi, np.zeros(n)] for m in range(4)])
    X = X + rng.normal(0, 0.003, X.shape)
    valid = np.ones(X.shape[:2], bool)
    k, table = gcv_displacement(psi, X, valid)
    # a linear displacement is pure noise to any spacing: GCV takes (one of) the widest it can fit
    assert k >= 10, table
    # filled entries (here: garbage) are not judged when enough measured points remain
    Xb = X.copy()
    bad = rng.choice(n, n // 20, replace=False)
    Xb[2, bad] += 1.0
    valid[2, bad] = False
    assert gcv_displacement(psi, Xb, valid)[0] == k


def test_a_time_chunk_of_a_long_record_fits_the_whole_record_surface():
    """Shape and motion regressed apart, windowed in time: a chunk's surface equals the whole record's."""
    from irdic.chunks import window
    from irdic.numerics.temporal import temporal_window

    ex = experiment("tube", "demo", ir_noise=0.0, dic_noise=0.0)
    t = np.arange(90) * 0.5  # longer than the temporal kernel's reach (19 stages at 2 Hz)
    rng = np.random.default_rng(5)
    x = ex.specimen.position(ex.s[None], ex.h[None], t[:, None]) + rng.normal(0, 0.003, (t.size, ex.s.size, 3))
    n = temporal_window(t)
    assert n is not None
    kw = dict(smoothing=(3.0, 6.0))
    whole = fit_surface(x, t, **kw)
    for a, b in ((30, 45), (75, 90)):
        w = window(t, t[a], t[b - 1], n)
        assert w.start > 0
        part = fit_surface(x[w], t[w], whole.psi, t_eval=t[a:b], record_times=t, shape_stage=x[0], **kw)
        for name in ("x", "tangents", "velocity"):
            np.testing.assert_allclose(getattr(part, name), getattr(whole, name)[a:b], rtol=0, atol=1e-9,
                                       err_msg=name)
    # without the record's stage 0 the shape would be fitted on the window's first stage
    stray = fit_surface(x[w], t[w], whole.psi, t_eval=t[a:b], record_times=t, **kw)
    assert np.abs(stray.tangents - whole.tangents[a:b]).max() > 1e-7


def test_gcv_of_a_large_cloud_on_its_middle_patch_chooses_as_the_whole_cloud():
    from irdic.surface.regression import gcv_spatial

    rng = np.random.default_rng(2)
    s, h = np.meshgrid(np.arange(100) * 0.4, np.arange(60) * 0.4)
    psi = np.c_[s.ravel(), h.ravel()]
    f = np.c_[np.sin(psi[:, 0] / 6.0) * np.cos(psi[:, 1] / 5.0), 0.02 * psi[:, 0] ** 2 / 40]
    f = f + rng.normal(0, 0.01, f.shape)
    whole, table_w = gcv_spatial(psi, f, max_points=psi.shape[0])
    patch, table_p = gcv_spatial(psi, f, max_points=2500)
    assert patch == whole, (table_w, table_p)
    assert table_p[0][1] < table_w[0][1]  # the patch's design is the smaller one
