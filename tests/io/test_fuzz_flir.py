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


def test_fuzz_bases_are_valid():
    for name in ("base.seq", "base.csq", "base.jpg"):
        da = read_ir(_DIR / name)
        assert np.abs(da.values - (_T if da.ndim == 3 else _T[0])).max() < 0.01
