"""The testing machine's signals in DIC exports (ZEISS nodemap ``# SIGNALS:`` section).

A ZEISS INSPECT / ARAMIS nodemap header lists the signals recorded with the
stage, one a line, ``# <name> : <kind> : <value>``::

    # SIGNALS:
    # force                         : value_element       : 14985.6119156
    # displacement                  : value_element       : -9.17953395844
    #
    # Kraft [kN]                    : analog_input        : 15.1025390625

Names are kept as written (German and English alike); a unit in brackets is
split off (``Kraft [kN]`` -> name ``Kraft``, unit ``kN``). A
``standard_name`` (force, displacement, torque, angle, cycles, time) is
derived from the first word of the name where it is a known German or English
term, so that figures can find the load whatever the language of the export.

One stage is represented as variables over a ``signal`` dimension:
``signal_value(signal)`` float64 values, coordinate ``signal`` (names) and the
coordinates ``signal_kind``, ``signal_unit``, ``signal_standard_name`` (empty
text where unknown).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np
import xarray as xr

from ..errors import FormatError, IrdicWarning
from ._tables import NA_TOKENS
from .units import split_unit

__all__ = ["Signal", "parse_signals", "standard_name", "signal_coords", "format_signals", "STANDARD_NAMES"]

#: first word of a signal name (lower case) -> standard name
STANDARD_NAMES = {
    "force": "force", "kraft": "force", "load": "force", "last": "force", "prüfkraft": "force",
    "displacement": "displacement", "verschiebung": "displacement", "weg": "displacement",
    "stroke": "displacement", "traverse": "displacement", "elongation": "displacement",
    "torque": "torque", "drehmoment": "torque", "moment": "torque", "torsionsmoment": "torque",
    "angle": "angle", "winkel": "angle", "drehwinkel": "angle", "verdrehwinkel": "angle", "twist": "angle",
    "rotation": "angle", "torsionswinkel": "angle",
    "cycles": "cycles", "cycle": "cycles", "zyklen": "cycles", "zyklus": "cycles", "zyklenzahl": "cycles",
    "time": "time", "zeit": "time",
}

_VALUE_UNIT = re.compile(r"^([+-]?(?:\d+(?:[.,]\d*)?|[.,]\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-zµμ°%].*)$")
_TITLE = re.compile(r"^signals?\s*:?$", re.IGNORECASE)
_RULE = set("#-=*_ ")


class Signal(NamedTuple):
    """One signal of one stage.

    Attributes
    ----------
    name : str
        Name as written, without a bracketed unit.
    kind : str
        ``value_element``, ``analog_input``, ... ("" when not given).
    value : float
        NaN when the export says nan/none.
    unit : str
        From ``name [unit]``; "" when unknown.
    line : int
        1-based line in the file.
    """

    name: str
    kind: str
    value: float
    unit: str
    line: int


def standard_name(name: str) -> str:
    """``"Kraft"`` -> ``"force"``, ``"Verschiebung_1"`` -> ``"displacement"``; "" when unknown."""
    first = re.split(r"[\s_.\-/]+", name.strip().lower(), maxsplit=1)[0]
    return STANDARD_NAMES.get(first, "")


def _number(text: str) -> float | None:
    t = text.strip()
    if t.lower() in NA_TOKENS:
        return float("nan")
    for candidate in (t, t.replace(",", ".") if t.count(",") == 1 and "." not in t else None):
        if candidate is None:
            continue
        try:
            return float(candidate)
        except ValueError:
            continue
    return None


def parse_signals(lines: Sequence[str], path: str | Path) -> list[Signal]:
    """The ``# SIGNALS:`` section of a nodemap header.

    Parameters
    ----------
    lines : sequence of str
        Header lines (everything before the column header).
    path : path-like
        The file, for messages.

    Returns
    -------
    list of Signal
        In file order; empty when the header has no SIGNALS section. A name
        that occurs twice with different kinds (``force`` as value element
        and as analog input) gets the kind appended (``force_analog_input``).

    Warns
    -----
    IrdicWarning
        A signal value is not a number (the signal is left out of this stage,
        so it is NaN there after ingest). A value followed by a unit
        (``23,5 °C``) is read with that unit; a unit alone (``N``: the signal
        is listed without a value) gives NaN with that unit, without warning.

    Raises
    ------
    FormatError
        The same name and kind occur twice in the section.
    """
    p = Path(path)
    out: list[Signal] = []
    seen: dict[tuple[str, str], int] = {}
    inside = False
    for k, raw in enumerate(lines):
        s = raw.strip()
        if not s.startswith("#"):
            if inside:
                break
            continue
        text = s.lstrip("#").strip()
        if not inside:
            inside = bool(_TITLE.match(text))
            continue
        if not text:
            continue  # "#" alone separates value elements from analog inputs
        if set(text) <= _RULE or ";" in text:
            break
        parts = [q.strip() for q in text.split(":")]
        if len(parts) < 2 or not parts[-1]:
            break  # the next section's title
        if len(parts) == 2:
            written, kind, value = parts[0], "", parts[1]
        else:
            written, kind, value = ":".join(parts[:-2]), parts[-2], parts[-1]
        name, unit = split_unit(written)
        v = _number(value)
        if v is None:
            # "23,5 °C": a value with its unit; "N" alone: the exporter lists the signal with its unit only
            m = _VALUE_UNIT.match(value)
            if m and _number(m.group(1)) is not None:
                v, unit = _number(m.group(1)), unit or m.group(2).strip()
            elif not any(ch.isdigit() for ch in value):
                v, unit = float("nan"), unit or value
        if v is None:
            warnings.warn(f"{p}, line {k + 1}: signal {written!r} has the value {value!r}, expected a number; "
                          "it is left out of this stage (NaN)", IrdicWarning, stacklevel=3)
            continue
        key = (name, kind)
        if key in seen:
            raise FormatError(f"signal {name!r} ({kind or 'no kind'}) appears twice in the SIGNALS section "
                              f"(lines {seen[key]} and {k + 1}); expected each signal once", p, k + 1)
        seen[key] = k + 1
        if any(q.name == name for q in out):
            name = f"{name}_{kind}" if kind else f"{name}_2"
        out.append(Signal(name, kind, float(v), unit or "", k + 1))
    return out


def signal_coords(names: Sequence[str], kinds: Sequence[str], units: Sequence[str],
                  standard: Sequence[str] | None = None, dim: str = "signal") -> dict:
    """Coordinates ``signal``, ``signal_kind``, ``signal_unit``, ``signal_standard_name`` (object text)."""
    std = [standard_name(n) for n in names] if standard is None else list(standard)

    def text(v):
        return np.array([str(s) for s in v], dtype=object)

    return {dim: (dim, text(names), {"long_name": "signal name as written in the source"}),
            f"{dim}_kind": (dim, text(kinds), {"long_name": "kind of signal (value_element, analog_input, machine)"}),
            f"{dim}_unit": (dim, text(units), {"long_name": "unit of the signal ('' when unknown)"}),
            f"{dim}_standard_name": (dim, text(std),
                                     {"long_name": "force, displacement, torque, angle, cycles, time ('' if unknown)"})}


def stage_signals(signals: Sequence[Signal]) -> xr.Dataset:
    """The signals of one stage as a Dataset over ``signal`` (see the module docstring)."""
    values = np.array([s.value for s in signals], dtype=np.float64)
    return xr.Dataset({"signal_value": ("signal", values, {"long_name": "value of the testing machine's signal"})},
                      coords=signal_coords([s.name for s in signals], [s.kind for s in signals],
                                           [s.unit for s in signals]))


def format_signals(signals: Sequence[tuple]) -> list[str]:
    """Header lines of a SIGNALS section from ``(name, kind, value)`` triples (NaN written ``nan``)."""
    lines = ["# SIGNALS:"]
    kind_prev = None
    for name, kind, value in signals:
        if kind_prev is not None and kind != kind_prev:
            lines.append("#")
        kind_prev = kind
        lines.append(f"# {str(name).ljust(30)}: {str(kind).ljust(20)}: {float(value)!r}")
    return lines
