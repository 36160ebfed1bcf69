"""ZEISS INSPECT / ARAMIS nodemap reader and writer.

No public nodemap sample exists; the files here follow the layout written by
the public ARAMIS data exporter (metadata blocks ``# key<padding>: value``,
header ``#  ID; x_undef [mm]; ...``, rows formatted ``{:10.0f}; {:20.10f}; ...``).
"""

from __future__ import annotations

import time
import tracemalloc
import warnings
from datetime import datetime

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError, FormatError, IrdicError, IrdicWarning
from irdic.io import detect_dic_format, read_dic
from irdic.io.nodemap import read_nodemap
from irdic.synthetic.writers import write_nodemap

SEP = "#" * 100

# five facets; facet 4 failed in this stage (nan), facet 5 is absent (not written)
IDS = np.array([1, 2, 3, 4, 6])
XU = np.array([[-12.5, 3.25, 0.125], [-11.0, 3.25, 0.13], [-9.5, 3.25, 0.1375],
               [-8.0, 3.25, 0.14], [-12.5, 4.75, 0.11]])
U = np.array([[0.0125, -0.002, 0.001], [0.013, -0.0021, 0.0012], [0.0135, -0.0022, 0.0014],
              [np.nan, np.nan, np.nan], [0.012, -0.0019, 0.0009]])
EPS = np.array([[0.12, -0.04, 0.001, 0.13], [0.125, -0.041, 0.0012, 0.135], [0.13, -0.042, 0.0013, 0.14],
                [np.nan] * 4, [0.11, -0.038, 0.0009, 0.12]])


def aramis_text(*, relative="1.5", rbm_block=None, stage_block=True, rows=None, header=None) -> str:
    """A nodemap as the ARAMIS data exporter writes it."""
    out = ["# Process data:"]
    meta = {"project_name": "tube_test", "specimen": "T1", "gom_project_file": r"C:\data\tube.aramis",
            "project_creation_time": "2021-04-13 09:12:01", "sensor_name": "ARAMIS 12M",
            "camera_focal_length": "50.0", "measuring_distance": "880.0"}
    out += [f"# {k.ljust(30)}: {v}" for k, v in meta.items()]
    out += [SEP, "# Calibration data:", f"# {'calibration_object'.ljust(30)}: CP20/MV320",
            f"# {'calibration_deviation'.ljust(30)}: 0.021", SEP]
    if stage_block:
        out += ["# stage data:"]
        stage = {"facet_size": 19, "facet_distance": 15, "exposure_time": 0.005, "current_stage_index": 3,
                 "current_stage_name": "Stage 3", "current_stage_date": "2021-04-13T12:38:34.500000",
                 "current_stage_relative_date": relative, "reference_stage_index": 0,
                 "reference_stage_name": "Stage 0", "reference_stage_date": "2021-04-13T12:38:33"}
        out += [f"# {k.ljust(30)}: {v}" for k, v in stage.items()] + [SEP]
    out += ["# rigid body motion compensation:"]
    rbm = rbm_block if rbm_block is not None else {
        "alignment_rotation_x": 0.0, "alignment_rotation_y": 0.0, "alignment_rotation_z": 0.0,
        "alignment_translation_x": 0.0, "alignment_translation_y": 0.0, "alignment_translation_z": 0.0,
        "alignment_deviation": 0.0}
    out += [f"# {k.ljust(30)}: {v}" for k, v in rbm.items()] + [SEP]
    out += ["# SIGNALS:", f"# {'Force'.ljust(30)}: {'analog_input'.ljust(20)}: N", "#", SEP]
    names = header or ["ID", "x_undef [mm]", "y_undef [mm]", "z_undef [mm]", "u [mm]", "v [mm]", "w [mm]",
                       "epsx [%]", "epsy [%]", "epsxy [1]", "epseqv [%]"]
    out.append("#{:>10}; ".format(names[0]) + "; ".join(f"{n:>20}" for n in names[1:]))
    if rows is None:
        rows = []
        for i, xu, u, e in zip(IDS, XU, U, EPS):
            rows.append("{:10.0f}; {:20.10f}; {:20.10f}; {:20.10f}; {:20.15f}; {:20.15f}; {:20.15f}; "
                        "{:20.15f}; {:20.15f}; {:20.15f}; {:20.15f}".format(i, *xu, *u, *e))
    return "\n".join(out + rows) + "\n"


@pytest.fixture
def nodemap(tmp_path):
    p = tmp_path / "tube_T1_3_dic_results_0_3.txt"
    p.write_text(aramis_text(), encoding="utf-8")
    return p


def test_reads_exporter_layout(nodemap):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean export must not warn
        ds = read_nodemap(nodemap)
    assert detect_dic_format(nodemap) == "nodemap"
    np.testing.assert_array_equal(ds.point.values, IDS)
    assert ds.point.dtype == np.int64
    assert list(ds.component.values) == ["x", "y", "z"]
    ok = [0, 1, 2, 4]
    np.testing.assert_allclose(ds.x.values[ok], (XU + U)[ok], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ds.x_ref.values[ok], XU[ok], rtol=0, atol=1e-12)
    assert np.isnan(ds.x.values[3]).all() and np.isnan(ds.x_ref.values[3]).all()
    assert ds.x.dtype == np.float64 and ds.x.attrs["units"] == "mm" and ds.x_ref.attrs["units"] == "mm"
    assert float(ds.time) == 1.5 and ds.time.attrs["units"] == "s"
    a = ds.attrs
    assert a["format"] == "nodemap" and a["source"] == str(nodemap)
    assert (a["stage_index"], a["reference_stage_index"], a["stage_name"]) == (3, 0, "Stage 3")
    assert a["stage_date"] == "2021-04-13T12:38:34.500000"
    assert a["rbm_compensation"] is False
    assert a["n_invalid"] == 1
    np.testing.assert_allclose(ds.epsxy.values[ok], EPS[ok, 2], atol=1e-15)
    assert ds.epsx.attrs["units"] == "%" and ds.epsxy.attrs["units"] == "1"


def test_read_dic_dispatches(nodemap):
    ds = read_dic(nodemap)
    assert ds.attrs["format"] == "nodemap" and ds.sizes["point"] == 5


def test_crlf_cp1252_and_decimal_comma(tmp_path):
    text = aramis_text().replace("# SIGNALS:", "# SIGNALS:\n# Temperatur                   : value_element       : 23,5 °C")
    rows_at = text.index("#        ID")
    body = text[rows_at:]
    head, *data = body.split("\n")
    text = text[:rows_at] + "\n".join([head] + [ln.replace(".", ",") for ln in data])
    p = tmp_path / "german_0_3.txt"
    p.write_bytes(text.replace("\n", "\r\n").encode("cp1252"))
    ds = read_nodemap(p)
    ok = [0, 1, 2, 4]
    np.testing.assert_allclose(ds.x.values[ok], (XU + U)[ok], rtol=0, atol=1e-12)
    assert np.isnan(ds.x.values[3]).all()


def test_column_order_padding_and_unknown_columns(tmp_path):
    names = ["w [mm]", "ID", "note", "z_undef [mm]", "y_undef [mm]", "x_undef [mm]", "v [mm]", "u [mm]"]
    rows = [f"{u[2]};{i};  7 ;{xu[2]}  ;  {xu[1]};{xu[0]};{u[1]};{u[0]};"
            for i, xu, u in zip(IDS[:3], XU[:3], U[:3])]  # trailing separator, odd spacing
    rows += ["NaN; 9; 1; 1.0; 2.0; 3.0; 0.1; 0.2", " ; 10; ; 1.0; 2.0; 3.0; ; "]  # failed: NaN, empty cells
    p = tmp_path / "shuffled_0_1.txt"
    p.write_text(aramis_text(rows=rows, header=names))
    ds = read_nodemap(p)
    np.testing.assert_array_equal(ds.point.values, [1, 2, 3, 9, 10])
    np.testing.assert_allclose(ds.x.values[:3], (XU + U)[:3], rtol=0, atol=1e-12)
    assert np.isnan(ds.x.values[3:]).all() and np.isnan(ds.x_ref.values[3:]).all()
    np.testing.assert_array_equal(ds.note.values[:4], [7.0, 7.0, 7.0, 1.0])
    assert np.isnan(ds.note.values[4])


def test_dataset_goes_into_the_store_cleanly(nodemap, tmp_path):
    from irdic.store import open_store, write_dataset

    ds = read_nodemap(nodemap)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_dataset(ds, tmp_path / "dic.zarr", stage="ingest", params={}, inputs=[str(nodemap)])
    assert not [w for w in caught if "Unstable" in type(w.message).__name__]
    back = open_store(tmp_path / "dic.zarr")
    np.testing.assert_array_equal(back.x.values, ds.x.values)
    assert float(back.time) == 1.5 and back.attrs["stage_index"] == 3 and back.attrs["rbm_compensation"] is False
    assert list(back.component.values) == ["x", "y", "z"]


@pytest.mark.parametrize("text, seconds", [("1.5", 1.5), ("1.5 s", 1.5), ("1500 ms", 1.5), ("1500ms", 1.5),
                                           ("0:00:01.5", 1.5), ("1:02:03.25", 3723.25), ("01:30", 90.0),
                                           ("1,5", 1.5), ("2.5e1", 25.0)])
def test_relative_time_forms(tmp_path, text, seconds):
    p = tmp_path / "t_0_3.txt"
    p.write_text(aramis_text(relative=text))
    assert float(read_nodemap(p).time) == pytest.approx(seconds, abs=1e-12)


@pytest.mark.parametrize("text", ["None", ""])
def test_relative_time_absent(tmp_path, text):
    p = tmp_path / "t_0_3.txt"
    p.write_text(aramis_text(relative=text))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert "time" not in read_nodemap(p).coords


def test_unreadable_time_warns_and_is_absent(tmp_path):
    p = tmp_path / "t_0_3.txt"
    p.write_text(aramis_text(relative="yesterday"))
    with pytest.warns(IrdicWarning, match=r"line \d+: cannot read 'yesterday' as a time"):
        ds = read_nodemap(p)
    assert "time" not in ds.coords


def test_rbm_flag_active_warns(tmp_path):
    p = tmp_path / "rbm_0_3.txt"
    p.write_text(aramis_text(rbm_block={"alignment_is_active": "True", "alignment_rotation_x": 0.0}))
    with pytest.warns(IrdicWarning, match="not in the sensor's fixed frame in which the calibration markers"):
        ds = read_nodemap(p)
    assert ds.attrs["rbm_compensation"] is True


def test_rbm_flag_inactive_with_transformation_is_quiet(tmp_path):
    p = tmp_path / "rbm_0_3.txt"
    p.write_text(aramis_text(rbm_block={"alignment_is_active": "False", "alignment_rotation_x": 0.3}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_nodemap(p).attrs["rbm_compensation"] is False


def test_rbm_old_exporter_nonzero_transformation_counts_as_active(tmp_path):
    # the first public exporter always activated the compensation and wrote no flag
    p = tmp_path / "rbm_0_3.txt"
    p.write_text(aramis_text(rbm_block={"alignment_rotation_x": 0.0, "alignment_rotation_y": 0.0124,
                                        "alignment_translation_x": -0.5}))
    with pytest.warns(IrdicWarning, match="rigid body motion compensation"):
        assert read_nodemap(p).attrs["rbm_compensation"] is True


def test_stage_indices_from_file_name_without_stage_block(tmp_path):
    p = tmp_path / "proj_spec_1_dic_results_2_17.txt"
    p.write_text(aramis_text(stage_block=False))
    ds = read_nodemap(p)
    assert (ds.attrs["stage_index"], ds.attrs["reference_stage_index"]) == (17, 2)
    assert "time" not in ds.coords


def test_length_unit_m_is_converted(tmp_path):
    names = ["ID", "x_undef [m]", "y_undef [m]", "z_undef [m]", "u [m]", "v [m]", "w [m]"]
    rows = ["1; 0.0125; 0.5; 0.001; 0.0; 0.00001; 0.0"]
    p = tmp_path / "m_0_1.txt"
    p.write_text(aramis_text(rows=rows, header=names))
    np.testing.assert_allclose(read_nodemap(p).x.values, [[12.5, 500.01, 1.0]], rtol=1e-14)


# --------------------------------------------------------------------------- errors


def _rows_with(tmp_path, rows, header=None):
    p = tmp_path / "bad_0_1.txt"
    p.write_text(aramis_text(rows=rows, header=header))
    return p


def _line_of(path, needle):
    return next(k + 1 for k, ln in enumerate(path.read_text().splitlines()) if needle in ln)


def test_non_numeric_cell_names_line_and_column(tmp_path):
    p = _rows_with(tmp_path, ["1; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0",
                              "2; 1.0; 2.O; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0"])
    with pytest.raises(FormatError) as err:
        read_nodemap(p)
    assert err.value.line == _line_of(p, "2.O")
    assert "'y_undef [mm]'" in str(err.value) and "'2.O'" in str(err.value) and str(p) in str(err.value)


def test_inf_coordinate_is_rejected(tmp_path):
    p = _rows_with(tmp_path, ["1; 1.0; 2.0; 3.0; 0.1; inf; 0.3; 0; 0; 0; 0"])
    with pytest.raises(FormatError, match=r"column 'v \[mm\]': found 'inf', expected a finite number"):
        read_nodemap(p)


def test_wrong_field_count_names_line(tmp_path):
    p = _rows_with(tmp_path, ["1; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0",
                              "2; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0"])
    with pytest.raises(FormatError, match="found 10 fields, expected 11") as err:
        read_nodemap(p)
    assert err.value.line == _line_of(p, "2; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0")


def test_duplicate_ids_name_both_lines(tmp_path):
    p = _rows_with(tmp_path, ["7; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0",
                              "8; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0",
                              "7; 1.5; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0"])
    first, second = _line_of(p, "7; 1.0"), _line_of(p, "7; 1.5")
    with pytest.raises(DataError, match=rf"facet ID 7 appears twice, on lines {first} and {second}"):
        read_nodemap(p)


def test_non_integer_id(tmp_path):
    p = _rows_with(tmp_path, ["7.5; 1.0; 2.0; 3.0; 0.1; 0.2; 0.3; 0; 0; 0; 0"])
    with pytest.raises(FormatError, match="facet ID '7.5' is not an integer"):
        read_nodemap(p)


def test_missing_columns_listed(tmp_path):
    names = ["ID", "x_undef [mm]", "y_undef [mm]", "z_undef [mm]", "u [mm]", "v [mm]"]
    p = _rows_with(tmp_path, ["1; 1; 2; 3; 0; 0"], header=names)
    with pytest.raises(FormatError) as err:
        read_nodemap(p)
    msg = str(err.value)
    assert "missing column 'w'" in msg and "found 'ID', 'x_undef [mm]'" in msg and err.value.line is not None


def test_no_header_line(tmp_path):
    p = tmp_path / "x_0_1.txt"
    p.write_text("# current_stage_index : 1\n1; 2; 3\n")
    with pytest.raises(FormatError, match="no column header found; expected a line like '#  ID; x_undef"):
        read_nodemap(p)


def test_no_data_rows(tmp_path):
    p = _rows_with(tmp_path, [])
    with pytest.raises(FormatError, match="no data rows after the header"):
        read_nodemap(p)


def test_bad_stage_index(tmp_path):
    p = tmp_path / "s_0_1.txt"
    p.write_text(aramis_text().replace("current_stage_index           : 3", "current_stage_index           : 3b"))
    with pytest.raises(FormatError, match="current_stage_index must be an integer stage index, found '3b'"):
        read_nodemap(p)


def test_missing_and_empty_file(tmp_path):
    with pytest.raises(FormatError, match="file not found"):
        read_nodemap(tmp_path / "nope.txt")
    (tmp_path / "empty.txt").write_bytes(b"")
    with pytest.raises(FormatError, match="file is empty"):
        read_nodemap(tmp_path / "empty.txt")


# --------------------------------------------------------------------------- writer


def test_round_trip(tmp_path):
    rng = np.random.default_rng(7)
    n = 200
    ids = rng.choice(np.arange(1, 5000), n, replace=False)
    xu = rng.uniform(-60, 60, (n, 3))
    d = rng.normal(0, 0.5, (n, 3))
    d[[3, 50, 199]] = np.nan
    strains = {"epsx": rng.normal(0, 1, n), "epsy": rng.normal(0, 1, n)}
    date = datetime(2021, 4, 13, 12, 38, 34, 250000)
    p = write_nodemap(tmp_path / "demo_0_12.txt", ids, xu, d, stage_index=12, relative_time=6.0,
                      reference_stage_index=0, stage_name="heating", stage_date=date, strains=strains,
                      decimals=4)
    ds = read_dic(p)
    np.testing.assert_array_equal(ds.point.values, ids)
    ok = np.isfinite(d).all(1)
    np.testing.assert_allclose(ds.x_ref.values[ok], xu[ok], rtol=0, atol=0.5e-4 + 1e-12)
    np.testing.assert_allclose(ds.x.values[ok], (xu + d)[ok], rtol=0, atol=1e-4 + 1e-12)
    assert np.isnan(ds.x.values[~ok]).all() and np.isnan(ds.x_ref.values[~ok]).all()
    assert float(ds.time) == 6.0
    assert ds.attrs["stage_index"] == 12 and ds.attrs["reference_stage_index"] == 0
    assert ds.attrs["stage_name"] == "heating" and ds.attrs["stage_date"] == "2021-04-13T12:38:34.250000"
    assert ds.attrs["rbm_compensation"] is False
    np.testing.assert_allclose(ds.epsx.values, strains["epsx"], atol=0.5e-10)


def test_round_trip_decimals_and_rbm(tmp_path):
    xu = np.array([[1.23456789, 2.0, 3.0]])
    p = write_nodemap(tmp_path / "a_0_1.txt", [5], xu, np.zeros((1, 3)), stage_index=1, decimals=8,
                      rbm_compensation=True)
    with pytest.warns(IrdicWarning, match="redo the export with rigid body motion compensation deactivated"):
        ds = read_nodemap(p)
    np.testing.assert_allclose(ds.x.values, xu, atol=0.5e-8)
    assert ds.attrs["rbm_compensation"] is True and "time" not in ds.coords


@pytest.mark.parametrize("kwargs, match", [
    ({"x_undef": np.zeros((2, 2))}, r"x_undef must have shape \(2, 3\), got \(2, 2\)"),
    ({"displacement": np.zeros((3, 3))}, r"displacement must have shape \(2, 3\)"),
    ({"ids": [1, 1]}, "ids must be unique"),
    ({"ids": [1.5, 2]}, "ids must be integers"),
    ({"stage_index": -1}, "stage_index must be a non-negative integer"),
    ({"decimals": 20}, "decimals must be an integer from 0 to 15"),
    ({"strains": np.zeros((2, 3))}, r"strains must be .* \(2, 4\)"),
    ({"relative_time": float("nan")}, "relative_time must be finite"),
])
def test_writer_argument_checks(tmp_path, kwargs, match):
    args = {"ids": [1, 2], "x_undef": np.zeros((2, 3)), "displacement": np.zeros((2, 3)), "stage_index": 0}
    args.update(kwargs)
    with pytest.raises(ConfigError, match=match):
        write_nodemap(tmp_path / "w.txt", args.pop("ids"), args.pop("x_undef"), args.pop("displacement"), **args)


def test_paper_scale_stage_reads_fast(tmp_path):
    rng = np.random.default_rng(0)
    n = 10_000
    p = write_nodemap(tmp_path / "big_0_5.txt", np.arange(1, n + 1), rng.uniform(-50, 50, (n, 3)),
                      rng.normal(0, 0.1, (n, 3)), stage_index=5, relative_time=2.5,
                      strains=rng.normal(0, 1, (n, 4)))
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        ds = read_nodemap(p)
        best = min(best, time.perf_counter() - t0)
    assert ds.sizes["point"] == n
    # target is well under 0.1 s; the bound leaves room for a loaded 2-core CI machine
    assert best < 0.3, f"reading 10k points took {best:.3f} s"


def test_all_errors_are_irdic_errors(tmp_path):
    p = tmp_path / "garbage.txt"
    p.write_bytes(b"\x00\x01binary")
    with pytest.raises(IrdicError, match="NUL bytes"):
        read_nodemap(p)


# ----------------------------------------------------------------------------- memory


def _big_nodemap(path, n, seed=3):
    rng = np.random.default_rng(seed)
    xu = rng.uniform(-50, 50, (n, 3))
    d = rng.normal(0, 0.2, (n, 3))
    return write_nodemap(path, np.arange(1, n + 1), xu, d, stage_index=2, relative_time=1.0,
                         strains=rng.normal(0, 1, (n, 4))), xu, d


def test_large_nodemap_is_parsed_in_bounded_memory(tmp_path):
    # regression: the text, its list of lines and a joined copy (plus pandas' UCS-4 buffer of it) were all
    # held at once, about 6.4 times the file; now the file is parsed a block of lines at a time
    p, xu, d = _big_nodemap(tmp_path / "big_0_2.txt", 40_000)
    size = p.stat().st_size
    read_nodemap(p)  # imports and caches out of the measurement
    tracemalloc.start()
    try:
        ds = read_nodemap(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    out = sum(v.nbytes for v in ds.variables.values())
    assert peak < 3 * size + out, f"peak {peak / size:.2f} x the file size ({size} B) plus the output ({out} B)"
    # the blocks join seamlessly: every point, in file order, to the written precision
    np.testing.assert_array_equal(ds["point"].values, np.arange(1, 40_001))
    np.testing.assert_allclose(ds["x_ref"].values, xu, rtol=0, atol=0.5e-4 + 1e-12)
    np.testing.assert_allclose(ds["x"].values, np.round(xu, 4) + np.round(d, 4), rtol=0, atol=1e-9)


def test_bad_cell_beyond_the_first_block_names_its_line(tmp_path):
    p, _, _ = _big_nodemap(tmp_path / "big_0_2.txt", 20_000)
    lines = p.read_text().splitlines()
    k = len(lines) - 7  # far past the first block of lines
    cells = lines[k].split(";")
    cells[3] = " 1.2.3"
    lines[k] = ";".join(cells)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError, match=rf"line {k + 1}: column 'z_undef \[mm\]': cannot read '1\.2\.3' as a number"):
        read_nodemap(p)
    lines[k] = ";".join(cells[:3])
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError, match=rf"line {k + 1}: found 3 fields, expected 11"):
        read_nodemap(p)
