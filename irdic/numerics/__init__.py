"""Shared numerics: the IMQ kernel, the saddle-point factorisation, the temporal operator, threads."""

from .imq import imq, imq_dr, imq_matrix, imq_planar
from .saddle import SaddleFactor
from .series import SeriesFit, smooth_series
from .temporal import TemporalInterpolant
from .temporal_choice import gcv_temporal

__all__ = [
    "imq",
    "imq_dr",
    "imq_matrix",
    "imq_planar",
    "SaddleFactor",
    "TemporalInterpolant",
    "gcv_temporal",
    "smooth_series",
    "SeriesFit",
]
