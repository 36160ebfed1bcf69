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


# --- data safety: alias bombs, long messages, fuzzing -------------------------

import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irdic.config import MAX_REPR

_LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{chr(ord('a') + i)}: &{chr(ord('a') + i)} [" + ", ".join([f"*{chr(ord('a') + i - 1)}"] * 9) + "]\n"
    for i in range(1, 9)
)


def test_alias_bomb_is_refused_quickly_naming_file_and_line(tmp_path):
    p = tmp_path / "laughs.yaml"
    p.write_text(_LAUGHS)
    assert len(_LAUGHS) < 1000
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"laughs\.yaml, line \d+: alias \*\w expands?|laughs\.yaml, line \d+: alias") as exc:
        load_config(p)
    assert time.perf_counter() - t0 < 2.0
    assert "write the repeated values out" in str(exc.value)
    assert len(str(exc.value)) < 400


def test_recursive_alias_is_refused(tmp_path):
    p = tmp_path / "rec.yaml"
    p.write_text("a: &x [1, *x]\n")
    with pytest.raises(ConfigError, match=r"rec\.yaml, line 1: alias \*x refers to a value that contains it"):
        load_config(p)


def test_modest_aliases_still_work(tmp_path):
    text = (ROOT / "config" / "config.yaml").read_text()
    cfg = yaml.safe_load(text)
    cfg["setups"]["lab2"] = cfg["setups"]["lab"]  # dumped as an anchor + alias
    p = tmp_path / "alias.yaml"
    p.write_text(yaml.safe_dump(cfg))
    assert "*id" in p.read_text()
    c = load_config(p)
    assert c["setups"]["lab2"] == c["setups"]["lab"]


def test_huge_value_is_quoted_short(tmp_path, cfg):
    cfg["calibration"]["polarity"] = "x" * 100_000
    cfg["results"] = list(range(100_000))
    p = tmp_path / "big.yaml"
    p.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert "more characters" in msg
    assert len(msg) < 5 * (MAX_REPR + 200)


def test_undecodable_file_is_a_config_error(tmp_path):
    p = tmp_path / "latin.yaml"
    p.write_bytes(b"results: r\xe9sultats\n")
    with pytest.raises(ConfigError, match=r"latin\.yaml: not a UTF-8 text file"):
        load_config(p)


_SHIPPED = (ROOT / "config" / "config.yaml").read_bytes()
_YAMLISH = st.sampled_from(
    [b"&a ", b"*a", b"[", b"]", b"{", b"}", b": ", b"- ", b"\n", b"  ", b"!!python/object ", b"<<: *a\n",
     b"\xff", b"~", b"1e999", b".inf", b"2020-01-01", b"'", b'"', b"#", b"? ", b"|\n", b"%YAML 1.1\n", b"---\n"]
)


@st.composite
def _edited_config(draw):
    data = bytearray(_SHIPPED)
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(data)))
        cut = draw(st.integers(0, 20))
        ins = draw(st.one_of(_YAMLISH, st.binary(max_size=8)))
        data[pos : pos + cut] = ins
    return bytes(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(_edited_config(), st.binary(max_size=200)))
def test_fuzzed_config_is_valid_or_config_error(tmp_path, data):
    p = tmp_path / "fuzz.yaml"
    p.write_bytes(data)
    try:
        cfg = load_config(p)
    except ConfigError as exc:
        assert len(str(exc)) < 3000
    else:
        assert isinstance(cfg, dict)


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


def test_command_line_strings_become_the_numbers_the_schema_wants():
    """Snakemake's --config gives nested values as strings: typed where the schema wants a number, bool or null."""
    from irdic.config import command_line_values

    given = {"execution": {"chunk_frames": "8"}, "interpolation": {"c_space": "2.5", "method": "rbf"},
             "fields": {"temperature_smoothing": "null", "c_time": "nan"}, "calibration": {"refine": "false"},
             "experiments": {"s07": {"ir": {"time_offset": "-0.25", "path": "123"}}}}
    cfg = {"setups": {}, "execution": {"chunk_frames": "8"},
           "interpolation": {"c_space": "2.5", "method": "rbf"},
           "fields": {"temperature_smoothing": "null", "c_time": "nan"}, "calibration": {"refine": "false"},
           "experiments": {"s07": {"setup": "lab", "ir": {"time_offset": "-0.25", "path": "123"}}}}
    command_line_values(cfg, given)
    assert cfg["execution"]["chunk_frames"] == 8 and isinstance(cfg["execution"]["chunk_frames"], int)
    assert cfg["interpolation"] == {"c_space": 2.5, "method": "rbf"}
    assert cfg["fields"]["temperature_smoothing"] is None
    assert cfg["fields"]["c_time"] == "nan"  # not a silent NaN: the schema refuses the string
    assert cfg["calibration"]["refine"] is False
    assert cfg["experiments"]["s07"]["ir"] == {"time_offset": -0.25, "path": "123"}  # a path stays a string
    # values from files are not touched (only those given on the command line)
    other = {"execution": {"chunk_frames": "8"}}
    command_line_values(other, {})
    assert other["execution"]["chunk_frames"] == "8"
    # a string that is no number still gets the schema's message
    bad = {"execution": {"chunk_frames": "eight"}}
    command_line_values(bad, {"execution": {"chunk_frames": "eight"}})
    assert bad["execution"]["chunk_frames"] == "eight"


# --- assumptions about the values: no key twice, no NaN, folders apart -------


def test_experiment_given_twice_names_both_lines(tmp_path):
    text = (ROOT / "config" / "config.yaml").read_text()
    copied = text.replace("experiments:\n", "experiments:\n  tube:\n    setup: lab\n"
                          "    dic: {path: resources/demo/tube/dic}\n    ir: {path: resources/demo/tube/ir}\n", 1)
    (tmp_path / "c.yaml").write_text(copied)
    lines = [i + 1 for i, line in enumerate(copied.splitlines()) if line.startswith("  tube:")]
    first, second = lines
    with pytest.raises(ConfigError, match=rf"c\.yaml, line {second}: key 'tube' is given twice in the same "
                                          rf"mapping \(first at line {first}\)"):
        load_config(tmp_path / "c.yaml")


@pytest.mark.parametrize("seeds, message", [
    ("{1: [1, 2], 2: [3, 4], 3: [5, 6], 4: [7, 8], 5: [9, 10], 1: [11, 12]}",
     r"line 1: key 1 is given twice in the same mapping \(first at line 1\)"),
    ("{1: [1, 2], 2: [3, 4], 3: [5, 6], 4: [7, 8], 5: [9, 10], '1': [11, 12]}",
     r"setups\.lab\.seeds: marker ID 1 is given twice \(1 and '1'\)"),
])
def test_marker_seed_given_twice_is_refused(tmp_path, seeds, message):
    (tmp_path / "s.yaml").write_text(f"seeds: {seeds}\n")
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    with pytest.raises(ConfigError, match=message):
        from irdic.config import load_yaml
        cfg["setups"]["lab"]["seeds"] = load_yaml(tmp_path / "s.yaml")["seeds"]
        validate_config(cfg)


def test_merge_keys_may_be_overridden(tmp_path):
    (tmp_path / "m.yaml").write_text("base: &b {c_space: 2.0, c_time: 1.0}\nother: {<<: *b, c_time: 3.0}\n")
    from irdic.config import load_yaml

    assert load_yaml(tmp_path / "m.yaml")["other"] == {"c_space": 2.0, "c_time": 3.0}


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf"])
def test_time_offset_nan_names_the_key(tmp_path, value):
    text = (ROOT / "config" / "config.yaml").read_text().replace(
        "    ir: {path: resources/demo/tube/ir}", f"    ir: {{path: resources/demo/tube/ir, time_offset: {value}}}")
    (tmp_path / "c.yaml").write_text(text)
    with pytest.raises(ConfigError, match=r"experiments\.tube\.ir\.time_offset: -?(nan|inf) is not a finite number"):
        load_config(tmp_path / "c.yaml")


@pytest.mark.parametrize("edit, key", [
    (lambda c: c["interpolation"].update(c_space=float("nan")), "interpolation.c_space"),
    (lambda c: c["fields"].update(temperature_smoothing=float("inf")), "fields.temperature_smoothing"),
    (lambda c: c["setups"]["lab"].update(seeds={i: [1.0 * i, float("nan") if i == 3 else 2.0] for i in range(6)}),
     "setups.lab.seeds.3.1"),
    (lambda c: c["experiments"]["tube"]["machine"].update(time_offset=float("nan")),
     "experiments.tube.machine.time_offset"),
])
def test_non_finite_numbers_anywhere_name_the_key(cfg, edit, key):
    edit(cfg)
    with pytest.raises(ConfigError, match=re.escape(key) + r": -?(nan|inf) is not a finite number"):
        validate_config(cfg)


def test_stage_parameters_refuse_nan():
    from irdic.parameters import settings

    with pytest.raises(ConfigError, match=r"interpolation\.c_time: nan is not a finite number"):
        settings("interpolation", {"c_time": float("nan")})


def test_results_inside_a_raw_data_folder_is_refused(cfg, tmp_path):
    raw = tmp_path / "raw" / "ir"
    raw.mkdir(parents=True)
    cfg["demo"]["enabled"] = False
    cfg["experiments"]["tube"]["ir"]["path"] = str(raw)
    cfg["results"] = str(raw / "results")
    with pytest.raises(ConfigError, match=r"experiments\.tube\.ir\.path: the input .* contains the results folder"):
        validate_config(cfg)


@pytest.mark.parametrize("pattern", ["{results}/raw", "{results}/raw/*.csv", "{results}"])
def test_raw_data_inside_results_is_refused(cfg, tmp_path, pattern):
    results = tmp_path / "res"
    cfg["demo"]["enabled"] = False
    cfg["results"] = str(results)
    cfg["experiments"]["halfshell"]["dic"]["path"] = pattern.format(results=results)
    with pytest.raises(ConfigError, match=r"experiments\.halfshell\.dic\.path: the input .* (lies inside|contains) "
                                          r"the results folder"):
        validate_config(cfg)


def test_results_in_demo_folder_is_refused(cfg):
    cfg["results"] = "resources/demo/results"
    with pytest.raises(ConfigError, match=r"results: the results folder resources/demo/results .* and demo\.outdir "
                                          r"resources/demo .* overlap"):
        validate_config(cfg)


def test_results_beside_one_input_file_is_accepted(cfg, tmp_path):
    cfg["results"] = str(tmp_path / "results")
    cfg["experiments"]["tube"]["machine"]["path"] = str(tmp_path / "machine.csv")
    validate_config(cfg)
