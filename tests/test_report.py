"""The HTML page of a run: exactly its figures, in pipeline order, with a header of what was run."""

import json

import numpy as np
import pytest
import xarray as xr
from PIL import Image, PngImagePlugin

from irdic.config import METHOD_SECTIONS, non_defaults, validate_section
from irdic.report import auto_choices, order_figures
from irdic.stages import report
from irdic.store import write_dataset


def _config(**given):
    """The method's sections with the schema's defaults and ``given`` on top (no setups needed)."""
    return {s: validate_section(s, given.get(s, {})) for s in METHOD_SECTIONS}


def _png(path, caption=None):
    path.parent.mkdir(parents=True, exist_ok=True)
    info = PngImagePlugin.PngInfo()
    if caption:
        info.add_text("Description", caption)
    Image.new("RGB", (4, 4)).save(path, pnginfo=info)
    return path


@pytest.fixture
def results(tmp_path):
    r = tmp_path / "results"
    _png(r / "setups" / "lab" / "calibration.png", "IR image of the reference object")
    _png(r / "setups" / "old" / "calibration.png", "another setup's")
    for exp in ("tube", "halfshell", "s99"):
        for name in ("load", "history", "strain", "rate", "gradient", "temperature"):
            _png(r / exp / "figures" / f"{name}.png", f"{name} of experiment {exp}")
    return r


def test_the_page_shows_exactly_the_given_run_in_pipeline_order(results, tmp_path):
    figures = [results / "setups/lab/calibration.png"]
    for exp in ("tube", "halfshell"):  # the configuration's experiments, in its order
        figures += sorted((results / exp / "figures").glob("*.png"))  # alphabetical on purpose
    cfg = _config(fields={"c_space": 0.5})
    report.run({"figures": figures}, {"html": tmp_path / "page.html"}, title="config/lab.yaml",
               settings=non_defaults(cfg))
    page = (tmp_path / "page.html").read_text(encoding="utf-8")
    assert "<h1>irdic results of config/lab.yaml</h1>" in page and "<title>irdic: config/lab.yaml</title>" in page
    assert "s99" not in page and "setup old" not in page and "another setup" not in page  # other runs' figures
    heads = [line for line in page.splitlines() if line.startswith("<h2 id=")]
    assert [h.split(">")[1].split("<")[0] for h in heads] == ["setup lab", "experiment tube", "experiment halfshell"]
    order = [page.index(f"{n} of experiment tube") for n in ("temperature", "gradient", "rate", "strain",
                                                             "history", "load")]
    assert order == sorted(order)
    assert page.index("experiment tube</a>") < page.index("<h2 id=")  # the table of contents comes first
    assert "<b>calibration</b>: IR image of the reference object" in page
    assert "<code>fields.c_space: 0.5</code>" in page and "irdic</th>" in page and "UTC" in page


def test_without_a_list_the_page_shows_the_whole_folder(results, tmp_path):
    report.run({"results": results}, {"html": tmp_path / "all.html"})
    page = (tmp_path / "all.html").read_text(encoding="utf-8")
    assert "experiment s99" in page and "setup old" in page
    assert page.index("setup old") < page.index("experiment halfshell")


def test_order_figures_puts_setups_first_and_keeps_the_experiments_order(results):
    figs = [results / "tube/figures/load.png", results / "halfshell/figures/rate.png",
            results / "setups/lab/calibration.png", results / "tube/figures/temperature.png"]
    got = [(sec, p.stem) for sec, p in order_figures(figs)]
    assert got == [("setup lab", "calibration"), ("experiment tube", "temperature"), ("experiment tube", "load"),
                   ("experiment halfshell", "rate")]


def test_non_defaults_and_auto_choices(tmp_path):
    cfg = _config(fields={"temperature_smoothing": None}, calibration={"polarity": "dark"},
                  execution={"chunk_frames": 8})
    assert non_defaults(cfg) == {"calibration.polarity": "dark", "execution.chunk_frames": 8,
                                 "fields.temperature_smoothing": None}
    assert non_defaults(_config()) == {}
    ds = xr.Dataset({"a": ("x", np.zeros(2), {"units": "K", "long_name": "a"})},
                    attrs={"temperature_smoothing_chosen": "4.0", "temperature_smoothing_reason": "IR noise 0.05 K",
                           "parametrisation": "cylinder", "surface_solver": "local"})
    write_dataset(ds, tmp_path / "tube" / "fields.zarr", stage="fields",
                  params={"temperature_smoothing": "auto", "parametrisation": "auto", "solver": "auto", "c_time": 1})
    cal = xr.Dataset({"a": ("x", np.zeros(2), {"units": "K", "long_name": "a"})},
                     attrs={"settings": json.dumps({"polarity": "dark"})})
    write_dataset(cal, tmp_path / "lab" / "calibration.zarr", stage="calibrate", params={"polarity": "auto"})
    lines = auto_choices([tmp_path / "lab" / "calibration.zarr", tmp_path / "tube" / "fields.zarr",
                          tmp_path / "missing.zarr"])
    assert lines == ["lab/calibration.zarr: polarity auto \u2192 dark",
                     "tube/fields.zarr: parametrisation auto \u2192 cylinder",
                     "tube/fields.zarr: solver auto \u2192 local",
                     "tube/fields.zarr: temperature_smoothing auto \u2192 4.0 (IR noise 0.05 K)"]


def test_auto_choices_say_the_spacings_the_regressions_used(tmp_path):
    """Where ``auto`` chose a regression, the line says its centre spacings (the fields store records them), so that
    a series can be re-processed with them fixed; a regression that is off has none."""
    ds = xr.Dataset({"a": ("x", np.zeros(2), {"units": "K", "long_name": "a"})},
                    attrs={"temperature_smoothing_chosen": "gcv", "temperature_smoothing_space_chosen": "gcv",
                           "surface_smoothing_chosen": "None", "temperature_smoothing_spacing": 3.0,
                           "temperature_smoothing_rate_spacing": 2.0, "temperature_smoothing_value_spacing": 3.0,
                           "temperature_smoothing_space_spacing": 12.000000000000002,
                           "surface_smoothing_spacing": None})
    write_dataset(ds, tmp_path / "tube" / "fields.zarr", stage="fields",
                  params={"temperature_smoothing": "auto", "temperature_smoothing_space": "auto",
                          "surface_smoothing": "auto"})
    assert auto_choices([tmp_path / "tube" / "fields.zarr"]) == [
        "tube/fields.zarr: surface_smoothing auto \u2192 null",
        "tube/fields.zarr: temperature_smoothing auto \u2192 gcv, centres every 3 DIC stages (rate 2, value 3)",
        "tube/fields.zarr: temperature_smoothing_space auto \u2192 gcv, centres every 12 point spacings"]
