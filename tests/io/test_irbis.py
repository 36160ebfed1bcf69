"""IRBIS 3 text exports: the real samples, every locale variant, and clear errors."""

from __future__ import annotations

import datetime as dt
import io

import numpy as np
import pytest

from irdic.errors import ConfigError, FormatError, IrdicError, IrdicWarning
from irdic.io import read_ir
from irdic.io._decimals import parse_fast
from irdic.io.irbis import parse_irbis, parse_slow, read_irbis, read_irbis_header
from irdic.synthetic.writers import write_irbis


def _data_section(raw: bytes) -> bytes:
    i = raw.index(b"[Data]")
    return raw[raw.index(b"\n", i) + 1:]


# ----------------------------------------------------------------------------
# real samples
# ----------------------------------------------------------------------------
@pytest.mark.samples
def test_sample_frame_values_and_metadata(samples):
    path = samples / "irbis-text" / "GW_1_Z2_860.txt"
    da = read_irbis(path)
    assert da.dims == ("v", "u")
    assert da.shape == (439, 586)
    assert da.dtype == np.float32
    np.testing.assert_array_equal(da.u.values, np.arange(586))
    np.testing.assert_array_equal(da.v.values, np.arange(439))
    # corners as printed in the file (top row first)
    assert da.values[0, 0] == np.float32(17.41)
    assert da.values[0, 1] == np.float32(17.48)
    assert da.values[0, -1] == np.float32(16.31)
    assert da.values[-1, 0] == np.float32(16.89)
    assert da.values[-1, -1] == np.float32(15.89)
    # every value equals numpy's own parse of the data section
    ref = np.loadtxt(io.BytesIO(_data_section(path.read_bytes())), dtype=np.float64)
    np.testing.assert_array_equal(da.values, ref.astype(np.float32))
    assert float(da.time) == pytest.approx(34.35975, abs=1e-9)
    a = da.attrs
    assert a["units"] == "degC" and a["long_name"] == "temperature" and a["format"] == "irbis"
    assert a["source"] == str(path)
    assert a["frame_index"] == 860
    assert a["rec_datetime"] == "2021-04-13T12:38:33"
    assert a["distance"] == 2.0 and a["env_temp"] == 25.0
    assert a["shot_range"] == [15.0, 35.0] and a["calib_range"] == [9.85, 99.85]
    assert a["recording_file"] == "GW_1_Zyklus2_0001.irb"
    assert "sensor_width" not in a  # the export does not say
    assert 14.0 < float(da.min()) < float(da.max()) < 25.0


@pytest.mark.samples
def test_consecutive_sample_frames_are_25_hz(samples):
    a = read_irbis(samples / "irbis-text" / "GW_1_Z2_860.txt")
    b = read_irbis(samples / "irbis-text" / "GW_1_Z2_861.txt")
    assert b.attrs["frame_index"] - a.attrs["frame_index"] == 1
    assert float(b.time - a.time) == pytest.approx(0.040, abs=1e-9)
    # the same scene 40 ms later: small differences, not a different image
    assert float(np.abs(b - a).mean()) < 0.2


@pytest.mark.samples
def test_header_only_read_and_dispatcher(samples):
    path = samples / "irbis-text" / "GW_1_Z2_861.txt"
    h = read_irbis_header(path)
    assert (h["width"], h["height"], h["unit"], h["frame_index"]) == (586, 439, "degC", 861)
    assert h["ms"] == 34399.75 and h["start_pos"] is None
    da = read_ir(path)
    assert da.attrs["format"] == "irbis" and da.shape == (439, 586)


@pytest.mark.samples
def test_sample_rewritten_in_every_locale_reads_identically(samples, tmp_path):
    path = samples / "irbis-text" / "GW_1_Z2_860.txt"
    ref = read_irbis(path)
    raw = path.read_bytes()
    i = raw.index(b"[Data]")
    head, data = raw[:i], raw[i:]
    variants = {
        "german": data.replace(b".", b",").replace(b"\t", b";"),
        "tab_comma": data.replace(b".", b","),
        "lf": data.replace(b"\r\n", b"\n"),
        "no_trailing": data.replace(b"\t\r\n", b"\r\n"),
    }
    for name, body in variants.items():
        out = tmp_path / f"{name}.txt"
        h = head.replace(b"\r\n", b"\n") if name == "lf" else head
        out.write_bytes(h + body)
        da = read_irbis(out)
        np.testing.assert_array_equal(da.values, ref.values, err_msg=name)
        assert da.attrs["frame_index"] == 860


# ----------------------------------------------------------------------------
# round trips through the writer
# ----------------------------------------------------------------------------
def _field(shape=(7, 9), lo=-30.0, hi=150.0, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, shape)


@pytest.mark.parametrize("sep,decimal,trailing", [
    ("\t", ".", False), ("\t", ".", True), ("\t", ",", True), (";", ",", True),
    (";", ".", False), (" ", ".", False), (",", ".", False), (" ", ",", True),
])
@pytest.mark.parametrize("decimals", [0, 2, 3])
def test_roundtrip_variants(tmp_path, sep, decimal, trailing, decimals):
    x = _field()  # mixed widths and signs: -30 .. 150 °C
    path = write_irbis(tmp_path / "f.txt", x, sep=sep, decimal=decimal, trailing_sep=trailing,
                       decimals=decimals, ms=1234.5, frame_index=7)
    da = read_irbis(path)
    expected = np.array([[float(f"{v:.{decimals}f}") for v in row] for row in x], np.float32)
    np.testing.assert_array_equal(da.values, expected)
    assert np.abs(da.values - x).max() <= 0.5 * 10.0 ** -decimals + 1e-4
    assert float(da.time) == pytest.approx(1.2345)
    assert da.attrs["frame_index"] == 7


def test_roundtrip_crop_kelvin_and_metadata(tmp_path):
    x = _field((5, 4), 18.0, 40.0, seed=1)
    when = dt.datetime(2021, 4, 13, 12, 38, 33, 500000)
    path = write_irbis(tmp_path / "k.asc", x, temp_unit="K", start_pos=(100, 40), sensor_size=(1024, 768),
                       rec_datetime=when, filename="run_0001.irb", decimals=3,
                       parameters={"EnvTemp": 298.15, "Distance": 1.5, "Emissivity": 0.95})
    text = path.read_bytes()
    assert b"\r\n" in text and b"TempUnit=K" in text and b"StartPos=100;40" in text and b"EndPos=103;44" in text
    da = read_irbis(path)
    np.testing.assert_array_equal(da.u.values, np.arange(100, 104))
    np.testing.assert_array_equal(da.v.values, np.arange(40, 45))
    np.testing.assert_allclose(da.values, x, atol=0.0005 + 1e-4)
    _, kelvin = parse_irbis(path.read_bytes())  # float64 in the file's unit
    np.testing.assert_array_equal(da.values, (kelvin - 273.15).astype(np.float32))  # one rounding only
    a = da.attrs
    assert (a["sensor_width"], a["sensor_height"]) == (1024, 768)
    assert a["start_pos"] == [100, 40]
    assert a["rec_datetime"] == "2021-04-13T12:38:33"
    assert a["env_temp"] == pytest.approx(25.0, abs=1e-9)
    assert a["distance"] == 1.5 and a["emissivity"] == 0.95
    assert a["source_unit"] == "K"


def test_degree_sign_in_utf8_and_cp1252_and_bom(tmp_path):
    x = _field((3, 3), 20, 30)
    base = write_irbis(tmp_path / "a.txt", x).read_bytes()
    assert "TempUnit=°C".encode("cp1252") in base
    for name, raw in {"utf8": base.replace(b"\xb0", "°".encode("utf-8")),
                      "bom": b"\xef\xbb\xbf" + base.replace(b"\xb0", "°".encode("utf-8")),
                      "cp1252": base}.items():
        p = tmp_path / f"{name}.txt"
        p.write_bytes(raw)
        np.testing.assert_allclose(read_irbis(p).values, x, atol=0.0051, err_msg=name)


def test_extra_sections_blank_lines_and_cr_only(tmp_path):
    x = _field((4, 5), 10, 20)
    raw = write_irbis(tmp_path / "a.txt", x).read_bytes()
    i = raw.index(b"[Data]")
    meas = b"[MeasDefs]\r\nROI1=Rect;10;10;20;20\r\nMean=17.5\r\n\r\n"
    variants = {
        "measdefs_before": raw[:i] + meas + raw[i:],
        "measdefs_after": raw + b"\r\n" + meas,
        "blank_lines": raw[:i] + raw[i:].replace(b"[Data]\r\n", b"[Data]\r\n\r\n") + b"\r\n\r\n",
        "cr_only": raw.replace(b"\r\n", b"\r"),
    }
    for name, content in variants.items():
        p = tmp_path / f"{name}.txt"
        p.write_bytes(content)
        np.testing.assert_allclose(read_irbis(p).values, x, atol=0.0051, err_msg=name)


def test_exponent_notation_goes_through_exact_path(tmp_path):
    p = tmp_path / "e.txt"
    p.write_bytes(b"[Settings]\r\nImageWidth=2\r\nImageHeight=2\r\nTempUnit=\xb0C\r\n[Data]\r\n"
                  b"1.5e1\t2.25E+01\r\n-3e-1\t.5\r\n")
    np.testing.assert_array_equal(read_irbis(p).values, np.array([[15.0, 22.5], [-0.3, 0.5]], np.float32))


def test_fast_and_exact_parsers_agree_on_mixed_numbers():
    rng = np.random.default_rng(3)
    cells = []
    for _ in range(40 * 30):
        v = rng.uniform(-500, 500)
        d = int(rng.integers(0, 5))
        cells.append(f"{v:.{d}f}")
    rows = ["\t".join(cells[r * 30:(r + 1) * 30]) for r in range(40)]
    data = ("\r\n".join(rows) + "\r\n").encode()
    fast = parse_fast(data, b"\t", ord("."), ord("\n"), 1200)
    assert fast is not None  # the vectorised path handles mixed decimals
    values, per_line = fast
    slow = parse_slow(data, b"\t", ord("."), ord("\n"), 1, 30, 40, "x", None, None)
    np.testing.assert_array_equal(values, slow.ravel())
    np.testing.assert_array_equal(values, [float(c) for c in cells])
    assert set(per_line[per_line > 0].tolist()) == {30}


def test_fahrenheit_header(tmp_path):
    p = tmp_path / "f.txt"
    p.write_bytes(b"[Settings]\nImageWidth=2\nImageHeight=1\nTempUnit=\xb0F\n[Data]\n32.0\t212.0\n")
    np.testing.assert_allclose(read_irbis(p).values, [[0.0, 100.0]], atol=1e-4)


# ----------------------------------------------------------------------------
# errors
# ----------------------------------------------------------------------------
def _good(tmp_path, shape=(3, 4)):
    return write_irbis(tmp_path / "good.txt", _field(shape, 15, 25)).read_bytes()


def _write(tmp_path, raw, name="bad.txt"):
    p = tmp_path / name
    p.write_bytes(raw)
    return p


def test_missing_data_section(tmp_path):
    raw = _good(tmp_path)
    p = _write(tmp_path, raw[:raw.index(b"[Data]")])
    with pytest.raises(FormatError, match=r"no \[Data\] section") as e:
        read_irbis(p)
    assert e.value.path == str(p)


def test_width_mismatch_names_the_data_line(tmp_path):
    raw = _good(tmp_path).replace(b"ImageWidth=4", b"ImageWidth=5")
    p = _write(tmp_path, raw)
    with pytest.raises(FormatError, match=r"data row 1 has 4 values, expected ImageWidth=5 \(line 3\)") as e:
        read_irbis(p)
    data_line = raw[:raw.index(b"[Data]")].count(b"\n") + 2
    assert e.value.line == data_line
    assert f"line {data_line}" in str(e.value) and str(p) in str(e.value)


def test_height_mismatch(tmp_path):
    p = _write(tmp_path, _good(tmp_path).replace(b"ImageHeight=3", b"ImageHeight=4"))
    with pytest.raises(FormatError, match=r"found 3 data rows, expected ImageHeight=4 \(line 4\).*truncated"):
        read_irbis(p)


def test_non_numeric_cell_names_line_and_column(tmp_path):
    raw = _good(tmp_path)
    lines = raw.split(b"\r\n")
    k = lines.index(b"[Data]") + 2  # second data row
    cells = lines[k].split(b"\t")
    cells[2] = b"17.4x"
    lines[k] = b"\t".join(cells)
    p = _write(tmp_path, b"\r\n".join(lines))
    with pytest.raises(FormatError, match=r"data row 2, column 3: '17.4x' is not a number") as e:
        read_irbis(p)
    assert e.value.line == k + 1


def test_truncated_file(tmp_path):
    raw = _good(tmp_path)
    p = _write(tmp_path, raw[:-9])  # cut inside the last row
    with pytest.raises(FormatError, match=r"data row 3 has \d values, expected ImageWidth=4.*truncated") as e, \
            pytest.warns(IrdicWarning, match="no line end"):
        read_irbis(p)
    assert e.value.line == raw.count(b"\n")


def test_cut_inside_the_last_value_warns(tmp_path):
    raw = _good(tmp_path)
    full = read_irbis(_write(tmp_path, raw, "full.txt")).values
    with pytest.warns(IrdicWarning, match="the last data row has no line end"):
        cut = read_irbis(_write(tmp_path, raw[:-3])).values  # drops CRLF and the last digit
    np.testing.assert_array_equal(cut.ravel()[:-1], full.ravel()[:-1])
    assert abs(cut[-1, -1] - full[-1, -1]) < 0.1


def test_ragged_rows_with_right_total_are_refused(tmp_path):
    raw = _good(tmp_path, (2, 4))
    lines = raw.split(b"\r\n")
    k = lines.index(b"[Data]") + 1
    c0, c1 = lines[k].split(b"\t"), lines[k + 1].split(b"\t")
    lines[k], lines[k + 1] = b"\t".join(c0 + c1[:1]), b"\t".join(c1[1:])  # 5 + 3 = 8 values
    with pytest.raises(FormatError, match=r"data row 1 has 5 values"):
        read_irbis(_write(tmp_path, b"\r\n".join(lines)))


@pytest.mark.parametrize("cell", [b"nan", b"inf", b"1_000", b"--1", b"1-2", b"1.2.3", b"-", b"."])
def test_odd_cells_are_refused(tmp_path, cell):
    raw = _good(tmp_path)
    i = raw.index(b"[Data]\r\n") + 8
    j = raw.index(b"\t", i)
    with pytest.raises(FormatError, match=r"data row 1, column 1"):
        read_irbis(_write(tmp_path, raw[:i] + cell + raw[j:]))


def test_empty_cell_between_separators(tmp_path):
    raw = _good(tmp_path)
    i = raw.index(b"[Data]\r\n") + 8
    j = raw.index(b"\t", i)
    with pytest.raises(FormatError, match=r"column 1: '' is not a number"):
        read_irbis(_write(tmp_path, raw[:i] + raw[j:]))


def test_bad_header_values(tmp_path):
    raw = _good(tmp_path)
    with pytest.raises(FormatError, match=r"ImageWidth='four' is not an integer") as e:
        read_irbis(_write(tmp_path, raw.replace(b"ImageWidth=4", b"ImageWidth=four")))
    assert e.value.line == 3
    with pytest.raises(FormatError, match=r"TempUnit='lux' is not a temperature unit"):
        read_irbis(_write(tmp_path, raw.replace("TempUnit=°C".encode("cp1252"), b"TempUnit=lux"), "u.txt"))
    with pytest.raises(FormatError, match=r"ms='soon' is not a number"):
        read_irbis(_write(tmp_path, raw.replace(b"[Data]", b"ms=soon\r\n[Data]"), "m.txt"))


def test_below_absolute_zero_means_wrong_unit(tmp_path):
    p = tmp_path / "z.txt"
    p.write_bytes(b"[Settings]\nImageWidth=1\nImageHeight=1\nTempUnit=K\n[Data]\n-5.0\n")
    with pytest.raises(FormatError, match="below absolute zero"):
        read_irbis(p)


def test_empty_and_missing_files(tmp_path):
    with pytest.raises(FormatError, match="file is empty"):
        read_irbis(_write(tmp_path, b""))
    with pytest.raises(FormatError, match="file not found"):
        read_irbis(tmp_path / "nope.txt")
    with pytest.raises(FormatError, match="holds no values"):
        read_irbis(_write(tmp_path, b"[Settings]\nImageWidth=2\n[Data]\n\n\n", "e.txt"))
    with pytest.raises(FormatError) as e:
        parse_irbis(b"[Data]")
    assert isinstance(e.value, IrdicError)


@pytest.mark.parametrize("kwargs,match", [
    ({"sep": "|"}, "sep='|'"),
    ({"decimal": ";"}, "decimal=';'"),
    ({"sep": ",", "decimal": ","}, "could not be told apart"),
    ({"decimals": 9}, "decimals=9"),
    ({"temp_unit": "F"}, "temp_unit='F'"),
    ({"start_pos": (-1, 0)}, "non-negative"),
    ({"start_pos": (0, 0), "sensor_size": (2, 2)}, "does not fit"),
    ({"frame_index": -3}, "frame_index=-3"),
    ({"rec_datetime": "2021-01-01"}, "datetime.datetime"),
])
def test_writer_argument_errors(tmp_path, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        write_irbis(tmp_path / "w.txt", np.zeros((3, 3)), **kwargs)


def test_writer_refuses_non_finite_and_wrong_shape(tmp_path):
    x = np.zeros((2, 3))
    x[1, 2] = np.nan
    with pytest.raises(ConfigError, match=r"temperature\[1, 2\] = nan"):
        write_irbis(tmp_path / "w.txt", x)
    with pytest.raises(ConfigError, match="2-D"):
        write_irbis(tmp_path / "w.txt", np.zeros((2, 2, 2)))


def test_empty_cell_plus_extra_value_is_not_shifted_silently(tmp_path):
    raw = _good(tmp_path)
    lines = raw.split(b"\r\n")
    k = lines.index(b"[Data]") + 1
    cells = lines[k].split(b"\t")
    lines[k] = b"\t".join(cells[:1] + [b""] + cells[1:3])  # a, '', b, c  (4 cells, one empty)
    with pytest.raises(FormatError, match=r"data row 1, column 2: '' is not a number"):
        read_irbis(_write(tmp_path, b"\r\n".join(lines)))
    lines[k] = b"\t".join(cells[:1] + [b""] + cells[1:])  # 5 cells, 4 of them numbers
    with pytest.raises(FormatError, match=r"data row 1 has 5 values"):
        read_irbis(_write(tmp_path, b"\r\n".join(lines), "b.txt"))


def test_header_without_data_is_refused_after_a_bounded_read(tmp_path):
    # a 4 MB file that starts like an export but never reaches [Data]: the old
    # header reader searched the whole growing text again for every 64 KiB read
    # (quadratic); now it stops after 1 MiB with a message saying why
    p = _write(tmp_path, b"[Settings]\r\nImageWidth=2\r\n" + b"Comment=xxxxxxxxxxxxxxxxxxxxxxxx\r\n" * 120_000)
    with pytest.raises(FormatError, match=r"no \[Data\] line in the first 1024 KiB") as e:
        read_irbis_header(p)
    assert e.value.path == str(p)


@pytest.mark.parametrize("pad", [65536 - 12, 65536 - 9, 65536 - 3, 65536, 2 * 65536 - 5])
def test_header_marker_cut_by_a_read_boundary_is_found(tmp_path, pad):
    head = b"[Settings]\nImageWidth=2\nImageHeight=1\n[Parameter]\nComment="
    raw = head + b"y" * (pad - len(head) - 1) + b"\n[Data]\n1.5\t2.5\n"
    p = _write(tmp_path, raw)
    assert read_irbis_header(p)["width"] == 2
    assert read_irbis(p).values.tolist() == [[1.5, 2.5]]
    lower = _write(tmp_path, raw.replace(b"[Data]", b"[DATA]"), "l.txt")
    assert read_irbis_header(lower)["height"] == 1


def _fifo(tmp_path):
    """A named pipe, and a writer thread that unblocks a reader that opens it (old code)."""
    import os
    import threading

    fifo = tmp_path / "pipe.txt"
    os.mkfifo(fifo)

    def writer():  # only returns once a reader opened the pipe
        with open(fifo, "wb") as fh:
            fh.write(b"[Settings]\nImageWidth=1\nImageHeight=1\n[Data]\n1.0\n")

    t = threading.Thread(target=writer, daemon=True)
    t.start()
    return fifo, t


def _release(fifo, t):
    import os

    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # lets the writer thread finish
    t.join(5)
    os.close(fd)


@pytest.mark.parametrize("reader", ["read_ir", "read_irbis", "read_irbis_header", "read_dic"])
def test_named_pipes_are_refused_before_opening(tmp_path, reader):
    import irdic.io as io_

    fn = {"read_ir": io_.read_ir, "read_irbis": read_irbis, "read_irbis_header": read_irbis_header,
          "read_dic": io_.read_dic}[reader]
    fifo, t = _fifo(tmp_path)
    try:
        with pytest.raises(FormatError, match=r"pipe\.txt: is a named pipe \(FIFO\), not a regular file"):
            fn(fifo)
    finally:
        _release(fifo, t)


def test_devices_are_refused(tmp_path):
    import os

    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    with pytest.raises(FormatError, match=r"/dev/zero: is a device, not a regular file"):
        read_ir("/dev/zero")
