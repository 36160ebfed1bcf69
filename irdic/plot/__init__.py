"""Figures: functions that take datasets/arrays and a path and write a PNG.

Matplotlib is used through its object interface with the Agg canvas, so no
global pyplot state or display is involved (safe in Snakemake jobs).

- :mod:`.calibration`: :func:`plot_calibration`, :func:`plot_detections`.
- :mod:`.maps`: the IR camera view (:func:`view_basis`), triangulated
  colour maps and colour scales every result figure shares.
- :mod:`.fields`: :func:`plot_temperature`, :func:`plot_gradient`,
  :func:`plot_rate`, :func:`plot_strain` on the surface.
- :mod:`.history`: :func:`plot_history` at chosen points and
  :func:`plot_load` (temperature against the testing machine's signals).
- :mod:`.heat`: :func:`plot_heat`, the heat source (maps and the mean against the load).
- :mod:`.experiment`: :func:`plot_experiment`, all figures of one experiment.
"""

from .calibration import FAINT_SNR, plot_calibration, plot_detections
from .experiment import FIGURES, HEAT_FIGURE, plot_experiment
from .fields import plot_gradient, plot_rate, plot_strain, plot_temperature
from .heat import plot_heat
from .history import load_signals, plot_history, plot_load
from .maps import view_basis

__all__ = [
    "plot_calibration",
    "plot_detections",
    "view_basis",
    "plot_temperature",
    "plot_gradient",
    "plot_rate",
    "plot_history",
    "plot_strain",
    "plot_load",
    "plot_experiment",
    "load_signals",
    "FIGURES",
    "HEAT_FIGURE",
    "plot_heat",
    "FAINT_SNR",
]
