"""Generic table reader (GOM CSV exports with preambles, MatchID-like files, ...)."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError, FormatError
from irdic.io import read_dic
from irdic.io.table import read_table
from irdic.io.units import parse_date, parse_duration

GOM_CSV = """Project: tube
Stage: 4
Export date: 13.04.2021
Unit: mm

Point ID,X [mm],Y [mm],Z [mm],dX [mm],dY [mm],dZ [mm],Eps X [%],Comment
1,-12.5,3.25,0.125,0.0125,-0.002,0.001,0.12,ok
2,-11.0,3.25,0.13,0.013,-0.0021,0.0012,0.125,ok
3,-9.5,3.25,0.1375,,,,,failed
"""

MAP = {"id": "Point ID", "x": "X [mm]", "y": "Y [mm]", "z": "Z [mm]", "u": "dX [mm]", "v": "dY [mm]", "w": "dZ [mm]"}


def test_preamble_reference_plus_displacement(tmp_path):
    p = tmp_path / "stage4.csv"
    p.write_text(GOM_CSV)
    ds = read_dic(p, format="table", columns=MAP, time=2.0)
    assert ds.attrs["header_line"] == 6 and ds.attrs["separator"] == ","
    np.testing.assert_array_equal(ds.point.values, [1, 2, 3])
    np.testing.assert_allclose(ds.x.values[:2], [[-12.4875, 3.248, 0.126], [-10.987, 3.2479, 0.1312]],
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds.x_ref.values[:2], [[-12.5, 3.25, 0.125], [-11.0, 3.25, 0.13]])
    assert np.isnan(ds.x.values[2]).all()
    assert float(ds.time) == 2.0
    # numeric extra column kept with its unit, text column left out
    assert ds.Eps_X.attrs["units"] == "%" and "Comment" not in ds


def test_names_without_units_and_case(tmp_path):
    p = tmp_path / "stage4.csv"
    p.write_text(GOM_CSV)
    ds = read_table(p, columns={"x": "x", "y": "y", "z": "z", "u": "dx", "v": "dy", "w": "dz"})
    assert ds.attrs["point_id_source"] == "row"
    np.testing.assert_array_equal(ds.point.values, [0, 1, 2])
    np.testing.assert_allclose(ds.x.values[0], [-12.4875, 3.248, 0.126], atol=1e-14)


def test_semicolon_decimal_comma_valid_column_and_time_column(tmp_path):
    p = tmp_path / "matchid.txt"
    p.write_bytes(("X;Y;Z;valid;t [ms]\r\n1,5;2,25;-0,5;1;1500\r\n2,5;2,25;-0,5;0;1500\r\n"
                   "3,5;2,25;-0,5;1;1500\r\n").encode("cp1252"))
    ds = read_table(p, columns={"x": "X", "y": "Y", "z": "Z", "valid": "valid", "time": "t"},
                    decimal=None, invalid_value=0)
    assert ds.attrs["decimal"] == "," and ds.attrs["separator"] == ";"
    np.testing.assert_allclose(ds.x.values[[0, 2]], [[1.5, 2.25, -0.5], [3.5, 2.25, -0.5]], rtol=0, atol=0)
    assert np.isnan(ds.x.values[1]).all() and "x_ref" not in ds
    assert float(ds.time) == 1.5


def test_whitespace_table_with_header_line_and_metres(tmp_path):
    p = tmp_path / "v6.txt"
    p.write_text("ARAMIS v6 export\nindex_x index_y x [m] y [m] z [m]\n  0 0  0.001 0.002 0.0005\n"
                 "  1 0  0.0015 0.002 0.0005\n")
    ds = read_table(p, columns={"x": "x", "y": "y", "z": "z"}, header_line=2)
    np.testing.assert_allclose(ds.x.values, [[1.0, 2.0, 0.5], [1.5, 2.0, 0.5]], rtol=1e-14)
    np.testing.assert_array_equal(ds.index_x.values, [0, 1])


def test_tab_separated_with_trailing_tabs(tmp_path):
    p = tmp_path / "t.txt"
    p.write_text("id\tx\ty\tz\t\n3\t1.5\t2\t3\t\n4\t4\t5\t6\t\n")
    ds = read_table(p, columns={"id": "id", "x": "x", "y": "y", "z": "z"})
    assert ds.attrs["separator"] == "\t"
    np.testing.assert_array_equal(ds.point.values, [3, 4])
    np.testing.assert_allclose(ds.x.values, [[1.5, 2, 3], [4, 5, 6]], rtol=0, atol=0)


def test_time_text_parameter(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("x,y,z\n1,2,3\n")
    assert float(read_table(p, columns={"x": "x", "y": "y", "z": "z"}, time="0:00:02.5").time) == 2.5


def test_unknown_column_names_available(tmp_path):
    p = tmp_path / "stage4.csv"
    p.write_text(GOM_CSV)
    with pytest.raises(ConfigError, match=r"column\(s\) 'height' given in columns not found in .*stage4.csv; the "
                                          r"closest header candidate \(line 6\) has the columns 'Point ID', 'X \[mm\]'"):
        read_table(p, columns={"x": "X [mm]", "y": "Y [mm]", "z": "height"})
    with pytest.raises(ConfigError, match=r"column\(s\) 'height' given in columns not found in .*; the header "
                                          r"\(line 6\) has the columns 'Point ID', 'X \[mm\]'"):
        read_table(p, columns={"x": "X [mm]", "y": "Y [mm]", "z": "height"}, header_line=6)
    with pytest.raises(ConfigError, match=r"'a', 'b', 'c' given in columns not found .*\(line 1\) has the columns "
                                          r"'Project:', 'tube'"):
        read_table(p, columns={"x": "a", "y": "b", "z": "c"})


def test_repeated_column_name(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("x,y,z,z\n1,2,3,4\n")
    with pytest.raises(FormatError, match="column 'z' appears 2 times in the header"):
        read_table(p, columns={"x": "x", "y": "y", "z": "z"})


@pytest.mark.parametrize("kwargs, match", [
    ({"columns": {"x": "a", "y": "b"}}, "must map the roles 'x', 'y', 'z'; missing 'z'"),
    ({"columns": {"x": "a", "y": "b", "z": "c", "u": "d"}}, "not all of 'u', 'v', 'w'"),
    ({"columns": {"x": "a", "y": "b", "z": "c", "colour": "d"}}, "unknown role\\(s\\) 'colour'"),
    ({"columns": ["x", "y", "z"]}, "must be a mapping"),
    ({"columns": {"x": "a", "y": "b", "z": 3}}, r"columns\['z'\] must be a non-empty column name"),
    ({"decimal": ";"}, "decimal must be"),
    ({"sep": ", "}, "sep must be one character"),
    ({"sep": ",", "decimal": ","}, "decimal ',' needs a separator other than ','"),
    ({"time": "soon"}, "time: cannot read 'soon' as a time"),
    ({"header_line": 0}, "header_line must be a line number between 1 and"),
])
def test_argument_checks(tmp_path, kwargs, match):
    p = tmp_path / "t.csv"
    p.write_text("a,b,c,d\n1,2,3,4\n")
    args = {"columns": {"x": "a", "y": "b", "z": "c"}}
    args.update(kwargs)
    with pytest.raises(ConfigError, match=match):
        read_table(p, **args)


def test_file_problems(tmp_path):
    cols = {"id": "id", "x": "x", "y": "y", "z": "z"}
    p = tmp_path / "t.csv"
    p.write_text("id,x,y,z,name\n1,1,2,3,a\n2,1,2,abc,b\n")
    with pytest.raises(FormatError, match="column 'z': cannot read 'abc' as a number") as err:
        read_table(p, columns=cols)
    assert err.value.line == 3
    p.write_text("id,x,y,z\n1,1,2,3\n1,1,2,4\n")
    with pytest.raises(DataError, match="point ID 1 appears twice, on lines 2 and 3"):
        read_table(p, columns=cols)
    p.write_text("id,x,y,z\n1,1,2,3\n2,1,2\n")
    with pytest.raises(FormatError, match="found 3 fields, expected 4"):
        read_table(p, columns=cols)
    p.write_text("id,x,y,z\n")
    with pytest.raises(FormatError, match="no data rows"):
        read_table(p, columns=cols)
    p.write_text("id,x,y,z,t\n1,1,2,3,0.5\n2,1,2,3,1.0\n")
    with pytest.raises(DataError, match="time column 't' varies within the file"):
        read_table(p, columns={**cols, "time": "t"})
    p.write_text("id,x [furlong],y,z\n1,1,2,3\n")
    with pytest.raises(FormatError, match="column 'x \\[furlong\\]' has unit 'furlong'; expected a length unit"):
        read_table(p, columns=cols)


def test_quoted_fields_with_separator(tmp_path):
    p = tmp_path / "q.csv"
    p.write_text('"label","x","y","z"\n"a, b",1,2,3\n')
    ds = read_table(p, columns={"x": "x", "y": "y", "z": "z"})
    np.testing.assert_array_equal(ds.x.values, [[1, 2, 3]])


@pytest.mark.parametrize("text, seconds", [("3", 3.0), ("-0.5 s", -0.5), ("250 ms", 0.25), ("2 min", 120.0),
                                           ("0:00:00.125", 0.125), ("10:00", 600.0), ("1,25 s", 1.25)])
def test_parse_duration(text, seconds):
    assert parse_duration(text) == pytest.approx(seconds, abs=1e-12)


@pytest.mark.parametrize("text", ["", "abc", "1:75:00", "12 parsecs", "inf"])
def test_parse_duration_rejects(text):
    with pytest.raises(ValueError):
        parse_duration(text)


@pytest.mark.parametrize("text, iso", [("2021-04-13T12:38:34.5", "2021-04-13T12:38:34.500000"),
                                       ("13.04.2021 12:38:34", "2021-04-13T12:38:34"),
                                       ("2021-04-13 12:38:34.250000", "2021-04-13T12:38:34.250000"),
                                       ("04/13/2021 12:38:34 PM", "2021-04-13T12:38:34")])
def test_parse_date(text, iso):
    assert parse_date(text) == iso
