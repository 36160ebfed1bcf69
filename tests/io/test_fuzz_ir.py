"""Damaged IR files end in a DataArray or an IrdicError, never in another exception."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irdic.errors import IrdicError
from irdic.io.irb import count_irb_frames, read_irb
from irdic.io.irbis import read_irbis
from irdic.synthetic.writers import write_irb, write_irbis

# fixed examples in the normal run; IRDIC_FUZZ_EXAMPLES=5000 explores new ones
_EXPLORE = int(os.environ.get("IRDIC_FUZZ_EXAMPLES", "0"))
pytestmark = pytest.mark.filterwarnings("ignore::irdic.errors.IrdicWarning")
FUZZ = settings(max_examples=_EXPLORE or 150, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=not _EXPLORE, database=None)
_DIR = Path(tempfile.mkdtemp(prefix="irdic-fuzz-"))
atexit.register(shutil.rmtree, _DIR, ignore_errors=True)


def _irbis_bytes() -> bytes:
    x = 20.0 + np.arange(30.0).reshape(5, 6) * 0.37 - 3.0
    return write_irbis(_DIR / "base.txt", x, ms=40.0, frame_index=3, trailing_sep=True).read_bytes()


def _irb_bytes() -> bytes:
    x = 20.0 + np.arange(60.0).reshape(2, 5, 6) * 0.25
    return write_irb(_DIR / "base.irb", x, [0.0, 0.5]).read_bytes()


def _tiff_bytes(compression=None) -> bytes:
    import tifffile

    x = (20.0 + np.arange(60.0).reshape(2, 5, 6) * 0.25).astype(np.float32)
    path = _DIR / f"base_{compression}.tif"
    tifffile.imwrite(path, x, photometric="minisblack", compression=compression)
    return path.read_bytes()


IRBIS = _irbis_bytes()
IRB = _irb_bytes()
TIFF = _tiff_bytes()
TIFF_ZLIB = _tiff_bytes("zlib")


def _check(reader, raw: bytes, name: str, allow_nan: bool = False) -> None:
    path = _DIR / name
    path.write_bytes(raw)
    try:
        da = reader(path)
    except IrdicError:
        return
    assert isinstance(da, xr.DataArray)
    assert da.dims in (("v", "u"), ("time", "v", "u"))
    assert da.dtype == np.float32
    values = da.values[~np.isnan(da.values)] if allow_nan else da.values  # TIFF stacks keep NaN (masked pixels)
    assert np.isfinite(values).all()
    assert (values > -273.2).all()


def _mutations(base: bytes):
    n = len(base)
    truncate = st.integers(0, n - 1).map(lambda k: base[:k])
    flips = st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, 255)), min_size=1, max_size=6).map(
        lambda fl: bytes(_apply(base, fl)))
    return truncate, flips


def _apply(base: bytes, flips):
    out = bytearray(base)
    for pos, val in flips:
        out[pos] = val
    return out


_T_IRBIS, _F_IRBIS = _mutations(IRBIS)
_T_IRB, _F_IRB = _mutations(IRB)
_T_TIFF, _F_TIFF = _mutations(TIFF)
_T_TIFF_Z, _F_TIFF_Z = _mutations(TIFF_ZLIB)


@FUZZ
@given(st.one_of(_T_IRBIS, _F_IRBIS))
def test_irbis_truncated_or_flipped(raw):
    _check(read_irbis, raw, "f.txt")


@FUZZ
@given(st.sampled_from([b"\t", b";", b",", b" ", b"|", b"\t\t", b""]),
       st.sampled_from([b".", b",", b";", b"'"]),
       st.sampled_from([b"\r\n", b"\n", b"\r", b"\n\r"]))
def test_irbis_wrong_separators_and_line_ends(sep, mark, eol):
    i = IRBIS.index(b"[Data]")
    data = IRBIS[i:].replace(b".", b"\x00").replace(b"\t", sep).replace(b"\x00", mark).replace(b"\r\n", eol)
    _check(read_irbis, IRBIS[:i] + data, "s.txt")


@FUZZ
@given(st.data())
def test_irbis_deleted_or_duplicated_lines(data):
    lines = IRBIS.split(b"\r\n")
    k = data.draw(st.integers(0, len(lines) - 1))
    if data.draw(st.booleans()):
        lines = lines[:k] + lines[k + 1:]
    else:
        lines = lines[:k + 1] + lines[k:]
    _check(read_irbis, b"\r\n".join(lines), "l.txt")


def _read_irb_all(path):
    count_irb_frames(path)
    return read_irb(path)


@FUZZ
@given(st.one_of(_T_IRB, _F_IRB))
def test_irb_truncated_or_flipped(raw):
    _check(_read_irb_all, raw, "f.irb")


@FUZZ
@given(st.integers(0, len(IRB) - 1), st.integers(1, 64), st.booleans())
def test_irb_deleted_or_duplicated_bytes(start, length, delete):
    chunk = IRB[start:start + length]
    raw = IRB[:start] + IRB[start + length:] if delete else IRB[:start] + chunk + IRB[start:]
    _check(_read_irb_all, raw, "d.irb")


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(range(64, 64 + 2 * 32, 4)), st.integers(-2**31, 2**31 - 1)),
                min_size=1, max_size=3))
def test_irb_damaged_directory_fields(changes):
    raw = bytearray(IRB)
    for pos, value in changes:
        raw[pos:pos + 4] = int(value).to_bytes(4, "little", signed=True)
    _check(_read_irb_all, bytes(raw), "h.irb")


def _read_tiff(path):
    from irdic.io.stack import read_tiff

    return read_tiff(path, frame_rate=2.0)


@FUZZ
@given(st.one_of(_T_TIFF, _F_TIFF, _T_TIFF_Z, _F_TIFF_Z))
def test_tiff_truncated_or_flipped(raw):
    _check(_read_tiff, raw, "f.tif", allow_nan=True)


def test_fuzz_bases_are_valid():
    _check(read_irbis, IRBIS, "ok.txt")
    da = read_irb(_DIR / "base.irb")
    assert da.shape == (2, 5, 6)
    for name in ("base_None.tif", "base_zlib.tif"):
        assert _read_tiff(_DIR / name).shape == (2, 5, 6)
    with pytest.raises(IrdicError):
        read_irbis(_DIR / "base.irb")
