"""Testing machine records (irdic.signals): reading, errors, and the signals at the DIC times."""

import numpy as np
import pytest
import xarray as xr

from irdic.config import validate_config
from irdic.errors import ConfigError, DataError, FormatError, IrdicWarning
from irdic.signals import ingest_machine, read_machine, signals_at
from irdic.store import open_store, write_dataset

COLS = {"time": "Zeit [ms]", "force": "Kraft [kN]", "angle": "Winkel [deg]"}


def _csv(tmp_path, rows, header="Zeit [ms];Kraft [kN];Winkel [deg]", name="m.csv"):
    p = tmp_path / name
    p.write_text("Prüfprogramm;Zug\n" + header + "\n" + "\n".join(rows) + "\n", encoding="cp1252")
    return p


def test_reads_german_csv_with_units_and_offset(tmp_path):
    p = _csv(tmp_path, ["0;0,0;0,0", "20;1,5;0,25", "40;3,0;0,5"])
    ds = read_machine(p, columns=COLS, time_offset=-0.02)
    np.testing.assert_allclose(ds.time.values, [-0.02, 0.0, 0.02])  # ms -> s, then the offset is added
    assert list(ds.signal.values) == ["force", "angle"] and list(ds.signal_unit.values) == ["kN", "deg"]
    assert list(ds.signal_kind.values) == ["machine"] * 2
    assert list(ds.signal_standard_name.values) == ["force", "angle"]
    np.testing.assert_array_equal(ds.signal_value.values, [[0.0, 0.0], [1.5, 0.25], [3.0, 0.5]])
    first = read_machine(p, columns=COLS, time_origin="first", time_offset=1.0)
    np.testing.assert_allclose(first.time.values, [1.0, 1.02, 1.04])


def test_missing_column_is_named(tmp_path):
    p = _csv(tmp_path, ["0;0;0"])
    with pytest.raises(ConfigError, match=r"'Drehmoment \[N\*m\]' given in columns not found in .*m.csv; .*"
                                          r"'Zeit \[ms\]', 'Kraft \[kN\]', 'Winkel \[deg\]'"):
        read_machine(p, columns={**COLS, "torque": "Drehmoment [N*m]"})


def test_non_increasing_time_names_the_line(tmp_path):
    p = _csv(tmp_path, ["0;0;0", "20;1;0", "20;2;0"])
    with pytest.raises(FormatError, match=r"m.csv, line 5: column 'Zeit \[ms\]': time '20' does not come after "
                                          r"'20' \(line 4\); machine times must increase"):
        read_machine(p, columns=COLS)


def test_non_numeric_cell_names_line_and_column(tmp_path):
    p = _csv(tmp_path, ["0;0;0", "20;1,0;x", "40;2;0"])
    with pytest.raises(FormatError, match=r"m.csv, line 4: column 'Winkel \[deg\]': cannot read 'x' as a number"):
        read_machine(p, columns=COLS)


def test_missing_time_and_too_short_records(tmp_path):
    with pytest.raises(FormatError, match=r"line 4: column 'Zeit \[ms\]': missing time"):
        read_machine(_csv(tmp_path, ["0;0;0", ";1;0"]), columns=COLS)
    with pytest.raises(DataError, match="1 sample; expected a time series"):
        read_machine(_csv(tmp_path, ["0;0;0"], name="short.csv"), columns=COLS)


@pytest.mark.parametrize("columns, match", [
    ({"force": "Kraft"}, "must name the time column"),
    ({"time": "Zeit"}, "names only the time column"),
    ({"time": "Zeit", "my force": "Kraft"}, "must be an identifier"),
])
def test_bad_columns(tmp_path, columns, match):
    with pytest.raises(ConfigError, match=match):
        read_machine(_csv(tmp_path, ["0;0;0", "1;1;1"]), columns=columns)


def test_config_section_defaults_and_errors():
    base = {"setups": {"s": {"markers": {"path": "m"}, "target_image": {"path": "t"}}},
            "experiments": {"e": {"setup": "s", "dic": {"path": "d"}, "ir": {"path": "i"},
                                  "machine": {"path": "m.csv", "columns": {"time": "t", "force": "F"}}}}}
    cfg = validate_config(base)
    m = cfg["experiments"]["e"]["machine"]
    assert (m["format"], m["time_offset"], m["time_origin"], m["sep"], m["decimal"]) == ("csv", 0.0, "file", None, None)
    base["experiments"]["e"]["machine"]["columns"] = {"force": "F"}
    with pytest.raises(ConfigError, match=r"experiments.e.machine.columns: 'time' is a required property"):
        validate_config(base)
    base["experiments"]["e"]["machine"]["columns"] = {"time": "t", "Kraft [kN]": "F"}
    with pytest.raises(ConfigError, match=r"experiments.e.machine.columns: signal name 'Kraft \[kN\]' must be"):
        validate_config(base)


def test_signals_at_dic_times_interpolates_machine_and_warns_outside(tmp_path):
    p = _csv(tmp_path, [f"{t};{2.0 * t / 1000};{t / 1000}" for t in range(0, 2001, 20)])
    ingest_machine(p, tmp_path / "machine.zarr", columns=COLS, time_offset=0.5)
    machine = open_store(tmp_path / "machine.zarr")
    dic = xr.Dataset({"signal_value": (("time", "signal"), [[1.0], [np.nan], [3.0], [4.0]])},
                     coords={"time": [0.0, 1.0, 2.0, 3.0], "signal": ["force"], "signal_unit": ("signal", ["N"])})
    t = np.array([0.0, 1.0, 2.0, 3.0, 2.0 + 1e-9])
    with pytest.warns(IrdicWarning, match=r"2 of 5 DIC times \(0 s first\) lie outside the machine record's span "
                                          r"0.5..2.5 s"):
        s = signals_at(t, dic=dic, machine=machine)
    assert list(s.signal.values) == ["force", "machine_force", "machine_angle"]
    v = s.signal_value.values
    np.testing.assert_array_equal(v[:, 0], [1.0, np.nan, 3.0, 4.0, 3.0])  # DIC: matched, never interpolated
    expected = 2.0 * (t - 0.5)  # the record's time + 0.5 s = DIC time
    expected[(t < 0.5) | (t > 2.5)] = np.nan
    np.testing.assert_allclose(v[:, 1], expected, rtol=1e-12, atol=1e-9)
    assert signals_at(t) is None


def test_machine_signals_at_the_ir_frame_times(tmp_path):
    """Every IR frame gets its load: the record interpolated onto the IR times, offset applied."""
    from irdic.stages import ingest_machine as stage

    p = _csv(tmp_path, [f"{t};{2.0 * t / 1000};{t / 1000}" for t in range(0, 2001, 20)])
    t_ir = np.array([0.25, 0.5, 0.51, 1.3, 2.5, 2.75])  # 50 Hz-ish frames, two outside the record
    ir = xr.Dataset({"temperature": (("time", "v", "u"), np.zeros((t_ir.size, 2, 2), np.float32))},
                    coords={"time": t_ir, "v": [0, 1], "u": [0, 1]})
    write_dataset(ir, tmp_path / "ir.zarr", stage="ingest-ir")
    with pytest.warns(IrdicWarning, match=r"2 of 6 IR frame times \(0.25 s first\) lie outside"):
        stage.run({"source": p, "ir": tmp_path / "ir.zarr"}, {"store": tmp_path / "machine.zarr"}, columns=COLS,
                  time_offset=0.5)
    m = open_store(tmp_path / "machine.zarr")
    np.testing.assert_array_equal(m.ir_time.values, t_ir)
    force = m.signal_value_ir.sel(signal="force").values
    expected = 2.0 * (t_ir - 0.5)  # the record's time + 0.5 s = the cameras' time
    expected[(t_ir < 0.5) | (t_ir > 2.5)] = np.nan
    np.testing.assert_allclose(force, expected, rtol=1e-12, atol=1e-9)
    assert m.signal_value_ir.attrs["long_name"].startswith("machine signal at the IR frame time")
