"""The testing machine's signals in nodemap headers (``# SIGNALS:``) and through ingest."""

import warnings

import numpy as np
import pytest

from irdic.errors import DataError, FormatError, IrdicWarning
from irdic.ingest.dic import ingest_dic
from irdic.io.nodemap import read_nodemap
from irdic.synthetic.writers import write_nodemap
from irdic.io.signals import parse_signals, standard_name
from irdic.store import open_store

HEADER = """# stage data:
# current_stage_index           : 3
# current_stage_relative_date   : 1.5
####################################################################################################
# SIGNALS:
# force                         : value_element       : 14985.6119156
# displacement                  : value_element       : -9.17953395844
# cycles                        : value_element       : 888983.0
# time                          : value_element       : 98166.9076195
#
# Kraft [kN]                    : analog_input        : 15,1025390625
# Verschiebung                  : analog_input        : nan
# Drehmoment                    : analog_input        : 12.5 N*m
####################################################################################################
""".splitlines()


def test_english_german_units_kinds_and_standard_names():
    sig = {s.name: s for s in parse_signals(HEADER, "f.txt")}
    assert list(sig) == ["force", "displacement", "cycles", "time", "Kraft", "Verschiebung", "Drehmoment"]
    assert sig["force"].value == 14985.6119156 and sig["force"].kind == "value_element" and sig["force"].unit == ""
    assert sig["Kraft"].value == 15.1025390625 and sig["Kraft"].unit == "kN" and sig["Kraft"].kind == "analog_input"
    assert np.isnan(sig["Verschiebung"].value)
    assert (sig["Drehmoment"].value, sig["Drehmoment"].unit) == (12.5, "N*m")
    assert sig["time"].line == 9
    assert [standard_name(n) for n in sig] == ["force", "displacement", "cycles", "time", "force", "displacement",
                                               "torque"]
    assert standard_name("Winkel_2") == "angle" and standard_name("Temperatur") == ""


def test_no_section_gives_no_signals():
    assert parse_signals(HEADER[:4], "f.txt") == []


def test_same_name_twice_with_another_kind_is_kept_apart():
    lines = ["# SIGNALS:", "# force : value_element : 1.0", "# force : analog_input : 2.0"]
    assert [(s.name, s.value) for s in parse_signals(lines, "f.txt")] == [("force", 1.0), ("force_analog_input", 2.0)]
    with pytest.raises(FormatError, match=r"f.txt, line 3: signal 'force' \(value_element\) appears twice"):
        parse_signals(lines[:2] + ["# force : value_element : 3.0"], "f.txt")


def test_text_value_warns_and_is_left_out():
    lines = ["# SIGNALS:", "# status : value_element : 1.2.3", "# force : value_element : 1.0"]
    with pytest.warns(IrdicWarning, match=r"f.txt, line 2: signal 'status' has the value '1.2.3'"):
        sig = parse_signals(lines, "f.txt")
    assert [s.name for s in sig] == ["force"]


def _stage(tmp_path, k, signals):
    ids = np.arange(1, 5)
    xu = np.column_stack([ids, ids * 2.0, np.zeros(4)]).astype(float)
    return write_nodemap(tmp_path / "dic" / f"s_0_{k}.txt", ids, xu, np.full((4, 3), 0.01 * k), stage_index=k,
                         relative_time=0.5 * k, signals=signals)


def test_writer_round_trip_and_the_stage_time_is_not_a_signal(tmp_path):
    (tmp_path / "dic").mkdir()
    p = _stage(tmp_path, 2, [("force [N]", "value_element", 0.1 + 0.2), ("relative_time", "value_element", 99.0)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = read_nodemap(p)
    assert float(ds.time) == 1.0  # a signal called relative_time does not replace the stage time
    assert list(ds.signal.values) == ["force", "relative_time"]
    assert ds.signal_value.values[0] == 0.1 + 0.2  # repr: exact
    assert list(ds.signal_unit.values) == ["N", ""] and list(ds.signal_standard_name.values) == ["force", ""]


def test_ingest_stores_signals_over_time_with_nan_where_missing(tmp_path):
    (tmp_path / "dic").mkdir()
    for k in range(3):
        sig = [("force [N]", "value_element", 10.0 * k), ("Kraft [kN]", "analog_input", 0.01 * k)]
        _stage(tmp_path, k, sig[1:] if k == 1 else sig)
    ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr")
    ds = open_store(tmp_path / "dic.zarr")
    assert ds.signal_value.dims == ("time", "signal")
    assert list(ds.signal.values) == ["force", "Kraft"]
    assert list(ds.signal_kind.values) == ["value_element", "analog_input"]
    assert list(ds.signal_unit.values) == ["N", "kN"]
    np.testing.assert_array_equal(ds.signal_value.values, [[0.0, 0.0], [np.nan, 0.01], [20.0, 0.02]])


def test_ingest_rejects_a_signal_whose_unit_changes(tmp_path):
    (tmp_path / "dic").mkdir()
    _stage(tmp_path, 0, [("force [N]", "value_element", 1.0)])
    _stage(tmp_path, 1, [("force [kN]", "value_element", 1.0)])
    with pytest.raises(DataError, match=r"s_0_1.txt: signal 'force' is a value_element in kN, but in s_0_0.txt "
                                        r"a value_element in N"):
        ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr")


def test_exports_without_signals_give_none(tmp_path):
    (tmp_path / "dic").mkdir()
    for k in range(2):
        _stage(tmp_path, k, None)
    ingest_dic(tmp_path / "dic", tmp_path / "dic.zarr")
    ds = open_store(tmp_path / "dic.zarr")
    assert "signal_value" not in ds and "signal" not in ds.coords
