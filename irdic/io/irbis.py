"""InfraTec IRBIS 3 text exports: one IR frame per file.

Layout (see ``formats/README.md``)::

    [Settings]
    Version=3
    ImageWidth=586
    ImageHeight=439
    ShotRange=15.00;35.00
    CalibRange=9.85;99.85
    TempUnit=°C

    [Parameter]
    Filename=GW_1_Zyklus2_0001.irb
    FrameIndex=860
    RecDate=13.04.2021
    RecTime=12:38:33
    ms=34359.75
    ...
    [Data]
    17.41<TAB>17.48<TAB>...        one line per image row, top row first

The separator (TAB, ``;`` or blanks) and the decimal mark (``.`` or ``,``)
follow the Windows locale of the exporting PC; they are detected per file from
the first row of the data section (``;`` also separates list values inside
``[Settings]``, so the header says nothing about them).

Parsing speed matters: a test series has thousands of these files of 1.5 MB
each. The data section is parsed by a vectorised fixed-point decoder
(:func:`irdic.io._decimals.parse_fast`) in blocks of whole lines: every number
is located by its first and last byte, its characters are gathered a position
at a time (counted from its last character) and the digits are summed with
their powers of ten, all in NumPy and in scratch arrays that are reused from
block to block. It gives the correctly rounded value of each decimal number
(the same as :func:`float`); its throughput next to :func:`numpy.loadtxt` and
:func:`pandas.read_csv` is in ``benchmarks/README.md``.
Anything the fast decoder does not expect (exponents, stray characters, empty
cells, ragged rows, a truncated file) sends the file through a plain
line-by-line parser (:func:`parse_slow`) that either reads it (exponents) or
says exactly which line and column is wrong.
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import os
import re
import warnings

import numpy as np
import xarray as xr

from ..errors import FormatError, IrdicWarning
from ._common import check_file, decode_text
from ._decimals import parse_fast
from .stack import check_temperatures, normalise_unit, temperature_dataarray, to_celsius

__all__ = ["read_irbis", "read_irbis_header", "parse_irbis"]

log = logging.getLogger(__name__)

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NON_BLANK = re.compile(rb"[^ \t\r\n]")
_LINE_END = re.compile(rb"[\r\n]")
_MAX_PIXELS = 100_000  # bound on image sizes and sensor positions (px)
# a real header is about 2 kB; read_irbis_header gives up after this many bytes without [Data]
_MAX_HEADER = 1 << 20


# ----------------------------------------------------------------------------
# header
# ----------------------------------------------------------------------------
def _find_data_marker(raw: bytes, start: int = 0) -> int:
    """Byte offset of the ``[Data]`` line (at a line start), or -1.

    Only markers beginning at or after ``start`` are looked for (the caller
    has searched the bytes before); the time taken is linear in the bytes
    searched.
    """
    pos = start
    while True:
        i = raw.find(b"[Data]", pos)
        if i < 0:
            break
        if _at_line_start(raw, i):
            return i
        pos = i + 1
    # other capitalisations ([DATA], [data]): rare, so the lower-case copy is
    # made only when the exact spelling is absent
    low = raw[start:].lower()
    i = low.find(b"[data]")
    while i >= 0 and not _at_line_start(raw, start + i):
        i = low.find(b"[data]", i + 1)
    return -1 if i < 0 else start + i


def _at_line_start(raw: bytes, i: int) -> bool:
    return i == 0 or raw[i - 1:i] in (b"\n", b"\r") or (
        i <= 64 and bytes(raw[:i]).strip(b"\xef\xbb\xbf \t") == b"")


def _parse_header_text(text: str) -> dict:
    """``{lower-case key: (key, value, line number)}`` plus ``"__sections__"``."""
    entries: dict = {}
    sections = []
    for no, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("[") and s.endswith("]"):
            sections.append(s[1:-1])
            continue
        if "=" not in s:
            log.debug("header line %d without '=' ignored: %r", no, s)
            continue
        key, value = s.split("=", 1)
        key = key.strip()
        entries[key.lower()] = (key, value.strip(), no)
    entries["__sections__"] = sections
    return entries


def _number(text: str, key: str, line: int, path) -> float:
    """A header number written with ``.`` or ``,`` as decimal mark."""
    t = text.strip()
    if "," in t and "." not in t:
        t = t.replace(",", ".")
    if not _NUMBER.fullmatch(t):
        raise FormatError(f"{key}={text!r} is not a number", path, line)
    value = float(t)
    if not math.isfinite(value):
        raise FormatError(f"{key}={text!r} is not a finite number", path, line)
    return value


def _number_list(text: str, key: str, line: int, path) -> list[float]:
    """``a;b`` (or ``a,b`` with ``.`` decimals, or blanks) as a list of floats."""
    t = text.strip()
    if ";" in t:
        parts = t.split(";")
    elif t.count(",") == 1 and "." in t:
        parts = t.split(",")
    else:
        parts = t.split()
    return [_number(p, key, line, path) for p in parts if p.strip()]


def _int(text: str, key: str, line: int, path, minimum: int, maximum: int = _MAX_PIXELS) -> int:
    t = text.strip()
    if not re.fullmatch(r"[+-]?\d{1,19}", t):
        raise FormatError(f"{key}={text!r} is not an integer", path, line)
    value = int(t)
    if not minimum <= value <= maximum:
        raise FormatError(f"{key}={value} is out of range; expected an integer from {minimum} to {maximum}",
                          path, line)
    return value


def _int_pair(text: str, key: str, line: int, path) -> tuple[int, int]:
    parts = [p for p in re.split(r"[;,\s]+", text.strip()) if p]
    if len(parts) != 2:
        raise FormatError(f"{key}={text!r}; expected two integers 'u;v'", path, line)
    return _int(parts[0], key, line, path, 0), _int(parts[1], key, line, path, 0)


def _rec_datetime(date: str, time: str | None, path, line: int) -> str | None:
    """ISO 8601 from ``RecDate`` (dd.mm.yyyy or yyyy-mm-dd) and ``RecTime``."""
    d = date.strip()
    for fmt in ("%d.%m.%Y", "%Y-%m-%d", "%d.%m.%y"):
        try:
            day = _dt.datetime.strptime(d, fmt).date()
            break
        except ValueError:
            continue
    else:
        warnings.warn(f"{path}, line {line}: RecDate={date!r} is not dd.mm.yyyy; rec_datetime left out",
                      IrdicWarning, stacklevel=4)
        return None
    if not time:
        return day.isoformat()
    t = time.strip()
    for fmt in ("%H:%M:%S", "%H:%M:%S.%f", "%H:%M"):
        try:
            clock = _dt.datetime.strptime(t, fmt).time()
            break
        except ValueError:
            continue
    else:
        warnings.warn(f"{path}: RecTime={time!r} is not hh:mm:ss; only the date is kept",
                      IrdicWarning, stacklevel=4)
        return day.isoformat()
    return _dt.datetime.combine(day, clock).isoformat()


def _interpret_header(entries: dict, path) -> dict:
    """Typed header values (see :func:`read_irbis_header`)."""
    def get(key):
        return entries.get(key.lower())

    out: dict = {"sections": list(entries.get("__sections__", []))}
    for name, key in (("width", "ImageWidth"), ("height", "ImageHeight")):
        e = get(key)
        out[name] = None if e is None else _int(e[1], e[0], e[2], path, 1)
        out[name + "_line"] = None if e is None else e[2]
    e = get("TempUnit")
    if e is None:
        log.info("%s: no TempUnit in the header; assuming °C", path)
        out["unit"] = "degC"
        out["unit_raw"] = None
    else:
        unit = normalise_unit(e[1])
        if unit is None:
            raise FormatError(f"TempUnit={e[1]!r} is not a temperature unit; expected °C or K", path, e[2])
        out["unit"], out["unit_raw"] = unit, e[1]
    start = get("StartPos")
    out["start_pos"] = None if start is None else _int_pair(start[1], start[0], start[2], path)
    end = get("EndPos")
    out["end_pos"] = None if end is None else _int_pair(end[1], end[0], end[2], path)
    for name, key in (("sensor_width", "SensorWidth"), ("sensor_height", "SensorHeight")):
        e = get(key)
        out[name] = None if e is None else _int(e[1], e[0], e[2], path, 1)
    e = get("FrameIndex")
    out["frame_index"] = None if e is None else _int(e[1], e[0], e[2], path, 0, 2**62)
    e = get("ms")
    out["ms"] = None if e is None else _number(e[1], e[0], e[2], path)
    d, t = get("RecDate"), get("RecTime")
    out["rec_datetime"] = None if d is None else _rec_datetime(d[1], None if t is None else t[1], path, d[2])
    for name, keys in (("emissivity", ("Emissivity", "Epsilon", "Eps")), ("distance", ("Distance",)),
                       ("env_temp", ("EnvTemp", "AmbientTemp")), ("path_temp", ("PathTemp",)),
                       ("transmission", ("Transmission", "Tau"))):
        for key in keys:
            e = get(key)
            if e is not None:
                out[name] = _number(e[1], e[0], e[2], path)
                break
    for name, key in (("shot_range", "ShotRange"), ("calib_range", "CalibRange")):
        e = get(key)
        if e is not None:
            out[name] = _number_list(e[1], e[0], e[2], path)
    for name, key in (("version", "Version"), ("recording_file", "Filename")):
        e = get(key)
        if e is not None:
            out[name] = e[1]
    return out


def read_irbis_header(path: str | os.PathLike) -> dict:
    """Read only the header (the sections before ``[Data]``) of an IRBIS text export.

    Cheap: reads the file in 64 KiB pieces until ``[Data]`` is found, so a
    series of thousands of frames can be listed and sorted quickly.

    Parameters
    ----------
    path : path-like
        IRBIS 3 text export.

    Returns
    -------
    dict
        ``width``, ``height`` (exported window, px), ``unit`` (``"degC"``,
        ``"K"`` or ``"degF"``), ``start_pos``/``end_pos`` ((u, v) or None),
        ``sensor_width``/``sensor_height``, ``frame_index``, ``ms``
        (time in the recording, ms), ``rec_datetime`` (ISO 8601 or None),
        and when present ``emissivity``, ``distance`` (m), ``env_temp``,
        ``shot_range``, ``calib_range`` (in the file's unit), ``version``,
        ``recording_file``, ``sections``.

    Raises
    ------
    FormatError
        No ``[Data]`` section, or a malformed header value (line named).
    """
    p = check_file(path)
    head = bytearray()
    i = -1
    with open(p, "rb") as fh:
        while len(head) < _MAX_HEADER:
            chunk = fh.read(65536)
            if not chunk:
                break
            # search only the new piece (plus a marker's length before it, for a
            # marker cut in two): the whole text again would be quadratic in the
            # length of a file without [Data]
            start = max(0, len(head) - len(b"[Data]"))
            head += chunk
            i = _find_data_marker(head, start)
            if i >= 0:
                break
    if i < 0:
        if len(head) >= _MAX_HEADER:
            raise FormatError(
                f"no [Data] line in the first {_MAX_HEADER // 1024} KiB; an IRBIS 3 text export has a "
                "header of a few kB before its [Data] section (not an IRBIS export, or a damaged one)", p)
        raise FormatError("no [Data] section found; expected an IRBIS 3 text export", p)
    return _interpret_header(_parse_header_text(decode_text(bytes(head[:i]))), p)


# ----------------------------------------------------------------------------
# data section
# ----------------------------------------------------------------------------
def _detect_layout(first_row: bytes, width: int | None, path, line: int) -> tuple[bytes, int]:
    """Separator and decimal-mark byte from the first data row."""
    row = first_row.strip()
    if b"\t" in row:
        sep = b"\t"
    elif b";" in row:
        sep = b";"
    elif b"," in row and (b"." in row or (width is not None and len(row.rstrip(b",").split(b",")) == width
                                            and b" " not in row)):
        sep = b","
    else:
        sep = b" "
    if sep != b"," and b"," in row:
        if b"." in row:
            raise FormatError("the first data row contains both '.' and ','; cannot tell the decimal mark",
                              path, line)
        mark = ord(",")
    else:
        mark = ord(".")
    return sep, mark


def _split_row(text: str, sep: str) -> list[str]:
    if sep == " ":
        return text.split()
    cells = [c.strip() for c in text.split(sep)]
    if len(cells) > 1 and cells[-1] == "":  # trailing separator
        cells.pop()
    return cells


def parse_slow(data: bytes, sep: bytes, mark: int, newline: int, first_line: int, width: int | None,
                height: int | None, path, width_line: int | None, height_line: int | None) -> np.ndarray:
    """Line-by-line parser: exact error messages, and exponent notation."""
    sep_s = sep.decode()
    mark_s = chr(mark)
    rows = []
    expected = width
    last_line = first_line
    all_lines = data.split(bytes([newline]))
    for k, raw_line in enumerate(all_lines):
        line_no = first_line + k
        text = raw_line.decode("latin-1").strip(" \r\n")  # a leading TAB is an empty cell
        if not text.strip():
            continue
        last_line = line_no
        cells = _split_row(text, sep_s)
        if expected is None:
            expected = len(cells)
        if len(cells) != expected:
            if width is not None:
                what = f"ImageWidth={width}" + (f" (line {width_line})" if width_line else "")
            else:
                what = f"{expected} as in the first data row"
            at_end = not any(x.strip() for x in all_lines[k + 1:])
            hint = " (file truncated?)" if len(cells) < expected and at_end else ""
            raise FormatError(f"data row {len(rows) + 1} has {len(cells)} values, expected {what}{hint}",
                              path, line_no)
        values = []
        for c, cell in enumerate(cells, start=1):
            t = cell.replace(mark_s, ".") if mark_s != "." else cell
            if mark_s != "." and "." in cell:
                t = "x"  # a '.' in a decimal-comma file is garbage
            if not _NUMBER.fullmatch(t):
                raise FormatError(
                    f"data row {len(rows) + 1}, column {c}: {cell!r} is not a number "
                    f"(separator {sep_s!r}, decimal mark {mark_s!r})",
                    path, line_no)
            v = float(t)
            if not math.isfinite(v):
                raise FormatError(f"data row {len(rows) + 1}, column {c}: {cell!r} is not a finite number",
                                  path, line_no)
            values.append(v)
        rows.append(values)
    if not rows:
        raise FormatError("the [Data] section holds no values", path, first_line)
    if height is not None and len(rows) != height:
        where = f" (line {height_line})" if height_line else ""
        raise FormatError(
            f"found {len(rows)} data rows, expected ImageHeight={height}{where}"
            + (" (file truncated?)" if len(rows) < height else ""),
            path, last_line)
    return np.asarray(rows, dtype=np.float64)


_TO_CELSIUS = {"degC": (1.0, 0.0), "K": (1.0, -273.15), "degF": (5.0 / 9.0, -32.0 * 5.0 / 9.0)}


def _check_one_frame(raw: bytes, stop: int, newline: int, where) -> None:
    """FormatError when a second ``[Data]`` section follows the matrix that ends at ``stop``.

    Exports concatenated into one file (or a multi-frame text export) would
    otherwise be read as their first frame alone.
    """
    again = _find_data_marker(raw, stop)
    if again >= 0:
        raise FormatError("a second [Data] section follows the first frame's matrix: the file holds more than "
                          "one frame; irdic reads one frame per IRBIS text file, so export each frame to a file "
                          "of its own", where, raw.count(bytes([newline]), 0, again) + 1)


def parse_irbis(raw: bytes, path: str | os.PathLike | None = None, *,
                celsius: bool = False) -> tuple[dict, np.ndarray]:
    """Parse the bytes of an IRBIS text export.

    Parameters
    ----------
    raw : bytes
        Whole file content.
    path : path-like, optional
        Named in error messages.
    celsius : bool
        Return float32 °C (converted in float64 from the file's unit, one
        rounding) instead of float64 values in the file's unit.

    Returns
    -------
    header : dict
        As :func:`read_irbis_header`, plus ``separator`` and ``decimal``.
    values : ndarray of float64 (float32 with ``celsius``), shape (height, width)
        Temperatures, rows top to bottom.

    Raises
    ------
    FormatError
        Missing ``[Data]``, malformed header, non-numeric cell (line, column), rows or columns that disagree
        with ``ImageHeight``/``ImageWidth`` (line), truncated file, a second frame.
    """
    where = path if path is not None else "<bytes>"
    i = _find_data_marker(raw)
    if i < 0:
        raise FormatError("no [Data] section found; expected an IRBIS 3 text export", where)
    head_text = decode_text(raw[:i])
    header = _interpret_header(_parse_header_text(head_text), where)
    marker_line = head_text.count("\n") + 1 if "\n" in head_text else head_text.count("\r") + 1
    m = _LINE_END.search(raw, i)
    if m is None:
        raise FormatError("the file ends right after [Data]; the temperature matrix is missing", where,
                          marker_line)
    eol = m.start()
    newline = ord("\n")
    if raw[eol:eol + 1] == b"\r":
        if raw[eol + 1:eol + 2] == b"\n":
            eol += 1
        else:
            newline = ord("\r")  # old Mac line ends
    # the data section is raw[start:stop]; it is not copied on the fast path
    start, stop = eol + 1, len(raw)
    # a section after the matrix ([MeasDefs] in some exports) ends it
    bracket = raw.find(b"[", start)  # one-byte search is memchr-fast; the two-byte one is not
    nxt = -1 if bracket < 0 else raw.find(bytes([newline]) + b"[", max(bracket - 1, start))
    if nxt >= 0:
        stop = nxt + 1
        _check_one_frame(raw, stop, newline, where)
    elif stop > start and raw[stop - 1:stop] not in (b"\n", b"\r"):
        warnings.warn(f"{where}: the last data row has no line end; the file may be cut short and "
                      "its last value incomplete", IrdicWarning, stacklevel=3)
    first_line = marker_line + 1
    m = _NON_BLANK.search(raw, start, stop)
    if m is None:
        raise FormatError("the [Data] section holds no values", where, first_line)
    skipped = raw.count(bytes([newline]), start, m.start())
    row_end = raw.find(bytes([newline]), m.start(), stop)
    first_row = raw[m.start():row_end if row_end >= 0 else stop]
    width, height = header["width"], header["height"]
    sep, mark = _detect_layout(first_row, width, where, first_line + skipped)
    header["separator"], header["decimal"] = sep.decode(), chr(mark)

    expected = width * height if width is not None and height is not None else None
    convert = _TO_CELSIUS[header["unit"]] if celsius else None
    fast = parse_fast(raw, sep, mark, newline, expected, start, stop, convert)
    if fast is not None:
        values, per_line = fast
        rows = per_line[per_line > 0]
        w = width if width is not None else (int(rows[0]) if rows.size else 0)
        h = height if height is not None else rows.size
        if rows.size == h and (rows == w).all() and values.size == w * h and w * h > 0:
            return header, values.reshape(h, w)
    values = parse_slow(raw[start:stop], sep, mark, newline, first_line, width, height, where,
                         header["width_line"], header["height_line"])
    return header, (to_celsius(values, header["unit"]) if celsius else values)


def _celsius_scalar(value: float, unit: str) -> float:
    """A header temperature in °C, rounded to remove float noise of the conversion."""
    if unit == "K":
        return round(value - 273.15, 9)
    if unit == "degF":
        return round((value - 32.0) * 5.0 / 9.0, 9)
    return float(value)


def read_irbis(path: str | os.PathLike) -> xr.DataArray:
    """Read one frame of an InfraTec IRBIS 3 text export.

    Parameters
    ----------
    path : path-like
        ``.txt``/``.asc``/``.csv`` export (TAB or ``;`` separated, ``.`` or
        ``,`` decimals, CRLF or LF, cp1252/latin-1/UTF-8).

    Returns
    -------
    xarray.DataArray
        float32 temperatures in °C (converted from K or °F when
        ``TempUnit`` says so), dims ``("v", "u")``; integer coordinates
        ``u``, ``v`` in full-sensor pixels (offset by ``StartPos=u;v`` for
        a crop export, which is taken as 0-based). Scalar coordinate
        ``time`` = ``ms`` / 1000 (s since the start of the recording) when
        ``ms`` is present. ``attrs``: ``units``, ``long_name``,
        ``format="irbis"``, ``source``, and when the header has them
        ``frame_index``, ``rec_datetime`` (ISO 8601 from ``RecDate`` and
        ``RecTime``), ``sensor_width``/``sensor_height`` (irdic's own
        ``SensorWidth``/``SensorHeight`` keys), ``emissivity``,
        ``distance`` (m), ``env_temp`` (°C), ``shot_range``/``calib_range``
        (°C), ``recording_file``, ``irbis_version``, ``source_unit``.

    Raises
    ------
    FormatError
        See :func:`parse_irbis`; also temperatures below absolute zero.
    """
    p = check_file(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise FormatError(f"cannot read the file ({exc.strerror})", p) from exc
    header, temps = parse_irbis(raw, p, celsius=True)
    unit = header["unit"]
    check_temperatures(temps, p)

    u0, v0 = header["start_pos"] or (0, 0)
    h, w = temps.shape
    if header["end_pos"] is not None and header["start_pos"] is not None:
        eu, ev = header["end_pos"]
        if (eu, ev) == (u0 + w, v0 + h):
            log.info("%s: EndPos is exclusive (start + size)", p)
        elif (eu, ev) != (u0 + w - 1, v0 + h - 1):
            warnings.warn(
                f"{p}: StartPos={u0};{v0} and EndPos={eu};{ev} do not span the {w} x {h} matrix; "
                "using StartPos and the matrix size", IrdicWarning, stacklevel=2)
    attrs: dict = {"format": "irbis", "source": str(p), "source_unit": unit}
    if header["frame_index"] is not None:
        attrs["frame_index"] = header["frame_index"]
    if header["rec_datetime"] is not None:
        attrs["rec_datetime"] = header["rec_datetime"]
    for key in ("sensor_width", "sensor_height"):
        if header[key] is not None:
            attrs[key] = header[key]
    if header["start_pos"] is not None:
        attrs["start_pos"] = [u0, v0]
    if "emissivity" in header:
        attrs["emissivity"] = header["emissivity"]
    if "distance" in header:
        attrs["distance"] = header["distance"]
    if "transmission" in header:
        attrs["transmission"] = header["transmission"]
    for key in ("env_temp", "path_temp"):
        if key in header:
            attrs[key] = _celsius_scalar(header[key], unit)
    for key in ("shot_range", "calib_range"):
        if key in header:
            attrs[key] = [_celsius_scalar(x, unit) for x in header[key]]
    if "recording_file" in header:
        attrs["recording_file"] = header["recording_file"]
    if "version" in header:
        attrs["irbis_version"] = header["version"]
    time = None if header["ms"] is None else header["ms"] / 1000.0
    return temperature_dataarray(temps, u0=u0, v0=v0, time=time, attrs=attrs)
