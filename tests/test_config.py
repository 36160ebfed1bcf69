import copy
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
