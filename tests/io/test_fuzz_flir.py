"""Damaged FLIR files (.seq, .csq, R-JPEG) end in a DataArray or an IrdicError, never in another exception."""

from __future__ import annotations

import atexit
import os
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irdic.errors import IrdicError
from irdic.io import read_ir
from irdic.io.flir import iter_flir_headers
from irdic.synthetic.writers import write_flir

# fixed examples in the normal run; IRDIC_FUZZ_EXAMPLES=5000 explores new ones
_EXPLORE = int(os.environ.get("IRDIC_FUZZ_EXAMPLES", "0"))
pytestmark = pytest.mark.filterwarnings("ignore::irdic.errors.IrdicWarning")
FUZZ = settings(max_examples=_EXPLORE or 150, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=not _EXPLORE, database=None)
_DIR = Path(tempfile.mkdtemp(prefix="irdic-fuzz-flir-"))
atexit.register(shutil.rmtree, _DIR, ignore_errors=True)

_T = 20.0 + np.arange(2 * 6 * 8, dtype=float).reshape(2, 6, 8) * 0.3
SEQ = write_flir(_DIR / "base.seq", _T).read_bytes()
CSQ = write_flir(_DIR / "base.csq", _T, encoding="jpegls").read_bytes()
RJPG = write_flir(_DIR / "base.jpg", _T[0], jpeg=True, encoding="png", header_order=">").read_bytes()
#: a ThermaCAM EX320-like picture: big-endian header and records, PNG samples as PNG says, uncompressed sibling
EX320 = write_flir(_DIR / "ex320.jpg", _T[1], jpeg=True, encoding="png", header_order=">", record_order=">",
                   png_swap=False).read_bytes()
RAWJPG = write_flir(_DIR / "raw.jpg", _T[1], jpeg=True, encoding="raw", header_order=">").read_bytes()
#: byte offsets of the FFF headers and directories of the .seq (the fields most worth damaging)
_HEADS = [h["offset"] for h in iter_flir_headers(_DIR / "base.seq")]
_FIELDS = [o + k for o in _HEADS for k in range(0x14, 0x20, 4)] + \
    [o + 64 + 32 * e + k for o in _HEADS for e in range(2) for k in (0, 16, 20)]


def _check(raw: bytes, name: str) -> None:
    path = _DIR / name
    path.write_bytes(raw)
    try:
        da = read_ir(path, format="flir")
    except IrdicError:
        return
    assert isinstance(da, xr.DataArray)
    assert da.dims in (("v", "u"), ("time", "v", "u"))
    assert da.dtype == np.float32
    values = da.values[~np.isnan(da.values)]  # counts too cold for a temperature are NaN
    assert np.isfinite(values).all() and (values > -273.2).all()


def _mutations(base: bytes):
    n = len(base)
    truncate = st.integers(0, n - 1).map(lambda k: base[:k])
    flips = st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, 255)), min_size=1, max_size=6).map(
        lambda fl: bytes(_apply(base, fl)))
    return st.one_of(truncate, flips)


def _apply(base: bytes, flips):
    out = bytearray(base)
    for pos, val in flips:
        out[pos] = val
    return out


@FUZZ
@given(_mutations(SEQ))
def test_seq_truncated_or_flipped(raw):
    _check(raw, "f.seq")


@FUZZ
@given(_mutations(CSQ))
def test_csq_truncated_or_flipped(raw):
    _check(raw, "f.csq")


@FUZZ
@given(_mutations(RJPG))
def test_rjpeg_truncated_or_flipped(raw):
    _check(raw, "f.jpg")


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(_FIELDS), st.integers(0, 2**32 - 1)), min_size=1, max_size=3),
       st.booleans())
def test_seq_damaged_header_and_directory_fields(changes, big):
    raw = bytearray(SEQ)
    for pos, value in changes:
        raw[pos:pos + 4] = struct.pack(">I" if big else "<I", value)
    _check(bytes(raw), "h.seq")


@FUZZ
@given(_mutations(EX320))
def test_big_endian_rjpeg_truncated_or_flipped(raw):
    _check(raw, "b.jpg")


@FUZZ
@given(_mutations(RAWJPG))
def test_uncompressed_rjpeg_truncated_or_flipped(raw):
    _check(raw, "u.jpg")


#: the camera-info fields of the .seq's frames: object parameters, Planck constants, raw range, time stamp
_CAM = [h["offset"] for h in iter_flir_headers(_DIR / "base.seq")]
_CAM_AT = [o + (64 + 2 * 32 + (128 if k == 0 else 0)) for k, o in enumerate(_CAM)]
_CAM_FIELDS = [0x20, 0x24, 0x28, 0x2c, 0x30, 0x34, 0x3c, 0x58, 0x5c, 0x60, 0x70, 0x74, 0x78, 0x7c, 0x80, 0x30c]


@FUZZ
@given(st.lists(st.tuples(st.integers(0, len(_CAM_AT) - 1), st.sampled_from(_CAM_FIELDS),
                          st.floats(width=32, allow_nan=True, allow_infinity=True)), min_size=1, max_size=4),
       st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1))
def test_seq_camera_info_values(changes, planck_o, seconds):
    """Any float in the object parameters and constants, any PlanckO and time: temperatures or a clear error."""
    raw = bytearray(SEQ)
    assert all(raw[c:c + 2] == b"\x02\x00" for c in _CAM_AT)  # the records start where the writer puts them
    for frame, off, value in changes:
        struct.pack_into("<f", raw, _CAM_AT[frame] + off, value)
    struct.pack_into("<i", raw, _CAM_AT[-1] + 0x308, planck_o)
    struct.pack_into("<I", raw, _CAM_AT[0] + 0x384, seconds)
    _check(bytes(raw), "c.seq")


@FUZZ
@given(st.integers(40, 3000), st.permutations(range(64)), st.lists(st.booleans(), min_size=64, max_size=64),
       st.lists(st.integers(0, 63), max_size=3))
def test_rjpeg_segment_splitting(chunk, order, fills, duplicates):
    """The FFF block in any chunk size and order, with fill bytes and repeated chunks: the same temperatures."""
    import imagecodecs

    from irdic.io.flir_jpeg import fff_from_jpeg

    block = fff_from_jpeg(_DIR / "base.jpg")
    parts = [block[k:k + chunk] for k in range(0, len(block), chunk)]
    if len(parts) > 64:
        return
    segs = {k: b"\xe1" + struct.pack(">H", 10 + len(c)) + b"FLIR\x00\x01" + bytes([k, len(parts) - 1]) + c
            for k, c in enumerate(parts)}
    keys = [k for k in order if k < len(parts)] + [k for k in duplicates if k < len(parts)]
    app1 = b"".join((b"\xff\xff" if fills[i % 64] else b"\xff") + segs[k] for i, k in enumerate(keys))
    picture = imagecodecs.jpeg8_encode(np.full((8, 8), 128, np.uint8))
    path = _DIR / "s.jpg"
    path.write_bytes(picture[:2] + app1 + picture[2:])
    np.testing.assert_array_equal(read_ir(path).values, read_ir(_DIR / "base.jpg").values)


def test_fuzz_bases_are_valid():
    for name in ("ex320.jpg", "raw.jpg"):
        assert np.abs(read_ir(_DIR / name).values - _T[1]).max() < 0.01
    for name in ("base.seq", "base.csq", "base.jpg"):
        da = read_ir(_DIR / name)
        assert np.abs(da.values - (_T if da.ndim == 3 else _T[0])).max() < 0.01
