"""Figures of an experiment (irdic.plot) from fabricated stores with the contract layout."""

import warnings

import numpy as np
import pytest
from matplotlib.image import imread

from irdic.errors import ConfigError, DataError, IrdicWarning
from irdic.plot import (FIGURES, plot_experiment, plot_gradient, plot_history, plot_load, plot_rate, plot_strain,
                        plot_temperature, view_basis)

from .test_export import contract_stores

pytestmark = pytest.mark.filterwarnings("error::UserWarning:matplotlib.*")


@pytest.fixture(scope="module")
def stores():
    return contract_stores()


def _check_png(path, min_kb=10, min_ink=0.15):
    """A real picture: PNG, not tiny, and a good part of it not white."""
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > min_kb * 1024, path.stat().st_size
    img = imread(path)[..., :3]
    ink = (img < 0.95).any(axis=2).mean()
    assert ink > min_ink, ink
    return img


def test_view_basis_follows_the_image_axes(stores):
    points, _ = stores
    right, up, centre = view_basis(points)
    # u = 500 + 10 x, v = 400 - 10 y: right is +x, up is +y
    np.testing.assert_allclose(right, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(up, [0.0, 1.0, 0.0], atol=1e-12)
    x = points["x"].values[int(np.argmax(points["visible"].values.sum(axis=1)))]
    np.testing.assert_allclose(centre, np.nanmean(x, axis=0), atol=1e-12)


def test_view_basis_without_pixels_uses_the_main_axes(stores):
    points, _ = stores
    right, up, _ = view_basis(points.drop_vars("pixel"))
    # arc (40 mm chord) is wider than the height (30 mm): first axis along x, second along y
    assert abs(right[0]) > 0.999 and abs(up[1]) > 0.999


@pytest.fixture
def figures(monkeypatch):
    """The matplotlib figures the plot functions save, to check their content (scales, labels, titles)."""
    import irdic.plot.calibration
    import irdic.plot.fields
    import irdic.plot.history
    from irdic.plot.maps import save_figure

    saved = []

    def keep(fig, path, caption=None):
        saved.append(fig)
        return save_figure(fig, path, caption=caption)

    for mod in (irdic.plot.fields, irdic.plot.history, irdic.plot.calibration):
        monkeypatch.setattr(mod, "save_figure", keep)
    return saved


def _colour_bar(fig):
    """(label, vmin, vmax) of the figure's one colour bar."""
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1, [ax.get_label() for ax in fig.axes]
    cb = bars[0]._colorbar
    return cb.ax.get_ylabel(), cb.norm.vmin, cb.norm.vmax


def _texts(fig):
    return [t.get_text() for ax in fig.axes for t in (ax.title,)] + [fig._suptitle.get_text()]


@pytest.mark.parametrize("func", [plot_temperature, plot_rate])
def test_map_figures_show_their_values_on_the_right_scale(stores, tmp_path, func, figures):
    points, fields = stores
    kw = {} if func is plot_temperature else {"fields": fields}
    out = func(points, tmp_path / "sub" / "f.png", times=[0.5, 1.5], experiment="fab", **kw)
    assert out == tmp_path / "sub" / "f.png"
    _check_png(out)
    fig = figures[-1]
    k = [int(np.argmin(np.abs(points.time.values - t))) for t in (0.5, 1.5)]
    label, lo, hi = _colour_bar(fig)
    if func is plot_temperature:
        v = points.temperature.values[k]
        v = v[np.isfinite(v)]
        # the colour scale spans the 0.5 .. 99.5 percentiles of the temperatures shown
        assert label == "temperature (°C)"
        np.testing.assert_allclose([lo, hi], np.percentile(v, [0.5, 99.5]), rtol=1e-12)
        assert "fab: temperature on the surface" in _texts(fig)[-1]
    else:
        v = fields.temperature_rate.values[k]
        v = v[np.isfinite(v)]
        # rates diverge about 0 K/s: a symmetric scale to the 99th percentile of |rate|
        assert label == "temperature rate (K/s)"
        np.testing.assert_allclose([lo, hi], np.array([-1.0, 1.0]) * np.percentile(np.abs(v), 99), rtol=1e-12)
        assert "fab: material temperature rate" in _texts(fig)[-1]
    assert [f"t = {points.time.values[i]:g} s" for i in k] == [t for t in _texts(fig)[:-1] if t.startswith("t =")]


def test_gradient_arrows_from_fields_and_from_pixels(stores, tmp_path):
    points, fields = stores
    a = _check_png(plot_gradient(points, tmp_path / "g1.png", fields=fields))
    b = _check_png(plot_gradient(points, tmp_path / "g2.png"))
    assert a.shape == b.shape and not np.array_equal(a, b)  # titles differ at least


def test_strain_figure_draws_directions(stores, tmp_path):
    points, fields = stores
    with_dirs = _check_png(plot_strain(fields, tmp_path / "s1.png", points=points, times=[2.0]))
    without = _check_png(plot_strain(fields.drop_vars("principal_direction"), tmp_path / "s2.png", points=points,
                                     times=[2.0]))
    # black segments: many more near-black pixels where directions are drawn
    dark = lambda img: (img.max(axis=2) < 0.15).mean()  # noqa: E731
    assert dark(with_dirs) > dark(without) + 0.002


def test_strain_needs_fields_and_3d_directions(stores, tmp_path):
    points, fields = stores
    with pytest.raises(DataError, match="needs fields.zarr"):
        plot_strain(None, tmp_path / "s.png", points=points)
    d2 = fields["principal_direction"].isel(component=slice(0, 2)).rename(component="basis").drop_vars("basis")
    with pytest.warns(IrdicWarning, match=r"2 components \(basis\), expected 3"):
        plot_strain(fields.assign(principal_direction=d2), tmp_path / "s.png", points=points)


def test_history_figure(stores, tmp_path, figures):
    points, fields = stores
    _check_png(plot_history(points, tmp_path / "h1.png", fields=fields), min_ink=0.08)
    _check_png(plot_history(points, tmp_path / "h2.png", point_ids=[1000, 1025, 1086]), min_ink=0.08)
    fig = figures[-1]
    assert fig._suptitle.get_text().endswith("temperature history at points 1000, 1025, 1086")
    ax_t = fig.axes[0]
    # one curve per point, with the point's own temperatures over time
    curves = {ln.get_label(): ln for ln in ax_t.get_lines() if ln.get_label().startswith("point ")}
    assert list(curves) == ["point 1000", "point 1025", "point 1086"]
    for pid, ln in curves.items():
        want = points.temperature.sel(point=int(pid.split()[1])).values
        np.testing.assert_array_equal(ln.get_xdata(), points.time.values)
        np.testing.assert_array_equal(ln.get_ydata(), want)
    assert ax_t.get_ylabel() == "temperature (°C)"


def test_experiment_figures_with_and_without_fields(stores, tmp_path):
    points, fields = stores
    done = plot_experiment(points, tmp_path / "a", fields=fields, experiment="fab")
    assert list(done) == list(FIGURES)
    for name, p in done.items():
        if name == "load":  # these stores have no signals: a note instead of empty axes
            _check_png(p, min_kb=3, min_ink=0.005)
            continue
        _check_png(p, min_ink=0.08 if name == "history" else 0.15)
    done = plot_experiment(points, tmp_path / "b")
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["gradient.png", "history.png", "rate.png",
                                                                  "temperature.png"]
    done = plot_experiment(points, {"temperature": tmp_path / "c" / "t.png"})
    assert list(done) == ["temperature"] and (tmp_path / "c" / "t.png").exists()


def test_points_without_temperature_are_drawn_grey(stores, tmp_path):
    points, _ = stores
    p = points.copy(deep=True)
    p["temperature"][:, : 9 * 7 // 2] = np.nan  # left half of the patch hidden at all times
    img = _check_png(plot_temperature(p, tmp_path / "t.png", times=[1.0]))
    grey = (np.abs(img - 0.82).max(axis=2) < 0.02).mean()
    assert grey > 0.05


def test_bad_arguments(stores, tmp_path):
    points, fields = stores
    with pytest.raises(ConfigError, match=r"times: 99 s outside the stored times 0 \.\. 2 s"):
        plot_temperature(points, tmp_path / "x.png", times=[99.0])
    with pytest.raises(ConfigError, match="point IDs 1, 2 not in the store"):
        plot_history(points, tmp_path / "x.png", point_ids=[1, 2])
    with pytest.raises(ConfigError, match="at most 8 points"):
        plot_history(points, tmp_path / "x.png", point_ids=[*range(1000, 1007), 1010, 1011])
    with pytest.raises(ConfigError, match="arrows must be an integer in 2 .. 200, got 0"):
        plot_gradient(points, tmp_path / "x.png", arrows=0)
    with pytest.raises(ConfigError, match="unknown figure.*'entropy'"):
        plot_experiment(points, tmp_path, names=["entropy"])
    with pytest.raises(DataError, match="needs heat.zarr"):  # the heat figure without the heat store
        plot_experiment(points, tmp_path, names=["heat"])
    with pytest.raises(DataError, match="nothing to draw"):
        plot_temperature(points.assign(x=points["x"] * np.nan), tmp_path / "x.png")
    assert not list(tmp_path.glob("*.png"))


def test_no_matplotlib_layout_warnings(stores, tmp_path):
    points, fields = stores
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_experiment(points, tmp_path, fields=fields, times=[0.0, 1.0, 2.0])


def _with_signals(fields, names=("Kraft", "Weg", "machine_torque"), units=("kN", "mm", "N*m"),
                  kinds=("analog_input", "value_element", "machine"), standard=("force", "displacement", "torque")):
    from irdic.io.signals import signal_coords

    t = fields["time"].values
    v = np.column_stack([10.0 * t, 0.1 * t, 3.0 * t])
    v[2, 0] = np.nan  # a stage without the force
    return fields.assign({"signal_value": (("time", "signal"), v)}).assign_coords(
        signal_coords(list(names), list(kinds), list(units), list(standard)))


def test_load_figure_against_force_displacement_and_torque(stores, tmp_path):
    from irdic.plot import load_signals

    points, fields = stores
    f = _with_signals(fields)
    # the standard name first, the record's own name in brackets: one language on the axes
    assert [lab for _, lab in load_signals(f)] == ["force (Kraft) [kN]", "displacement (Weg) [mm]",
                                                    "torque (machine_torque) [N*m]"]
    img = _check_png(plot_load(points, tmp_path / "load.png", fields=f, point_ids=[1000], experiment="fab"),
                     min_ink=0.08)
    assert img.shape[1] > 1000  # three columns of panels
    # the placeholder when there is nothing to plot against is a small picture, not an error
    small = _check_png(plot_load(points, tmp_path / "none.png", fields=fields), min_kb=3, min_ink=0.005)
    assert small.shape[1] < img.shape[1]


def test_load_figure_prefers_the_complete_signal(stores):
    from irdic.plot import load_signals

    _, fields = stores
    f = _with_signals(fields, names=("force", "machine_force", "cycles"), units=("N", "N", ""),
                      kinds=("value_element", "machine", "value_element"), standard=("force", "force", "cycles"))
    # the DIC force misses a stage, the machine's does not; cycles are no load axis
    assert [lab for _, lab in load_signals(f)] == ["force (machine_force) [N]"]


def test_noise_dominated_tells_a_smooth_field_from_noise():
    """Analytic: a linear field on a 20 x 20 grid is smooth; the same with noise of twice its range is not."""
    from irdic.plot.maps import noise_dominated

    g = np.arange(20.0)
    x = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    x = np.c_[x, np.zeros(len(x))]
    smooth = 0.01 * x[:, 0]  # range 0.19
    rng = np.random.default_rng(1)
    assert not noise_dominated(x, smooth)
    assert noise_dominated(x, smooth + rng.normal(0.0, 0.2, smooth.size))
    assert not noise_dominated(x, smooth + rng.normal(0.0, 0.005, smooth.size))
    assert not noise_dominated(x[:10], smooth[:10])  # too few points to judge


def test_resolved_fraction_against_zero():
    """Analytic: values 0, 1, 3, 5 with std 1: |v| > 2 std for 3 and 5; a zero std is exact, not judged."""
    from irdic.plot.uncertainty import resolved_fraction

    assert resolved_fraction([0.0, 1.0, -3.0, 5.0], [1.0, 1.0, 1.0, 1.0]) == 0.5
    assert resolved_fraction([0.0, 1.0, -3.0, 5.0, np.nan], [0.0, 1.0, 1.0, 1.0, 1.0]) == pytest.approx(2 / 3)
    assert np.isnan(resolved_fraction([0.0, 0.0], [0.0, 0.0]))  # the reference stage's strain


def _with_std(fields, name, std, bias=None):
    """``fields`` with ``<name>_std`` (and ``<name>_bias_dominated``) of the variable's shape."""
    da = fields[name]
    f = fields.assign({f"{name}_std": (da.dims, np.broadcast_to(std, da.shape).copy())})
    if bias is not None:
        f = f.assign({f"{name}_bias_dominated": (da.dims, np.broadcast_to(bias, da.shape).copy())})
    return f


@pytest.mark.parametrize("name, func", [("temperature_rate", plot_rate), ("max_principal_strain", plot_strain)])
def test_captions_say_when_a_map_is_noise_dominated_by_its_uncertainty(stores, tmp_path, name, func):
    """A std ten times the values' size makes the map noise-dominated; a std a hundredth of it does not."""
    from irdic.report import figure_caption

    points, fields = stores
    k = [int(np.argmin(np.abs(points.time.values - t))) for t in (1.0, 2.0)]
    size = float(np.nanmax(np.abs(fields[name].values[k])))
    assert size > 0

    def caption(f):
        if func is plot_rate:
            return figure_caption(plot_rate(points, tmp_path / "r.png", fields=f, times=[1.0, 2.0]))
        return figure_caption(plot_strain(f, tmp_path / "s.png", points=points, times=[1.0, 2.0]))

    noisy = caption(_with_std(fields, name, 10 * size))
    assert noisy.startswith("Noise-dominated at t = 1 s, 2 s: most values lie within 2 standard uncertainties of zero")
    assert f"fields.{name}_std" in noisy
    assert "0-0 % of the points per panel lie more than 2 std from zero" in noisy
    clean = caption(_with_std(fields, name, size / 100, bias=np.zeros(fields[name].shape, bool)))
    assert not clean.startswith("Noise-dominated") and "method's bias" not in clean
    assert f"median {size / 100 * (100 if name == 'max_principal_strain' else 1):.3g}" in clean
    flagged = np.zeros(fields[name].shape, bool)
    flagged[:, :7] = True  # 7 of the 63 points of each time
    clean = caption(_with_std(fields, name, size / 100, bias=flagged))
    assert "at 11 % of the points the method's bias" in clean


def test_temperature_caption_uses_the_noise_estimated_by_couple(stores, tmp_path):
    """points.zarr's IR noise x the interpolation's gain, against the map's 5-95 % range."""
    from irdic.report import figure_caption

    points, _ = stores
    k = [int(np.argmin(np.abs(points.time.values - t))) for t in (1.0, 2.0)]
    v = points.temperature.values[k]
    spread = np.nanpercentile(v[0], 95) - np.nanpercentile(v[0], 5)
    p = points.copy()
    p.attrs.update(ir_noise_k=0.05, ir_noise_gain_temperature=1.0)
    quiet = figure_caption(plot_temperature(p, tmp_path / "t.png", times=[1.0, 2.0]))
    assert "Standard uncertainty (the IR noise estimated by couple, through the interpolation): median 0.05 °C" in quiet
    assert not quiet.startswith("Noise-dominated")
    p.attrs.update(ir_noise_k=float(spread))  # std = the range: a pattern of noise
    assert figure_caption(plot_temperature(p, tmp_path / "t.png", times=[1.0, 2.0])).startswith(
        "Noise-dominated at t = 1 s")


def test_history_shades_the_rate_uncertainty(stores, tmp_path, figures):
    from irdic.report import figure_caption

    points, fields = stores
    f = _with_std(fields, "temperature_rate", 0.01)
    out = plot_history(points, tmp_path / "h.png", fields=f, point_ids=[1000])
    ax_r = figures[-1].axes[1]
    bands = [c for c in ax_r.collections if c.get_label() == "material rate ± 2 std"]
    assert len(bands) == 1
    ys = bands[0].get_paths()[0].vertices[:, 1]
    rate = fields.temperature_rate.sel(point=1000).values
    np.testing.assert_allclose([ys.min(), ys.max()], [np.nanmin(rate) - 0.02, np.nanmax(rate) + 0.02], atol=1e-12)
    assert "± 2 standard uncertainties" in figure_caption(out)
