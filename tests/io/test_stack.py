"""Temperature stacks as TIFF and .npy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import tifffile

from irdic.errors import ConfigError, FormatError, IrdicWarning
from irdic.io import read_ir
from irdic.io.stack import normalise_unit, read_npy, read_tiff, temperature_dataarray


@pytest.fixture
def stack():
    v, u = np.mgrid[0:6, 0:8]
    return np.stack([20.0 + 0.5 * u + 0.25 * v + k for k in range(3)]).astype(np.float32)


def test_tiff_stack_with_frame_rate(tmp_path, stack):
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, stack, photometric="minisblack")
    da = read_tiff(path, frame_rate=4.0, time_offset=10.0)
    assert da.dims == ("time", "v", "u") and da.shape == (3, 6, 8) and da.dtype == np.float32
    np.testing.assert_array_equal(da.values, stack)
    np.testing.assert_allclose(da.time.values, [10.0, 10.25, 10.5])
    # rows = v downwards, columns = u: value at (v=2, u=5) of frame 1
    assert float(da.isel(time=1).sel(v=2, u=5)) == 20.0 + 2.5 + 0.5 + 1
    assert da.attrs["units"] == "degC" and da.attrs["frame_rate"] == 4.0
    with pytest.warns(IrdicWarning, match="no frame_rate"):
        assert read_ir(path).shape == (3, 6, 8)  # the dispatcher detects TIFF


def test_single_page_tiff_in_kelvin(tmp_path, stack):
    path = tmp_path / "k.tiff"
    tifffile.imwrite(path, (stack[0] + 273.15).astype(np.float64))
    da = read_tiff(path, temp_unit="K")
    assert da.dims == ("v", "u")
    np.testing.assert_allclose(da.values, stack[0], atol=2e-5)
    assert "time" not in da.coords


def test_stack_without_frame_rate_warns(tmp_path, stack):
    path = tmp_path / "s.npy"
    np.save(path, stack)
    with pytest.warns(IrdicWarning, match="no frame_rate given"):
        da = read_npy(path)
    assert da.dims == ("time", "v", "u") and "time" not in da.coords


def test_npy_frame_and_fahrenheit(tmp_path):
    path = tmp_path / "f.npy"
    np.save(path, np.array([[32.0, 212.0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        da = read_npy(path, temp_unit="degF")
    np.testing.assert_allclose(da.values, [[0.0, 100.0]], atol=1e-5)


def test_nan_pixels_are_kept(tmp_path, stack):
    s = stack.copy()
    s[1, 2, 3] = np.nan
    path = tmp_path / "n.npy"
    np.save(path, s)
    da = read_npy(path, frame_rate=1.0)
    assert np.isnan(da.values[1, 2, 3]) and np.isnan(da.values).sum() == 1


def test_integer_counts_are_refused_unless_allowed(tmp_path):
    counts = np.full((4, 5), 7312, np.uint16)
    path = tmp_path / "c.tif"
    tifffile.imwrite(path, counts)
    with pytest.raises(FormatError, match=r"holds integers \(uint16\); these are usually raw detector counts"):
        read_tiff(path)
    da = read_tiff(path, temp_unit="K", allow_integer=True)
    np.testing.assert_allclose(da.values, 7312 - 273.15, rtol=1e-6)


@pytest.mark.parametrize("arr,match", [
    (np.zeros((2, 2, 2, 2)), r"4-D array"),
    (np.zeros(5), r"1-D array"),
    (np.zeros((2, 2), complex), "complex128 values; expected floating-point"),
    (np.zeros((2, 2), bool), "bool values"),
    (np.full((2, 2), np.inf), "non-finite temperature inf at index"),
    (np.zeros((0, 3)), "empty array"),
])
def test_npy_refusals(tmp_path, arr, match):
    path = tmp_path / "x.npy"
    np.save(path, arr)
    with pytest.raises(FormatError, match=match) as e:
        read_npy(path)
    assert e.value.path == str(path)


def test_below_absolute_zero_and_bad_arguments(tmp_path, stack):
    path = tmp_path / "s.npy"
    np.save(path, stack[0] - 30.0)  # -10 .. -3: fine in °C, impossible in K
    assert float(read_npy(path).min()) == -10.0
    with pytest.raises(FormatError, match="below absolute zero"):
        read_npy(path, temp_unit="K")
    with pytest.raises(ConfigError, match="temp_unit='lux'"):
        read_npy(path, temp_unit="lux")
    with pytest.raises(ConfigError, match="frame_rate must be positive"):
        read_npy(path, frame_rate=0)
    with pytest.raises(ConfigError, match="time_offset must be a number"):
        read_npy(path, time_offset="soon")


def test_not_a_tiff_or_npy(tmp_path):
    p = tmp_path / "x.tif"
    p.write_bytes(b"II*\x00garbage")
    with pytest.raises(FormatError, match="cannot read as TIFF"):
        read_tiff(p)
    q = tmp_path / "x.npy"
    q.write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(FormatError, match="cannot read as a .npy array"):
        read_npy(q)
    z = tmp_path / "x.npz"
    np.savez(z, a=np.zeros((2, 2)))
    with pytest.raises(FormatError, match="is a .npz archive"):
        read_npy(z)
    o = tmp_path / "o.npy"
    np.save(o, np.array([{"a": 1}], dtype=object))
    with pytest.raises(FormatError, match="cannot read as a .npy array"):
        read_npy(o)


def test_rgb_tiff_is_refused(tmp_path):
    p = tmp_path / "rgb.tif"
    tifffile.imwrite(p, np.zeros((4, 5, 3), np.float32), photometric="rgb")
    with pytest.raises(FormatError, match="colour/multi-sample pages.*photometric='minisblack'"):
        read_tiff(p)


def test_units_and_layout_helpers():
    assert normalise_unit("°C") == normalise_unit("Â°C") == normalise_unit("degC") == "degC"
    assert normalise_unit("K") == "K" and normalise_unit("°F") == "degF" and normalise_unit("lux") is None
    da = temperature_dataarray(np.zeros((2, 3)), u0=10, v0=5, time=1.5)
    assert da.u.values.tolist() == [10, 11, 12] and da.v.values.tolist() == [5, 6] and float(da.time) == 1.5


def _ome_referencing(tmp_path, target):
    """A one-page OME-TIFF whose OME-XML puts the page of ``target`` (any path) in its series as frame 1."""
    uuid_main, uuid_other = "urn:uuid:00000000-0000-0000-0000-000000000001", \
        "urn:uuid:00000000-0000-0000-0000-000000000002"
    xml = (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" '
        f'UUID="{uuid_main}">'
        '<Image ID="Image:0"><Pixels ID="Pixels:0" DimensionOrder="XYCZT" Type="float" '
        'SizeX="5" SizeY="4" SizeC="1" SizeZ="1" SizeT="2" BigEndian="false">'
        '<Channel ID="Channel:0:0" SamplesPerPixel="1"/>'
        f'<TiffData FirstT="0" IFD="0" PlaneCount="1"><UUID FileName="main.ome.tif">{uuid_main}</UUID></TiffData>'
        f'<TiffData FirstT="1" IFD="0" PlaneCount="1"><UUID FileName="{target}">{uuid_other}</UUID></TiffData>'
        '</Pixels></Image></OME>'
    )
    p = tmp_path / "main.ome.tif"
    tifffile.imwrite(p, np.full((4, 5), 20.0, np.float32), description=xml, metadata=None)
    return p


def test_ome_references_to_other_files_are_not_followed(tmp_path):
    secret = tmp_path / "elsewhere" / "secret.tif"
    secret.parent.mkdir()
    tifffile.imwrite(secret, np.full((4, 5), 99.0, np.float32))
    for target in (str(secret), "elsewhere/secret.tif"):
        p = _ome_referencing(tmp_path, target)
        da = read_tiff(p)
        assert da.dims == ("v", "u") and da.shape == (4, 5)
        assert (da.values == 20.0).all()  # nothing of the other file
    # the file really is a multi-file OME-TIFF: tifffile alone follows the reference
    with tifffile.TiffFile(p) as tif:
        assert tif.series[0].shape == (2, 4, 5) and tif.series[0].asarray().max() == 99.0


def test_tiff_that_decodes_to_far_more_than_its_size_is_refused(tmp_path, monkeypatch):
    import irdic.io.stack as stack_mod

    p = tmp_path / "bomb.tif"
    tifffile.imwrite(p, np.zeros((8, 512, 512), np.float32), compression="zlib", photometric="minisblack")
    size = p.stat().st_size
    assert 8 * 512 * 512 * 4 > 32 * size  # a zlib ratio no temperature field reaches
    monkeypatch.setattr(stack_mod, "MAX_DECODE_FLOOR", 2**20)  # the 256 MiB floor scaled down for the test
    with pytest.raises(FormatError, match=r"bomb\.tif: its pages \(shape \(8, 512, 512\), float32\) would decode to "
                                          r"8 MiB from a \d+ kB file; irdic reads TIFFs that decode to at most 32 "
                                          r"times their size or 1 MiB"):
        read_tiff(p)
    # an uncompressed stack of the same size is read
    q = tmp_path / "plain.tif"
    tifffile.imwrite(q, np.full((8, 512, 512), 20.0, np.float32), photometric="minisblack")
    assert read_tiff(q, frame_rate=1.0).shape == (8, 512, 512)


def test_npy_header_larger_than_the_file_is_refused(tmp_path):
    import io

    buf = io.BytesIO()
    np.save(buf, np.zeros((2, 3, 4), np.float32))
    p = tmp_path / "lie.npy"
    p.write_bytes(buf.getvalue().replace(b"(2, 3, 4)", b"(2000, 3000, 4)"))  # 96 bytes of data for 96 MB
    with pytest.raises(FormatError, match=r"lie\.npy: cannot read as a \.npy array \(mmap length is greater"):
        read_npy(p)
