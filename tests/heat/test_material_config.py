"""An experiment's material block: defaults, and clear errors naming the key."""

import copy
from pathlib import Path

import pytest
import yaml

from irdic.config import validate_config
from irdic.errors import ConfigError
from irdic.pipeline import stage_paths

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def cfg():
    with open(ROOT / "config" / "config.yaml") as fh:
        return yaml.safe_load(fh)


def test_demo_experiments_have_a_steel_material(cfg):
    out = validate_config(copy.deepcopy(cfg))
    for name in ("halfshell", "tube"):
        m = out["experiments"][name]["material"]
        assert (m["density"], m["specific_heat"], m["conductivity"]) == (7850, 470, 50)
        assert m["laplacian_smoothing"] == "auto" and m["laplacian_smoothing_time"] == "gcv" and m["cooling"] is None
    assert stage_paths(out)["experiments"]["tube"]["heat"].name == "heat.zarr"


@pytest.mark.parametrize("change, message", [
    ({"density": -1}, "experiments.tube.material.density"),
    ({"loss_time_constant": "often"}, "experiments.tube.material.loss_time_constant"),
    ({"loss_time_constant": "auto"}, "auto needs material.cooling"),
    ({"loss_time_constant": "auto", "cooling": [9, 8]}, "t1 > t0"),
    ({"conductivty": 50}, "conductivty"),
    ({"laplacian_smoothing": 0.5}, "experiments.tube.material.laplacian_smoothing"),
])
def test_bad_material_is_named(cfg, change, message):
    cfg["experiments"]["tube"]["material"].update(change)
    with pytest.raises(ConfigError, match=message.replace(".", r"\.")):
        validate_config(cfg)


def test_no_material_no_heat(cfg):
    del cfg["experiments"]["tube"]["material"]
    assert "heat" not in stage_paths(validate_config(cfg))["experiments"]["tube"]
