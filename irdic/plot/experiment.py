"""All figures of one experiment (:func:`plot_experiment`)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Mapping

from ..errors import ConfigError
from .fields import plot_gradient, plot_rate, plot_strain, plot_temperature
from .heat import plot_heat
from .history import plot_history, plot_load

__all__ = ["plot_experiment", "FIGURES", "HEAT_FIGURE"]

log = logging.getLogger(__name__)

#: figures of :func:`plot_experiment`, by name (the strain figure needs fields.zarr)
FIGURES = ("temperature", "gradient", "rate", "history", "strain", "load")
#: the heat source's figure, drawn when asked for (it needs heat.zarr merged into ``fields``)
HEAT_FIGURE = "heat"


def plot_experiment(points, outdir, *, fields=None, times=None, point_ids=None, experiment=None,
                    names=None) -> dict[str, Path]:
    """All figures of one experiment.

    Parameters
    ----------
    points : xarray.Dataset
        ``points.zarr``.
    outdir : path-like or mapping of str to path-like
        Folder of the PNGs (``<outdir>/<name>.png``), or the path of each
        figure by name (keys of :data:`FIGURES`; then ``names`` are its keys).
    fields : xarray.Dataset, optional
        ``fields.zarr``; the strain and load figures need it.
    times, point_ids, experiment
        See the single figure functions.
    names : sequence of str, optional
        Figures to draw (keys of :data:`FIGURES`); default all that the data
        allow (no strain or load figure without ``fields``).

    Returns
    -------
    dict of str to pathlib.Path
    """
    if isinstance(outdir, Mapping):
        paths = {str(k): Path(v) for k, v in outdir.items()}
        names = list(paths)
    else:
        if names is None:
            names = [n for n in FIGURES if n not in ("strain", "load") or fields is not None]
        paths = {n: Path(outdir) / f"{n}.png" for n in names}
    unknown = [n for n in names if n not in FIGURES + (HEAT_FIGURE,)]
    if unknown:
        raise ConfigError(f"unknown figure(s) {', '.join(map(repr, unknown))}; known: "
                          f"{', '.join(FIGURES + (HEAT_FIGURE,))}")
    done = {}
    for n in names:
        p = paths[n]
        if n == "temperature":
            done[n] = plot_temperature(points, p, times=times, experiment=experiment)
        elif n == "gradient":
            done[n] = plot_gradient(points, p, fields=fields, times=times, experiment=experiment)
        elif n == "rate":
            done[n] = plot_rate(points, p, fields=fields, times=times, experiment=experiment)
        elif n == "history":
            done[n] = plot_history(points, p, fields=fields, point_ids=point_ids, experiment=experiment)
        elif n == "load":
            done[n] = plot_load(points, p, fields=fields, point_ids=point_ids, experiment=experiment)
        elif n == HEAT_FIGURE:
            done[n] = plot_heat(points, p, fields=fields, times=times, experiment=experiment)
        else:
            done[n] = plot_strain(fields, p, points=points, times=times, experiment=experiment)
        log.info("figure %s -> %s", n, p)
    return done
