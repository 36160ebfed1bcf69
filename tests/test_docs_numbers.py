"""The demo figures quoted in README.md and docs/ against a demo run's stores.

One slow test: the bundled demo (``config/config.yaml``, scale ``demo``)
runs through :func:`irdic.pipeline.run` up to the fields stage in a
temporary folder, then every number the documentation quotes about it is
read from the text and compared with the stores: marker counts, the
calibration RMS, which experiment drops an IR frame, the record sizes and the
accuracy table of docs/method.md. ``IRDIC_DEMO_WORKDIR`` points the test at
the working folder of a finished demo run instead (``resources/demo`` and
``results`` in it), to check the text without running the demo again.
"""

import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from irdic.store import open_store

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ("halfshell", "tube")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    given = os.environ.get("IRDIC_DEMO_WORKDIR")
    if given:
        return Path(given)
    from irdic.config import validate_config
    from irdic.pipeline import run

    work = tmp_path_factory.mktemp("demo_docs")
    with open(ROOT / "config" / "config.yaml", encoding="utf-8") as fh:
        cfg = yaml.safe_load(fh)
    cwd = os.getcwd()
    os.chdir(work)
    try:
        run(validate_config(cfg), stages=("demo", "ingest", "calibrate", "couple", "fields"))
    finally:
        os.chdir(cwd)
    return work


def _text(name: str) -> str:
    return " ".join((ROOT / name).read_text(encoding="utf-8").split())  # line breaks as spaces


def _close(doc: str, value: float) -> bool:
    """``value`` rounds to the figure ``doc`` as written (its last digit, half a unit either way)."""
    mantissa = doc.lower().split("e")[0]
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    exponent = int(doc.lower().split("e")[1]) if "e" in doc.lower() else 0
    return abs(float(doc) - value) <= 0.5 * 10.0 ** (exponent - decimals) * (1 + 1e-9)


def accuracy(work: Path, name: str) -> dict:
    """RMS errors against the truth as docs/method.md section 5 defines them."""
    truth = open_store(work / "resources" / "demo" / name / "truth.zarr")
    pts = open_store(work / "results" / name / "points.zarr")
    f = open_store(work / "results" / name / "fields.zarr")
    truth = truth.sel(point=f.point)
    ok = pts.status.values == 0
    inner = ok & (truth.patch_edge_distance.values > 2.0)

    def rms(a, mask):
        return float(np.sqrt(np.nanmean(a[mask] ** 2)))

    grad = np.linalg.norm((f.temperature_gradient - truth.temperature_gradient).values, axis=-1)
    return {"temperature": rms(f.temperature.values - truth.temperature.values, ok),
            "in-plane gradient": rms(grad, inner),
            "material rate": rms(f.temperature_rate.values - truth.temperature_rate.values, inner),
            "max. principal strain": rms(f.max_principal_strain.values - truth.strain_max.values, inner)}


def test_the_documented_demo_figures_are_the_demos(demo_run):
    work = demo_run
    cal = open_store(work / "results" / "setups" / "lab" / "calibration.zarr")
    used, total, rms_px = int(cal.attrs["n_used"]), int(cal.attrs["n_markers"]), float(cal["rms_px"])
    # markers and calibration RMS (docs/calibration-target.md, docs/method.md, docs/performance.md)
    target = _text("docs/calibration-target.md")
    assert int(re.search(r"one corner left unpainted so that the open book is not symmetric: (\d+) markers",
                         target)[1]) == total
    m = re.search(r"The demo reports `(\d+) of (\d+) markers used, RMS ([\d.]+) px`", target)
    assert (int(m[1]), int(m[2])) == (used, total) and _close(m[3], rms_px), (m.groups(), used, total, rms_px)
    m = re.search(r"The calibration of the demo uses (\d+) of (\d+) markers at ([\d.]+) px RMS", _text("docs/method.md"))
    assert (int(m[1]), int(m[2])) == (used, total) and _close(m[3], rms_px)
    perf = _text("docs/performance.md")
    assert int(re.search(r"one calibration \((\d+) markers\)", perf)[1]) == total
    # which experiment drops an IR frame (README.md)
    gaps = {}
    for name in EXPERIMENTS:
        t = open_store(work / "results" / name / "ir.zarr").time.values
        dt = np.diff(t)
        gaps[name] = int((dt > 1.5 * np.median(dt)).sum())
    m = re.search(r"The demo drops one IR frame of the (\w+) on purpose", _text("README.md"))
    assert {k for k, v in gaps.items() if v} == {m[1].replace("half-shell", "halfshell")} and gaps[m[1]] == 1
    # record sizes (docs/performance.md)
    for label, name in (("half-shell has", "halfshell"), ("tube", "tube")):
        m = re.search(label + r" (\d+) (?:IR )?frames of (\d+) × (\d+) px and ([\d,]+) points × (\d+) stages", perf)
        ir = open_store(work / "results" / name / "ir.zarr")
        dic = open_store(work / "results" / name / "dic.zarr")
        assert (int(m[1]), int(m[2]), int(m[3])) == (ir.sizes["time"], ir.sizes["u"], ir.sizes["v"]), name
        assert (int(m[4].replace(",", "")), int(m[5])) == (dic.sizes["point"], dic.sizes["time"]), name
    # the accuracy table (docs/method.md, section 5)
    method = (ROOT / "docs" / "method.md").read_text(encoding="utf-8")
    section = method.split("## 5. Accuracy", 1)[1].split("\n## ", 1)[0]
    rows = {r[0]: r[1:] for r in (re.findall(r"^\| ([^|]+?) \| ([-\d.e]+)[^|]*\| ([-\d.e]+)[^|]*\|$", section, re.M))}
    measured = {name: accuracy(work, name) for name in EXPERIMENTS}
    assert set(rows) == set(measured["tube"]), rows
    for quantity, docs in rows.items():
        for doc, name in zip(docs, EXPERIMENTS):
            assert _close(doc, measured[name][quantity]), (quantity, name, doc, measured[name][quantity])
