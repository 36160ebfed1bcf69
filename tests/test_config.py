import copy
import re
from pathlib import Path

import pytest
import yaml

from irdic.config import load_config, validate_config
from irdic.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def cfg():
    with open(ROOT / "config" / "config.yaml") as fh:
        return yaml.safe_load(fh)


def test_shipped_config_is_valid_and_defaults_are_filled(cfg):
    c = validate_config(cfg)
    assert c["results"] == "results"
    assert c["experiments"]["tube"]["ir"]["time_origin"] == "first"
    assert c["experiments"]["tube"]["dic"]["format"] == "auto"
    assert c["calibration"]["outlier_factor"] == 5.0
    assert c["demo"]["outdir"] == "resources/demo"


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda c: c["calibration"].update(polarty="dark"), r"calibration\.polarty: unknown key; allowed here: .*polarity"),
        (lambda c: c["calibration"].update(polarity="red"), r"calibration\.polarity: 'red' is not one of"),
        (lambda c: c["experiments"]["tube"].update(setup="other"), r"experiments\.tube\.setup: setup 'other' is not defined"),
        (lambda c: c["experiments"]["tube"]["ir"].update(frame_rate=-2), r"experiments\.tube\.ir\.frame_rate"),
        (lambda c: c["experiments"]["tube"]["ir"].update(time_source="frame_rate"), r"frame_rate: required"),
        (lambda c: c["experiments"]["tube"].pop("dic"), r"experiments\.tube: 'dic' is a required property"),
        (lambda c: c["setups"]["lab"].update(seeds={1: [1, 2], 2: [3, 4]}), r"setups\.lab\.seeds: give at least 6"),
        (lambda c: c["experiments"]["tube"]["dic"].update(format="table"), r"dic\.columns: format table needs"),
        (lambda c: c.update(experimnts={}), r"experimnts: unknown key"),
    ],
)
def test_bad_config_names_the_key(cfg, edit, message):
    edit(cfg)
    with pytest.raises(ConfigError, match=message):
        validate_config(cfg)


def test_load_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ConfigError, match="empty"):
        load_config(tmp_path / "empty.yaml")
    (tmp_path / "bad.yaml").write_text("a: [1,\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(tmp_path / "bad.yaml")


@pytest.mark.parametrize("section", ["setups", "experiments"])
@pytest.mark.parametrize("name", ["../../x", "/tmp/x", "a/b", ".hidden", "..", "", "tab\\there", "x y"])
def test_names_that_would_escape_results_are_refused(cfg, section, name):
    if section == "setups":
        cfg["setups"][name] = cfg["setups"].pop("lab")
        for e in cfg["experiments"].values():
            e["setup"] = name
    else:
        cfg["experiments"][name] = cfg["experiments"].pop("tube")
    with pytest.raises(ConfigError, match=rf"{section}: name {re.escape(repr(name))} is not allowed; {section} names "
                                          r"become folder names under the results folder"):
        validate_config(cfg)


@pytest.mark.parametrize("name", ["tube", "Tube_2-b", "run.3", "-x", "42"])
def test_plain_names_are_accepted(cfg, name):
    cfg["experiments"][name] = cfg["experiments"].pop("tube")
    assert name in validate_config(cfg)["experiments"]


def test_stage_paths_stay_inside_results(cfg, tmp_path):
    from irdic.pipeline import stage_paths

    c = validate_config(cfg)
    c["results"] = str(tmp_path / "results")
    paths = stage_paths(c)
    assert paths["experiments"]["tube"]["ir"] == tmp_path / "results" / "tube" / "ir.zarr"
    # a configuration that skipped validation (Python API) is still caught where paths are made
    c["experiments"]["../../x"] = c["experiments"].pop("tube")
    with pytest.raises(ConfigError, match=r"experiments\.\.\./\.\./x: output .* would lie outside the results folder"):
        stage_paths(c)
    c["experiments"] = {"tube": c["experiments"].pop("../../x")}
    (tmp_path / "results").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "results" / "tube").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(ConfigError, match=r"experiments\.tube: output .* would lie outside the results folder"):
        stage_paths(c)
