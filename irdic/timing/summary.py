"""One line on the IR clock of a ``points.zarr``, for ``irdic info`` and the report."""

from __future__ import annotations

from typing import Mapping

__all__ = ["clock_summary"]


def clock_summary(attrs: Mapping) -> str | None:
    """The offset added to the IR times, its uncertainty and where it came from; None without ``ir_time_offset``."""
    if attrs.get("ir_time_offset") is None:
        return None
    std = float(attrs.get("ir_time_offset_std", float("nan")))
    line = (f"IR clock: time_offset {float(attrs['ir_time_offset']):.6g} s"
            + (f" +- {std:.2g} s" if std == std and std > 0 else "")
            + f" ({attrs.get('ir_time_offset_source', '?')})")
    if "ir_time_offset_estimate" in attrs:
        line += (f"; the data say {float(attrs['ir_time_offset_estimate']):.6g} s"
                 f" +- {float(attrs.get('ir_time_offset_estimate_std', float('nan'))):.2g} s")
    return line
