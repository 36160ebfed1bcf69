"""Fuzzing the DIC and marker readers: damaged files end in a Dataset or an IrdicError.

Each case takes a small valid file, applies one to three damages (truncation,
byte changes, a wrong separator, deleted or duplicated lines) and reads it.
Any exception other than :class:`irdic.errors.IrdicError` fails the test, and
so does a Dataset that breaks the common layout.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irdic.errors import IrdicError
from irdic.io import read_dic
from irdic.io.dice import read_dice
from irdic.io.markers import read_markers
from irdic.io.nodemap import read_nodemap
from irdic.io.table import read_table
from irdic.io.vic import read_vic
from irdic.synthetic.writers import write_dice, write_markers, write_nodemap, write_vic

SETTINGS = settings(max_examples=200, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

_rng = np.random.default_rng(11)
_N = 8
_XU = _rng.uniform(-20, 20, (_N, 3))
_D = _rng.normal(0, 0.1, (_N, 3))
_D[2] = np.nan


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    """One small valid file per format, as bytes."""
    d = tmp_path_factory.mktemp("fuzz_bases")
    files = {
        "nodemap": write_nodemap(d / "n_0_3.txt", np.arange(1, _N + 1), _XU, _D, stage_index=3, relative_time=1.5,
                                 stage_name="Stage 3", stage_date="2021-04-13T12:38:34",
                                 strains=_rng.normal(0, 1, (_N, 4)), decimals=5),
        "dice": write_dice(d / "DICe_solution_3.txt", np.arange(_N), _XU, _D,
                           image_coordinates=_rng.uniform(0, 999, (_N, 2)), header_lines=["DICe", "Frame: 3"]),
        "vic": write_vic(d / "v.csv", _XU, _D, spacing=" "),
        "markers": write_markers(d / "m.txt", np.arange(1, _N + 1), _XU, decimals=4),
    }
    (d / "t.csv").write_text("# preamble\nid;X [mm];Y [mm];Z [mm];q\n"
                             + "".join(f"{i};{a:.3f};{b:.3f};{c:.3f};x{i}\n" for i, (a, b, c) in enumerate(_XU)))
    files["table"] = d / "t.csv"
    return {k: p.read_bytes() for k, p in files.items()}


def _table(p):
    return read_table(p, columns={"id": "id", "x": "X [mm]", "y": "Y [mm]", "z": "Z [mm]"})


READERS = {"nodemap": read_nodemap, "dice": read_dice, "vic": read_vic, "markers": read_markers, "table": _table}
SEPS = {"nodemap": b";", "dice": b",", "vic": b",", "markers": b";", "table": b";"}


@st.composite
def damaged(draw, raw: bytes, sep: bytes) -> bytes:
    """``raw`` with one to three random damages."""
    data = raw
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["truncate", "bytes", "separator", "delete", "duplicate"]))
        if kind == "truncate":
            data = data[: draw(st.integers(0, max(len(data) - 1, 0)))]
        elif kind == "bytes":
            if not data:
                continue
            buf = bytearray(data)
            for _ in range(draw(st.integers(1, 4))):
                buf[draw(st.integers(0, len(buf) - 1))] = draw(st.integers(0, 255))
            data = bytes(buf)
        elif kind == "separator":
            data = data.replace(sep, draw(st.sampled_from([b",", b";", b"\t", b" ", b"|", b".", b""])))
        else:
            lines = data.split(b"\n")
            k = draw(st.integers(0, len(lines) - 1))
            if kind == "delete":
                del lines[k]
            else:
                lines.insert(draw(st.integers(0, len(lines))), lines[k])
            data = b"\n".join(lines)
    return data


def _check(result: xr.Dataset, fmt: str) -> None:
    assert isinstance(result, xr.Dataset)
    dim = "marker" if fmt == "markers" else "point"
    assert result.x.dims == (dim, "component") and result.x.shape[1] == 3
    assert result.x.dtype == np.float64
    ids = result[dim].values
    assert ids.dtype == np.int64 and np.unique(ids).size == ids.size
    if fmt == "markers":
        assert np.isfinite(result.x.values).all()
    else:
        # a point is either fully valid or a NaN row, never half
        finite = np.isfinite(result.x.values)
        assert (finite.all(1) | ~finite.any(1)).all()


def _fuzz(fmt: str, data: bytes, path) -> None:
    path.write_bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            result = READERS[fmt](path)
        except IrdicError:
            return
    _check(result, fmt)


@pytest.mark.parametrize("fmt", sorted(READERS))
def test_base_files_are_valid(bases, fmt, tmp_path):
    p = tmp_path / "f.txt"
    p.write_bytes(bases[fmt])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _check(READERS[fmt](p), fmt)


@pytest.mark.parametrize("fmt", sorted(READERS))
@SETTINGS
@given(data=st.data())
def test_damaged_files(bases, fmt, data, tmp_path):
    _fuzz(fmt, data.draw(damaged(bases[fmt], SEPS[fmt])), tmp_path / "DICe_solution_1.txt")


@SETTINGS
@given(data=st.data())
def test_damaged_files_through_detection(bases, data, tmp_path):
    fmt = data.draw(st.sampled_from(["nodemap", "dice", "vic"]))
    p = tmp_path / "stage.txt"
    p.write_bytes(data.draw(damaged(bases[fmt], SEPS[fmt])))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            result = read_dic(p)
        except IrdicError:
            return
    _check(result, fmt)
