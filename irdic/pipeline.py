"""The whole pipeline as plain Python functions, one per stage.

These are what the Snakemake scripts, the CLI and the tests call. Each takes
paths and parameters (as in the configuration) and writes its store
atomically. :func:`run` runs every stage for every configured experiment in
order, without Snakemake (no caching: use the workflow for that).
"""

from __future__ import annotations

import logging
import os
import shutil
from pathlib import Path
from typing import Mapping

import yaml

from .errors import ConfigError
from .store import _jsonable
from .ingest import ingest_dic, ingest_ir
from .threads import stage_threads

__all__ = ["make_demo", "ingest_experiment", "calibrate_setup", "make_figures", "export_experiment", "run",
           "stage_paths", "STAGES"]

log = logging.getLogger(__name__)


def stage_paths(config: Mapping) -> dict:
    """Output paths of every stage (the contract of the results folder)."""
    r = Path(config.get("results", "results"))
    out = {"setups": {}, "experiments": {}}
    for s in config["setups"]:
        out["setups"][s] = {"calibration": r / "setups" / s / "calibration.zarr",
                            "figure": r / "setups" / s / "calibration.png"}
    for e in config["experiments"]:
        out["experiments"][e] = {k: r / e / f"{k}.zarr" for k in ("dic", "ir", "points", "fields")}
    return out


#: what :func:`make_demo` writes into its folder
_DEMO_ENTRIES = {"setup", "halfshell", "tube", "manifest.yaml"}


def make_demo(outdir: str | os.PathLike, *, scale: str = "demo", ir_noise: float = 0.05,
              dic_noise: float = 0.005, seed: int = 0, manifest: str | os.PathLike | None = None) -> Path:
    """Generate the synthetic demo (raw exports + truth) under ``outdir``.

    The folder is emptied first; ``manifest`` (default ``outdir/manifest.yaml``)
    lists what was written and is written last, so its presence means the
    demo is complete.
    """
    from . import synthetic

    out = Path(outdir)
    if out.exists():
        # only ever delete what an earlier demo wrote, never a user's folder
        foreign = [p.name for p in out.iterdir() if p.name not in _DEMO_ENTRIES and not p.name.startswith(".")]
        if foreign:
            raise ConfigError(
                f"{out}: folder exists and holds {', '.join(sorted(foreign)[:5])}, which the demo did not write; "
                "choose an empty or new folder for the demo"
            )
        shutil.rmtree(out)
    out.mkdir(parents=True)
    written = synthetic.make_demo(out, scale=scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed)
    man = Path(manifest) if manifest is not None else out / "manifest.yaml"
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*")
                   if p.is_file() and not any(part.endswith(".zarr") for part in p.parts))
    with open(man, "w", encoding="utf-8") as fh:
        yaml.safe_dump({"scale": scale, "ir_noise": ir_noise, "dic_noise": dic_noise, "seed": seed,
                        "n_files": len(files), "contents": _jsonable(written)},
                       fh, sort_keys=False)
    log.info("demo written to %s (%d files)", out, len(files))
    return out


def ingest_experiment(exp: Mapping, dic_out: str | os.PathLike, ir_out: str | os.PathLike) -> None:
    """Ingest one experiment's DIC and IR exports (``exp`` as in the configuration)."""
    dic = dict(exp["dic"])
    ir = dict(exp["ir"])
    ingest_dic(dic.pop("path"), dic_out, **dic)
    ingest_ir(ir.pop("path"), ir_out, **ir)


def calibrate_setup(markers: str | os.PathLike, target: Mapping | str | os.PathLike,
                    store: str | os.PathLike, figure: str | os.PathLike | None = None, *,
                    seeds: Mapping | None = None, **settings) -> Path:
    """Calibrate the IR camera of one setup and write ``calibration.zarr`` (+ figure).

    Parameters
    ----------
    markers : path-like
        Marker centres export (ID, x, y, z in mm).
    target : mapping or path-like
        IR image of the reference object (``{"path": ..., "format": ...}`` or a path).
    store : path-like
        Output store.
    figure : path-like, optional
        PNG of the detections and residuals.
    seeds : mapping, optional
        ``{marker_id: [u, v]}`` approximate pixel positions.
    **settings
        The ``calibration`` section of the configuration.
    """
    from .calibrate import calibrate_from_files

    if isinstance(target, Mapping):
        tpath, tfmt = target["path"], target.get("format", "auto")
    else:
        tpath, tfmt = target, "auto"
    return calibrate_from_files(markers, tpath, store, figure, target_format=tfmt, seeds=seeds, **settings)


STAGES = ("demo", "ingest", "calibrate", "couple", "fields", "figures", "export")


def run(config: Mapping, *, stages: tuple[str, ...] = STAGES, threads: int | None = None) -> dict:
    """Run the configured stages for every setup and experiment, in order.

    Parameters
    ----------
    config : mapping
        A validated configuration (see :func:`irdic.config.load_config`).
    stages : tuple of str
        Which stages to run.
    threads : int, optional
        CPU threads for BLAS/OpenMP in every stage; default all cores this
        process may use.

    Returns
    -------
    dict
        The output paths (see :func:`stage_paths`).
    """
    unknown = set(stages) - set(STAGES)
    if unknown:
        raise ConfigError(f"unknown stage(s) {sorted(unknown)}; expected {', '.join(STAGES)}")
    with stage_threads(threads):
        return _run(config, stages)


def _run(config: Mapping, stages: tuple[str, ...]) -> dict:
    paths = stage_paths(config)
    demo = config.get("demo", {})
    if "demo" in stages and demo.get("enabled", False):
        man = Path(demo["outdir"]) / "manifest.yaml"
        if not man.exists():
            make_demo(demo["outdir"], scale=demo["scale"], ir_noise=demo["ir_noise"],
                      dic_noise=demo["dic_noise"], seed=demo["seed"])
    if "calibrate" in stages:
        for name, s in config["setups"].items():
            p = paths["setups"][name]
            calibrate_setup(s["markers"]["path"], s["target_image"], p["calibration"], p["figure"],
                            seeds=s.get("seeds"), **config.get("calibration", {}))
    if "ingest" in stages:
        for name, e in config["experiments"].items():
            p = paths["experiments"][name]
            ingest_experiment(e, p["dic"], p["ir"])
    if "couple" in stages:
        from .couple import couple_stores

        for name, e in config["experiments"].items():
            p = paths["experiments"][name]
            cal = paths["setups"][e["setup"]]["calibration"]
            couple_stores(p["dic"], p["ir"], cal, p["points"], **config.get("interpolation", {}))
    if "fields" in stages:
        from .fields import fields_stores

        for name, e in config["experiments"].items():
            p = paths["experiments"][name]
            cal = paths["setups"][e["setup"]]["calibration"]
            fields_stores(p["points"], cal, p["fields"], **config.get("fields", {}))
    if "figures" in stages or "export" in stages:
        for name, e in config["experiments"].items():
            p = paths["experiments"][name]
            rep = e.get("report", {})
            if "figures" in stages:
                make_figures(p["points"], p["fields"], Path(p["points"]).parent / "figures", experiment=name,
                             times=rep.get("times"), point_ids=rep.get("points"))
            if "export" in stages:
                ex = config.get("export", {})
                export_experiment(p["points"], p["fields"], Path(p["points"]).parent / "paraview",
                                  Path(p["points"]).parent / "points.csv", experiment=name,
                                  point_ids=rep.get("points"), csv_points=ex.get("csv_points", "selected"),
                                  precision=ex.get("paraview_precision", "float32"), every=ex.get("paraview_every", 1))
    return paths


def _open_optional(path):
    from .store import open_store

    return open_store(path) if path is not None and Path(path).exists() else None


def make_figures(points_path, fields_path, outputs, *, experiment: str, times=None, point_ids=None) -> dict:
    """Figures of one experiment (``fields.zarr`` optional) -> PNG paths.

    ``outputs`` is a folder or a mapping ``{figure name: path}``; ``times``
    (s) and ``point_ids`` as in ``experiments.<name>.report`` of the configuration.
    """
    from .export import select_points, select_times
    from .plot import plot_experiment
    from .store import open_store

    points = open_store(points_path)
    fields = _open_optional(fields_path)
    key = f"experiments.{experiment}.report"
    t = points["time"].values
    sel_t = t[select_times(t, list(times) if times else None, name=f"{key}.times")]
    ids = select_points(points, list(point_ids) if point_ids else None, name=f"{key}.points")
    return plot_experiment(points, outputs, fields=fields, times=sel_t, point_ids=ids, experiment=experiment)


def export_experiment(points_path, fields_path, paraview_dir, csv_path, *, experiment: str, point_ids=None,
                      csv_points: str = "selected", precision: str = "float32", every: int = 1) -> None:
    """ParaView time series (.pvd + .vtu) and CSV of selected points of one experiment."""
    from .export import select_points, write_csv, write_paraview
    from .store import open_store

    points = open_store(points_path)
    fields = _open_optional(fields_path)
    ids = "all" if csv_points == "all" else select_points(points, list(point_ids) if point_ids else None,
                                                         name=f"experiments.{experiment}.report.points")
    write_paraview(points, paraview_dir, fields=fields, dtype=precision, every=every)
    write_csv(points, csv_path, fields=fields, point_ids=ids)
