"""The whole pipeline as plain Python functions, one per stage.

These are what the Snakemake scripts, the CLI and the tests call. Each takes
paths and parameters (as in the configuration) and writes its store
atomically. :func:`run` runs every stage for every configured experiment in
order, without Snakemake (no caching: use the workflow for that).
"""

from __future__ import annotations

import json
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
    """Output paths of every stage (the contract of the results folder).

    Raises
    ------
    ConfigError
        A setup or experiment name would put an output outside the results
        folder (``../x``, an absolute path, a link leading elsewhere).
    """
    r = Path(config.get("results", "results"))
    out = {"setups": {}, "experiments": {}}
    for s in config["setups"]:
        out["setups"][s] = {"calibration": r / "setups" / s / "calibration.zarr",
                            "figure": r / "setups" / s / "calibration.png"}
    for e in config["experiments"]:
        out["experiments"][e] = {k: r / e / f"{k}.zarr" for k in ("dic", "ir", "points", "fields")}
        if config["experiments"][e].get("machine"):
            out["experiments"][e]["machine"] = r / e / "machine.zarr"
    root = r.resolve()
    for section, entries in out.items():
        for name, paths in entries.items():
            for p in paths.values():
                resolved = p.resolve()
                # the experiment's own folder must lie strictly below results, not be results itself
                if root not in resolved.parents or resolved.parent == root:
                    raise ConfigError(
                        f"{section}.{name}: output {p} would lie outside the results folder {r} (resolves to "
                        f"{resolved}); use a plain name of letters, digits, '_', '-' and '.'"
                    )
    return out


#: the demo's record of every path it wrote (relative to its folder): the next run removes these and nothing else
_DEMO_RECORD = ".irdic-demo-files.json"


def _demo_tree(out: Path) -> list[str]:
    """Every file, link and folder under ``out`` (``.zarr`` stores as one entry), relative, deepest first."""
    found = []
    for dirpath, dirnames, filenames in os.walk(out):  # does not follow links
        rel = Path(dirpath).relative_to(out)
        for d in list(dirnames):
            p = Path(dirpath) / d
            if d.endswith(".zarr") or p.is_symlink():
                dirnames.remove(d)
                found.append((rel / d).as_posix())
        found += [(rel / f).as_posix() for f in filenames]
        if rel != Path("."):
            found.append(rel.as_posix())
    return sorted(found, key=lambda r: (-r.count("/"), r))


def _demo_removals(out: Path) -> list[str]:
    """What a new demo run may remove from ``out``: the paths the last run recorded.

    Raises :class:`ConfigError` when ``out`` holds anything else (dot files
    and folders included), before anything is touched.
    """
    if not out.exists():
        return []
    if not out.is_dir():
        raise ConfigError(f"{out}: the demo folder exists and is a file; choose a new or empty folder for the demo")
    record = out / _DEMO_RECORD
    recorded: set[str] = set()
    if record.is_file():
        try:
            recorded = set(json.loads(record.read_text(encoding="utf-8")))
        except (OSError, ValueError, TypeError):
            raise ConfigError(f"{record}: the demo's record of its files is unreadable; "
                              "choose a new or empty folder for the demo") from None
        recorded.add(_DEMO_RECORD)
    tree = _demo_tree(out)
    # a folder is the demo's when the demo wrote it (recorded) or all it holds is the demo's
    foreign = [r for r in tree if r not in recorded]
    if foreign:
        tops = sorted({r.split("/", 1)[0] for r in foreign})
        raise ConfigError(
            f"{out}: folder exists and holds {', '.join(tops[:5])}{' ...' if len(tops) > 5 else ''}, "
            "which the demo did not write; choose an empty or new folder for the demo"
        )
    return tree


def make_demo(outdir: str | os.PathLike, *, scale: str = "demo", ir_noise: float = 0.05,
              dic_noise: float = 0.005, seed: int = 0, manifest: str | os.PathLike | None = None) -> Path:
    """Generate the synthetic demo (raw exports + truth) under ``outdir``.

    What an earlier demo wrote into ``outdir`` is removed first, file by
    file, from the record it kept (``.irdic-demo-files.json``); a folder
    holding anything else (dot files included) is refused before anything
    is touched, as is a symbolic link. ``manifest`` (default
    ``outdir/manifest.yaml``) summarises what was written and is written
    last, so its presence means the demo is complete.

    Raises
    ------
    ConfigError
        An invalid argument, or ``outdir`` holds files the demo did not
        write, is a file or is a symbolic link.
    """
    from . import synthetic
    from .validation import as_int, choice, positive
    from .synthetic.experiments import SCALES

    # every argument is checked before the disk is touched
    choice(scale, "scale", SCALES)
    ir_noise = positive(ir_noise, "ir_noise", allow_zero=True)
    dic_noise = positive(dic_noise, "dic_noise", allow_zero=True)
    seed = as_int(seed, "seed", minimum=0)
    out = Path(outdir)
    if out.is_symlink():
        raise ConfigError(f"{out}: the demo folder is a symbolic link (to {os.readlink(out)}); give the folder "
                          "itself: the demo replaces what it wrote and does not write through links")
    man = Path(manifest) if manifest is not None else out / "manifest.yaml"
    removals = _demo_removals(out)
    for rel in removals:  # deepest first, so folders are empty when their turn comes
        p = out / rel
        if p.is_dir() and not p.is_symlink():
            if p.name.endswith(".zarr"):
                shutil.rmtree(p)
            else:
                p.rmdir()
        elif os.path.lexists(p):
            p.unlink()
    out.mkdir(parents=True, exist_ok=True)
    written = synthetic.make_demo(out, scale=scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed)
    tree = _demo_tree(out)
    try:
        in_out = man.resolve().relative_to(out.resolve()).as_posix()
        tree.append(in_out)
    except ValueError:
        pass  # a manifest outside the folder is not the demo's to remove
    _write_text_atomic(out / _DEMO_RECORD, json.dumps(sorted(set(tree)), indent=0))
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*")
                   if p.is_file() and not any(part.endswith(".zarr") for part in p.parts)
                   and not p.name.startswith("."))
    _write_text_atomic(man, yaml.safe_dump({"scale": scale, "ir_noise": ir_noise, "dic_noise": dic_noise,
                                            "seed": seed, "n_files": len(files), "contents": _jsonable(written)},
                                           sort_keys=False))
    log.info("demo written to %s (%d files)", out, len(files))
    return out


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def ingest_experiment(exp: Mapping, dic_out: str | os.PathLike, ir_out: str | os.PathLike,
                      machine_out: str | os.PathLike | None = None) -> None:
    """Ingest one experiment's DIC and IR exports (``exp`` as in the configuration).

    The testing machine record (``exp["machine"]``) goes to ``machine_out``
    when both are given.
    """
    dic = dict(exp["dic"])
    ir = dict(exp["ir"])
    ingest_dic(dic.pop("path"), dic_out, **dic)
    ingest_ir(ir.pop("path"), ir_out, **ir)
    if exp.get("machine") and machine_out is not None:
        from .signals import ingest_machine

        machine = dict(exp["machine"])
        ingest_machine(machine.pop("path"), machine_out, **machine)


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
    from .calibration import calibrate_from_files

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
            ingest_experiment(e, p["dic"], p["ir"], p.get("machine"))
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
            fields_stores(p["points"], cal, p["fields"], dic=p["dic"], machine=p.get("machine"),
                          **config.get("fields", {}))
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
