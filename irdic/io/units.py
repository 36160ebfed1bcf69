"""Units and metadata values as DIC and IR text exports write them.

Column units in brackets (``"x_undef [mm]"``), their factors to mm and s,
and the stage times and dates of file headers.
"""

from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path

import numpy as np

from ..errors import FormatError

__all__ = ["split_unit", "length_scale", "time_scale", "parse_duration", "parse_date"]

# Length units seen in DIC headers, as factors to mm.
_LENGTH_UNITS = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "µm": 1e-3, "μm": 1e-3, "um": 1e-3, "in": 25.4}
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3,
               "min": 60.0, "h": 3600.0}

_UNIT_RE = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\[\]()]*)[\])]$")



def split_unit(name: str) -> tuple[str, str | None]:
    """``"x_undef [mm]"`` -> ``("x_undef", "mm")``; ``"SIGMA"`` -> ``("SIGMA", None)``."""
    name = name.strip()
    m = _UNIT_RE.match(name)
    if m and m.group("name").strip():
        return m.group("name").strip(), m.group("unit").strip()
    return name, None


def length_scale(unit: str | None, column: str, path: Path, line: int | None = None) -> float:
    """Factor that converts a coordinate column in ``unit`` to mm."""
    if unit is None or unit == "":
        return 1.0
    try:
        return _LENGTH_UNITS[unit.strip().lower()]
    except KeyError:
        raise FormatError(
            f"column {column!r} has unit {unit!r}; expected a length unit "
            f"({', '.join(k for k in _LENGTH_UNITS if k not in ('μm', 'um'))})",
            path, line,
        ) from None


def time_scale(unit: str | None, column: str, path: Path, line: int | None = None) -> float:
    """Factor that converts a time column in ``unit`` to s."""
    if unit is None or unit == "":
        return 1.0
    try:
        return _TIME_UNITS[unit.strip().lower()]
    except KeyError:
        raise FormatError(f"column {column!r} has unit {unit!r}; expected s, ms, min or h", path, line) from None


# --------------------------------------------------------------------------- metadata values

_NUM = r"[+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?"
_DURATION_RE = re.compile(rf"^(?P<num>{_NUM})\s*(?P<unit>[a-zA-Zµ]*)$")
_HMS_RE = re.compile(r"^(?P<sign>-?)(?:(?P<h>\d+):)?(?P<m>\d{1,2}):(?P<s>\d{1,2}(?:[.,]\d*)?)$")

_DATE_FORMATS = (
    "%d.%m.%Y %H:%M:%S.%f", "%d.%m.%Y %H:%M:%S", "%d.%m.%Y %H:%M", "%d.%m.%Y",
    "%m/%d/%Y %I:%M:%S %p", "%m/%d/%Y %H:%M:%S", "%m/%d/%Y %H:%M:%S.%f",
    "%a %b %d %H:%M:%S %Y", "%Y/%m/%d %H:%M:%S", "%Y/%m/%d %H:%M:%S.%f",
)


def parse_duration(text: str) -> float:
    """A time span in s from ``"12.5"``, ``"12.5 s"``, ``"1500 ms"``, ``"0:01:02.5"``.

    Also accepts decimal commas and ``MM:SS(.fff)``.

    Raises
    ------
    ValueError
        The text is none of these forms.
    """
    s = text.strip()
    m = _HMS_RE.match(s)
    if m:
        h = int(m.group("h") or 0)
        minutes = int(m.group("m"))
        secs = float(m.group("s").replace(",", "."))
        if m.group("h") is not None and minutes >= 60 or secs >= 60:
            raise ValueError(f"{text!r} is not a valid H:MM:SS time")
        value = 3600.0 * h + 60.0 * minutes + secs
        return -value if m.group("sign") else value
    m = _DURATION_RE.match(s)
    if m:
        unit = m.group("unit").lower()
        if unit in ("", *_TIME_UNITS):
            value = float(m.group("num").replace(",", ".")) * _TIME_UNITS.get(unit, 1.0)
            if np.isfinite(value):
                return value
    raise ValueError(f"cannot read {text!r} as a time; expected seconds (e.g. 12.5, 12.5 s, 1500 ms) or H:MM:SS.fff")


def parse_date(text: str) -> str:
    """A time stamp as ISO 8601 text; accepts ISO and common German/US layouts.

    Raises
    ------
    ValueError
        The text is not a date in any known layout.
    """
    s = text.strip()
    try:
        return datetime.fromisoformat(s).isoformat()
    except ValueError:
        pass
    for fmt in _DATE_FORMATS:
        try:
            return datetime.strptime(s, fmt).isoformat()
        except ValueError:
            continue
    raise ValueError(f"cannot read {text!r} as a date")
