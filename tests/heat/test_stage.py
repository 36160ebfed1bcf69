"""The heat stage entry on the tiny synthetic tube: heat.zarr's content, attributes and errors."""

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError
from irdic.stages import heat
from irdic.coupling import couple
from irdic.fields import fields
from irdic.store import open_store, write_dataset
from irdic.synthetic.laplacian import temperature_laplacian
from irdic.synthetic.specimens import Tube

from .._synthetic_stores import synthetic_inputs

STEEL = dict(density=7850.0, specific_heat=470.0, conductivity=50.0)


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    work = tmp_path_factory.mktemp("heat")
    dic, ir, cal, truth = synthetic_inputs("tube", "tiny")
    pts = couple(dic, ir, cal)
    write_dataset(pts, work / "points.zarr", stage="couple")
    write_dataset(fields(pts, cal), work / "fields.zarr", stage="fields")
    return work, truth.sel(point=pts.point)


def test_heat_store_against_the_closed_form(stores):
    work, truth = stores
    heat.run({"fields": work / "fields.zarr", "points": work / "points.zarr"}, {"store": work / "heat.zarr"},
             loss_time_constant=60.0, **STEEL)
    h = open_store(work / "heat.zarr")
    for name in ("heat_source", "temperature_laplacian", "heat_storage", "heat_losses", "heat_conduction"):
        assert h[name].dims == ("time", "point") and h[name].attrs["units"]
        assert h[f"{name}_std"].attrs["units"] == h[name].attrs["units"]
        assert h[f"{name}_bias_dominated"].dtype == bool
    assert h.temperature_laplacian.attrs["units"] == "K/mm2" and h.heat_source.attrs["units"] == "W/m3"
    np.testing.assert_allclose(h.heat_source, h.heat_storage + h.heat_losses - h.heat_conduction, rtol=1e-12)
    assert h.attrs["material_density"] == 7850.0 and h.attrs["loss_time_constant_s"] == 60.0
    assert "by the Laplacian's estimated risk" in h.attrs["laplacian_spacing_chosen"]
    # the truth: the synthetic tube's closed-form rate and Laplacian on the stretched and twisted surface
    tt = truth.time.values[:, None]
    lap = temperature_laplacian(Tube(), truth.s.values[None], truth.h.values[None], tt)
    rc = 7850.0 * 470.0
    src = rc * (truth.temperature_rate.values + (truth.temperature.values - truth.temperature.values[0]) / 60.0) \
        - 50e6 * lap
    inner = np.isfinite(h.heat_source.values) & (truth.patch_edge_distance.values >= 2.0)
    inner[[0, -1]] = False
    err = (h.heat_source.values - src)[inner]
    # tiny scene (2 mm point spacing, 7 DIC times, noise-free): the rate's interpolation limits the source
    assert np.sqrt(np.mean(err ** 2)) < 0.05 * np.abs(src[inner]).max()


def test_auto_tau_needs_a_cooling_window(stores):
    work, _ = stores
    with pytest.raises(ConfigError, match="material.cooling"):
        heat.run({"fields": work / "fields.zarr", "points": work / "points.zarr"}, {"store": work / "h2.zarr"},
                 loss_time_constant="auto", **STEEL)
    assert not (work / "h2.zarr").exists()


def test_wrong_inputs_are_named(stores):
    work, _ = stores
    with pytest.raises(DataError, match="fields store lacks"):
        heat.run({"fields": work / "points.zarr", "points": work / "points.zarr"}, {"store": work / "h3.zarr"},
                 loss_time_constant=None, **STEEL)
    with pytest.raises(ConfigError, match="material: unknown parameter"):
        heat.run({"fields": work / "fields.zarr", "points": work / "points.zarr"}, {"store": work / "h4.zarr"},
                 loss_time_constant=None, densty=1.0, **STEEL)


def test_cli_heat(stores, capsys):
    from irdic.cli import main

    work, _ = stores
    args = ["heat", "--fields", str(work / "fields.zarr"), "--points", str(work / "points.zarr"),
            "--density", "7850", "--specific-heat", "470", "--conductivity", "50"]
    assert main(args + ["--out", str(work / "cli.zarr"), "--loss-time-constant", "none",
                        "--set", "material.reference_temperature=22.5"]) == 0
    h = open_store(work / "cli.zarr")
    assert h.attrs["material_reference_temperature"] == 22.5 and np.all(h.heat_losses.values == 0)
    assert main(args + ["--out", str(work / "cli2.zarr"), "--loss-time-constant", "auto"]) == 2
    assert "material.cooling" in capsys.readouterr().err


def test_figure_and_export_carry_the_source(stores):
    from irdic.report import figure_caption
    from irdic.stages import export, figures

    work, _ = stores
    if not (work / "heat.zarr").exists():
        heat.run({"fields": work / "fields.zarr", "points": work / "points.zarr"}, {"store": work / "heat.zarr"},
                 loss_time_constant=60.0, **STEEL)
    inputs = {"points": work / "points.zarr", "fields": work / "fields.zarr", "heat": work / "heat.zarr"}
    png = work / "figs" / "heat.png"
    figures.run(inputs, {"heat": png}, experiment="tube", times=[], points=[])
    assert png.stat().st_size > 10_000
    caption = figure_caption(png)
    assert "Heat source" in caption and "MW/m³" in caption and "against" in caption
    export.run(inputs, {"paraview": work / "pv", "csv": work / "points.csv"}, experiment="tube", points=[])
    header = (work / "points.csv").read_text().splitlines()[0]
    assert "heat_source [W/m3]" in header and "temperature_laplacian_std [K/mm2]" in header
    assert "heat_source" in (work / "pv" / sorted(p.name for p in (work / "pv").glob("*.vtu"))[0]).read_text()
