"""Timing of the two series: the offset of the IR clock from the data (:mod:`irdic.timing.offset`)."""

from .offset import ClockOffset, estimate_offset

__all__ = ["ClockOffset", "estimate_offset"]
