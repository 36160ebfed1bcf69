"""VIC-3D CSV reader (no public sample: files follow the documented layout)."""

from __future__ import annotations

import numpy as np
import pytest

from irdic.errors import FormatError
from irdic.io import detect_dic_format, read_dic
from irdic.io.vic import read_vic
from irdic.synthetic.writers import write_vic

VIC7 = ('"X", "Y", "Z", "U", "V", "W", "sigma", "x", "y", "u", "v", "exx", "eyy", "exy"\n'
        "-12.5, 3.25, 0.125, 0.0125, -0.002, 0.001, 0.0123, 512, 384, 0.12, -0.03, 0.001, -0.0004, 0.00001\n"
        "-11.0, 3.25, 0.13, 0.013, -0.0021, 0.0012, 0.0101, 527, 384, 0.13, -0.03, 0.001, -0.0004, 0.00001\n"
        "0, 0, 0, 0, 0, 0, -1, 542, 384, 0, 0, 0, 0, 0\n")


def test_vic7_layout(tmp_path):
    p = tmp_path / "spec-0005_0.csv"
    p.write_text(VIC7)
    assert detect_dic_format(p) == "vic"
    ds = read_dic(p)
    assert ds.attrs["format"] == "vic" and ds.attrs["point_id_source"] == "row"
    np.testing.assert_array_equal(ds.point.values, [0, 1, 2])
    np.testing.assert_allclose(ds.x.values[:2], [[-12.4875, 3.248, 0.126], [-10.987, 3.2479, 0.1312]],
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds.x_ref.values[:2], [[-12.5, 3.25, 0.125], [-11.0, 3.25, 0.13]], rtol=0, atol=0)
    assert np.isnan(ds.x.values[2]).all() and np.isnan(ds.x_ref.values[2]).all()
    # image-plane columns renamed so they do not clash with x
    np.testing.assert_array_equal(ds.x_image.values, [512, 527, 542])
    np.testing.assert_array_equal(ds.v_image.values, [-0.03, -0.03, 0])
    assert ds.sigma.values[2] == -1 and "exy" in ds


def test_older_spacing_crlf_and_trailing_separator(tmp_path):
    text = VIC7.replace(", ", ",").replace('"X"', ' "X" ').replace("\n", ",\r\n")
    p = tmp_path / "old.csv"
    p.write_bytes(text.encode())
    ds = read_vic(p)
    np.testing.assert_allclose(ds.x.values[0], [-12.4875, 3.248, 0.126], rtol=0, atol=1e-14)
    assert ds.attrs["n_invalid"] == 1


def test_vic2d_export_is_refused(tmp_path):
    p = tmp_path / "v2d.csv"
    p.write_text('"x", "y", "u", "v", "sigma"\n1, 2, 0.1, 0.2, 0.01\n')
    with pytest.raises(FormatError, match="looks like a 2-D .* VIC-3D export with X, Y, Z, U, V, W"):
        read_vic(p)


def test_case_matters_and_missing_listed(tmp_path):
    p = tmp_path / "v.csv"
    p.write_text('"X", "Y", "Z", "u", "v", "w", "sigma"\n1, 2, 3, 0.1, 0.2, 0.3, 0.01\n')
    with pytest.raises(FormatError, match="missing columns 'U', 'V', 'W'; found 'X', 'Y', 'Z', 'u'"):
        read_vic(p)


def test_bad_cell_names_line_and_column(tmp_path):
    p = tmp_path / "v.csv"
    p.write_text(VIC7.replace("0.0101", "0.01O1"))
    with pytest.raises(FormatError, match="column 'sigma': cannot read '0.01O1'") as err:
        read_vic(p)
    assert err.value.line == 3


def test_short_row(tmp_path):
    p = tmp_path / "v.csv"
    p.write_text(VIC7 + "1, 2, 3\n")
    with pytest.raises(FormatError, match="found 3 fields, expected 14") as err:
        read_vic(p)
    assert err.value.line == 5


def test_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    xr_ = rng.uniform(-30, 30, (40, 3))
    d = rng.normal(0, 0.3, (40, 3))
    d[11] = np.nan
    for spacing in ("", " "):
        p = write_vic(tmp_path / f"r{len(spacing)}.csv", xr_, d, spacing=spacing)
        ds = read_dic(p)
        ok = np.arange(40) != 11
        np.testing.assert_allclose(ds.x.values[ok], (xr_ + d)[ok], rtol=0, atol=1e-6 + 1e-12)
        assert np.isnan(ds.x.values[11]).all()


def _vic_frame(path, rows, shift):
    """A VIC-3D frame holding the grid ``rows`` (indices into a 1-D grid) displaced by ``shift`` mm."""
    head = '"X", "Y", "Z", "U", "V", "W", "sigma", "x", "y"\n'
    body = "".join(f"{2.0 * r:.3f}, {0.5 * r:.3f}, 0.1, {shift}, 0, 0, 0.01, {500 + 15 * r}, 384\n" for r in rows)
    path.write_text(head + body)


def test_frame_with_a_row_fewer_keeps_points_on_their_own_positions(tmp_path):
    from irdic.ingest.dic import ingest_dic
    from irdic.store import open_store

    src = tmp_path / "vic"
    src.mkdir()
    _vic_frame(src / "spec_0.csv", range(5), 0.0)
    _vic_frame(src / "spec_1.csv", [0, 2, 3, 4], 1.0)  # grid point 1 not written in this frame
    ds = open_store(ingest_dic(src, tmp_path / "dic.zarr", time_source="frame_rate", frame_rate=1.0))
    np.testing.assert_array_equal(ds.point.values, np.arange(5))
    # each point moves by exactly the 1 mm shift; none lands on its neighbour (2 mm away)
    np.testing.assert_allclose(ds.x.values[1, :, 0] - ds.x.values[0, :, 0], [1, np.nan, 1, 1, 1], atol=1e-12)
    assert np.isnan(ds.x.values[1, 1]).all()


def test_frames_without_image_columns_and_different_rows_are_refused(tmp_path):
    from irdic.errors import DataError
    from irdic.ingest.dic import ingest_dic

    src = tmp_path / "vic"
    src.mkdir()
    for name, n in (("spec_0.csv", 3), ("spec_1.csv", 2)):
        write_vic(src / name, np.ones((n, 3)), np.zeros((n, 3)))
    with pytest.raises(DataError, match=r"spec_1\.csv: 2 rows, but spec_0\.csv has 3; .* identified by their row"):
        ingest_dic(src, tmp_path / "dic.zarr", time_source="frame_rate", frame_rate=1.0)
    assert not (tmp_path / "dic.zarr").exists()
