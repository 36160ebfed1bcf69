"""Calibration-target marker centres: reader and writer."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError, FormatError, IrdicWarning
from irdic.io import read_markers as read_markers_dispatch
from irdic.io.markers import read_markers
from irdic.synthetic.writers import write_markers

SEMI = """# Reference object: open book, brass, 8 markers
# exported from point components
#        ID;             x [mm];             y [mm];             z [mm]
         1;          -40.000000;           12.500000;            0.000000
         2;          -20.000000;           12.500000;            0.000000
        17;          -20.000000;          -12.500000;           35.355339
        18;                 nan;                 nan;                 nan
        21;           20.000000;          -12.500000;          -35.355339
"""

XYZ = np.array([[-40.0, 12.5, 0.0], [-20.0, 12.5, 0.0], [-20.0, -12.5, 35.355339], [20.0, -12.5, -35.355339]])


def test_semicolon_style_drops_unseen_marker(tmp_path):
    p = tmp_path / "markers.txt"
    p.write_text(SEMI)
    with pytest.warns(IrdicWarning, match="1 marker\\(s\\) without coordinates dropped .*IDs 18"):
        ds = read_markers_dispatch(p)
    np.testing.assert_array_equal(ds.marker.values, [1, 2, 17, 21])
    assert ds.marker.dtype == np.int64 and ds.x.dtype == np.float64
    np.testing.assert_allclose(ds.x.values, XYZ, rtol=0, atol=0)
    assert ds.x.attrs["units"] == "mm" and list(ds.component.values) == ["x", "y", "z"]
    assert ds.attrs["format"] == "markers" and ds.attrs["dropped_markers"] == [18]


def test_csv_header_case_extra_columns_and_crlf(tmp_path):
    p = tmp_path / "m.csv"
    p.write_bytes(b"Marker_ID,Deviation [mm],X [mm],Y [mm],Z [mm]\r\n5,0.01,1.5,2.5,3.5\r\n6,0.02,4,5,6\r\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = read_markers(p)
    np.testing.assert_array_equal(ds.marker.values, [5, 6])
    np.testing.assert_allclose(ds.x.values, [[1.5, 2.5, 3.5], [4, 5, 6]], rtol=0, atol=0)


@pytest.mark.parametrize("text", ["1 0.5 1.5 2.5\n2 3.5 4.5 5.5\n",
                                  "1\t0.5\t1.5\t2.5\n2\t3.5\t4.5\t5.5\n",
                                  "# no header here\n1,0.5,1.5,2.5\n2,3.5,4.5,5.5\n",
                                  "1;0,5;1,5;2,5\n2;3,5;4,5;5,5\n"])
def test_headerless_four_columns(tmp_path, text):
    p = tmp_path / "m.txt"
    p.write_text(text)
    ds = read_markers(p)
    np.testing.assert_array_equal(ds.marker.values, [1, 2])
    np.testing.assert_allclose(ds.x.values, [[0.5, 1.5, 2.5], [3.5, 4.5, 5.5]], rtol=0, atol=0)


def test_headerless_wrong_count(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text("1 0.5 1.5\n")
    with pytest.raises(FormatError, match="found no header naming the columns ID, x, y, z and 3 fields"):
        read_markers(p)


def test_text_ids_refused(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text("# ID; x; y; z\n1; 0; 0; 0\nP12; 1; 2; 3\n")
    with pytest.raises(FormatError, match="marker ID 'P12' in column 'ID' is not an integer") as err:
        read_markers(p)
    assert err.value.line == 3


def test_duplicate_ids(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text(SEMI.replace("        21;", "         2;"))
    with pytest.raises(DataError, match="marker ID 2 appears twice, on lines 5 and 8"):
        read_markers(p)


def test_bad_cell_and_all_unseen(tmp_path):
    p = tmp_path / "m.txt"
    p.write_text("# ID; x; y; z\n1; 0; 0; 0\n2; 1; 2; 3..\n")
    with pytest.raises(FormatError, match="column 'z': cannot read '3..' as a number") as err:
        read_markers(p)
    assert err.value.line == 3
    p.write_text("# ID; x; y; z\n1; nan; nan; nan\n")
    with pytest.raises(DataError, match="none of the 1 markers has coordinates"), pytest.warns(IrdicWarning):
        read_markers(p)
    p.write_text("# ID; x; y; z\n")
    with pytest.raises(FormatError, match="no data rows"):
        read_markers(p)


def test_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    ids = np.arange(10, 94)
    x = rng.uniform(-50, 50, (84, 3))
    x[5] = np.nan
    p = write_markers(tmp_path / "target.txt", ids, x)
    with pytest.warns(IrdicWarning, match="IDs 15"):
        ds = read_markers(p)
    keep = np.arange(84) != 5
    np.testing.assert_array_equal(ds.marker.values, ids[keep])
    np.testing.assert_allclose(ds.x.values, x[keep], rtol=0, atol=0.5e-6 + 1e-12)


@pytest.mark.parametrize("ids, x, match", [([1, 1], np.zeros((2, 3)), "ids must be unique"),
                                           ([1.0, 2.0], np.zeros((2, 3)), "ids must be a non-empty 1-D integer"),
                                           ([1, 2], np.zeros((2, 2)), r"x must have shape \(2, 3\)")])
def test_writer_checks(tmp_path, ids, x, match):
    with pytest.raises(ConfigError, match=match):
        write_markers(tmp_path / "m.txt", np.asarray(ids), x)
