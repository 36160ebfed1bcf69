"""DICe stereo solution reader: real gold files from the DICe regression tests, and edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import DataError, FormatError
from irdic.io import detect_dic_format, read_dic
from irdic.io.dice import read_dice
from irdic.synthetic.writers import write_dice

HEADER = ("SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y,MODEL_COORDINATES_X,"
          "MODEL_COORDINATES_Y,MODEL_COORDINATES_Z,MODEL_DISPLACEMENT_X,MODEL_DISPLACEMENT_Y,"
          "MODEL_DISPLACEMENT_Z,SIGMA")


@pytest.mark.samples
def test_sample_frame_0(samples):
    p = samples / "dice" / "DICe_solution_0.txt"
    assert detect_dic_format(p) == "dice"
    ds = read_dic(p)
    assert ds.attrs["format"] == "dice" and ds.attrs["frame_index"] == 0
    assert ds.sizes == {"point": 1089, "component": 3}
    np.testing.assert_array_equal(ds.point.values, np.arange(1089))
    # first row: 0,5.5500E+02,9.3000E+02,1.6353E-06,1.4493E-06,-2.2699E+00,2.1956E+00,-3.5498E-02,
    #            1.3418E-08,-4.4086E-11,-2.8049E-08,3.9571E-03
    np.testing.assert_allclose(ds.x_ref.values[0], [-2.2699, 2.1956, -3.5498e-02], rtol=0, atol=1e-15)
    np.testing.assert_allclose(ds.x.values[0], [-2.2699 + 1.3418e-08, 2.1956 - 4.4086e-11, -3.5498e-02 - 2.8049e-08],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(ds.SIGMA.values[0], 3.9571e-03, rtol=1e-12)
    np.testing.assert_allclose([ds.COORDINATE_X.values[0], ds.COORDINATE_Y.values[0]], [555.0, 930.0])
    assert ds.attrs["n_invalid"] == 0 and np.isfinite(ds.x.values).all()
    # the stereo model of this regression case spans about +-2.3 mm
    assert np.abs(ds.x_ref.values[:, :2]).max() == pytest.approx(2.3, abs=0.1)


@pytest.mark.samples
def test_sample_frame_1_moves_the_same_subsets(samples):
    d0 = read_dice(samples / "dice" / "DICe_solution_0.txt")
    d1 = read_dice(samples / "dice" / "DICe_solution_1.txt")
    assert d1.attrs["frame_index"] == 1
    np.testing.assert_array_equal(d0.point.values, d1.point.values)
    np.testing.assert_array_equal(d0.x_ref.values, d1.x_ref.values)  # same model coordinates
    np.testing.assert_allclose(d1.x.values[0], [-2.2699 - 3.0356e-02, 2.1956 + 2.5451e-02, -3.5498e-02 + 3.5206e-02],
                               rtol=0, atol=1e-15)
    # last row: 1088,...,2.2215E+00,-2.2992E+00,-2.1803E-02,2.8639E-02,-3.0434E-02,2.1696E-02,...
    assert int(d1.point[-1]) == 1088
    np.testing.assert_allclose(d1.x.values[-1], [2.2215 + 2.8639e-02, -2.2992 - 3.0434e-02, -2.1803e-02 + 2.1696e-02],
                               rtol=0, atol=1e-15)
    disp = np.linalg.norm(d1.x.values - d1.x_ref.values, axis=1)
    assert 0 < disp.max() < 0.1


def test_star_header_failed_subset_and_crlf(tmp_path):
    lines = ["***", "*** Digital Image Correlation Engine (DICe)", "*** Reference image: ref.tif", "***", HEADER,
             "0,5.5500E+02,9.3000E+02,0,0,-2.0000E+00,1.0000E+00,5.0000E-01,1.0000E-02,0,-2.0000E-02,4.0E-03",
             "1,5.5500E+02,9.0500E+02,0,0,-1.5000E+00,1.0000E+00,5.0000E-01,0,0,0,-1.0000E+00",
             "5,5.5500E+02,8.8000E+02,0,0,-1.0000E+00,1.0000E+00,nan,0,0,0,3.0E-03"]
    p = tmp_path / "DICe_solution_12.txt"
    p.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    assert detect_dic_format(p) == "dice"
    ds = read_dice(p)
    np.testing.assert_array_equal(ds.point.values, [0, 1, 5])
    np.testing.assert_allclose(ds.x.values[0], [-1.99, 1.0, 0.48], rtol=0, atol=1e-15)
    assert np.isnan(ds.x.values[1:]).all() and np.isnan(ds.x_ref.values[1:]).all()
    assert ds.SIGMA.values[1] == -1.0  # kept for the user to see why
    assert ds.attrs["n_invalid"] == 2 and ds.attrs["frame_index"] == 12


def test_extra_columns_and_order(tmp_path):
    p = tmp_path / "DICe_solution_3.txt"
    p.write_text("MODEL_DISPLACEMENT_Z, MODEL_COORDINATES_Z, GAMMA, SUBSET_ID, MODEL_COORDINATES_X, "
                 "MODEL_COORDINATES_Y, MODEL_DISPLACEMENT_X, MODEL_DISPLACEMENT_Y, STATUS_FLAG\n"
                 "1.0E-01, 2.0E+00, 0.01, 42, 1.0E+00, 3.0E+00, 0, 5.0E-01, 4\n")
    ds = read_dice(p)
    np.testing.assert_allclose(ds.x.values, [[1.0, 3.5, 2.1]], rtol=0, atol=1e-15)
    assert ds.point.values.tolist() == [42]
    assert ds.STATUS_FLAG.values.tolist() == [4.0] and ds.GAMMA.values.tolist() == [0.01]


def test_two_d_solution_is_refused(tmp_path):
    p = tmp_path / "DICe_solution_0.txt"
    p.write_text("SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y,SIGMA\n0,1,2,3,4,0.1\n")
    with pytest.raises(FormatError, match=r"2-D DICe solution .* stereo analysis: MODEL_COORDINATES_X/Y/Z"):
        read_dice(p)


def test_missing_model_displacement_listed(tmp_path):
    p = tmp_path / "DICe_solution_0.txt"
    p.write_text("SUBSET_ID,MODEL_COORDINATES_X,MODEL_COORDINATES_Y,MODEL_COORDINATES_Z\n0,1,2,3\n")
    with pytest.raises(FormatError, match="missing columns 'MODEL_DISPLACEMENT_X', 'MODEL_DISPLACEMENT_Y'.*found 'SUBSET_ID'"):
        read_dice(p)


def test_bad_cell_and_duplicates(tmp_path):
    row = "{i},0,0,0,0,1.0E+00,2.0E+00,3.0E+00,{dx},0,0,1.0E-02"
    p = tmp_path / "DICe_solution_0.txt"
    p.write_text("\n".join([HEADER, row.format(i=0, dx="0"), row.format(i=1, dx="1.0E-0x")]) + "\n")
    with pytest.raises(FormatError, match="column 'MODEL_DISPLACEMENT_X': cannot read '1.0E-0x'") as err:
        read_dice(p)
    assert err.value.line == 3
    p.write_text("\n".join([HEADER, row.format(i=4, dx="0"), row.format(i=5, dx="0"), row.format(i=4, dx="0")]) + "\n")
    with pytest.raises(DataError, match="SUBSET_ID 4 appears twice, on lines 2 and 4"):
        read_dice(p)


def test_header_only(tmp_path):
    p = tmp_path / "DICe_solution_0.txt"
    p.write_text("***\n" + HEADER + "\n")
    with pytest.raises(FormatError, match="no data rows after the header on line 2"):
        read_dice(p)


def test_write_read_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    n = 50
    mc = rng.uniform(-20, 20, (n, 3))
    md = rng.normal(0, 0.2, (n, 3))
    md[7] = np.nan
    p = write_dice(tmp_path / "DICe_solution_4.txt", np.arange(100, 100 + n), mc, md,
                   image_coordinates=rng.uniform(0, 1000, (n, 2)), header_lines=["Frame: 4"])
    ds = read_dic(p)
    ok = np.arange(n) != 7
    # %.4E keeps 5 significant digits
    np.testing.assert_allclose(ds.x_ref.values[ok], mc[ok], rtol=5e-5)
    np.testing.assert_allclose(ds.x.values[ok], (mc + md)[ok], rtol=0, atol=5e-5 * 20 + 5e-5 * 1)
    assert np.isnan(ds.x.values[7]).all() and ds.SIGMA.values[7] == -1
    np.testing.assert_array_equal(ds.point.values, np.arange(100, 100 + n))


def _dice_no_ids(path, rows, shift):
    head = ("COORDINATE_X,COORDINATE_Y,MODEL_COORDINATES_X,MODEL_COORDINATES_Y,MODEL_COORDINATES_Z,"
            "MODEL_DISPLACEMENT_X,MODEL_DISPLACEMENT_Y,MODEL_DISPLACEMENT_Z,SIGMA\n")
    body = "".join(f"{5.55e2 + 20 * r:.4E},{9.3e2:.4E},{2.0 * r:.4E},0,0,{shift:.4E},0,0,1.0E-02\n" for r in rows)
    path.write_text(head + body)


def test_stage_without_subset_ids_and_a_row_fewer_matches_by_coordinates(tmp_path):
    from irdic.ingest.dic import ingest_dic
    from irdic.store import open_store

    src = tmp_path / "dice"
    src.mkdir()
    _dice_no_ids(src / "DICe_solution_0.txt", range(4), 0.0)
    _dice_no_ids(src / "DICe_solution_1.txt", [1, 2, 3], 0.5)  # subset 0 dropped from this file
    ds0 = read_dice(src / "DICe_solution_0.txt")
    assert ds0.attrs["point_key"] == "COORDINATE_X,COORDINATE_Y"
    ds = open_store(ingest_dic(src, tmp_path / "dic.zarr", time_source="frame_rate", frame_rate=1.0))
    np.testing.assert_allclose(ds.x.values[1, :, 0] - ds.x.values[0, :, 0], [np.nan, 0.5, 0.5, 0.5], atol=1e-12)


def test_duplicate_reference_position_without_ids_is_refused(tmp_path):
    from irdic.ingest.dic import ingest_dic

    src = tmp_path / "dice"
    src.mkdir()
    _dice_no_ids(src / "DICe_solution_0.txt", [0, 1, 1], 0.0)
    with pytest.raises(DataError, match=r"DICe_solution_0\.txt: two rows have the same reference image position "
                                        r"\(COORDINATE_X, COORDINATE_Y = 575, 930\)"):
        ingest_dic(src, tmp_path / "dic.zarr", time_source="frame_rate", frame_rate=1.0)
