"""The whole pipeline without Snakemake: every stage for every setup and experiment, in order.

:func:`run` calls the same stage entries as the Snakemake scripts and the
command line (``irdic.stages.<stage>.run``), with the paths of
:func:`stage_paths` and the sections of a validated configuration. A job
whose inputs, parameters and code are unchanged since it wrote its outputs is
skipped (:class:`irdic.runs.Ledger`, records under ``<results>/.irdic/runs``);
``force=True`` runs every job.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Mapping

from .errors import ConfigError
from .threads import stage_threads

__all__ = ["run", "stage_paths", "check_inputs", "STAGES"]


def stage_paths(config: Mapping) -> dict:
    """Output paths of every stage (the contract of the results folder).

    Raises
    ------
    ConfigError
        A setup or experiment name would put an output outside the results
        folder (``../x``, an absolute path, a link leading elsewhere).
    """
    r = Path(config["results"])
    out = {"setups": {}, "experiments": {}}
    for s in config["setups"]:
        out["setups"][s] = {"calibration": r / "setups" / s / "calibration.zarr",
                            "figure": r / "setups" / s / "calibration.png"}
    for e in config["experiments"]:
        out["experiments"][e] = {k: r / e / f"{k}.zarr" for k in ("dic", "ir", "points", "fields")}
        if config["experiments"][e].get("machine"):
            out["experiments"][e]["machine"] = r / e / "machine.zarr"
        if config["experiments"][e].get("material"):
            out["experiments"][e]["heat"] = r / e / "heat.zarr"
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


STAGES = ("demo", "ingest", "calibrate", "couple", "fields", "heat", "figures", "export", "report")


def _in_demo(config: Mapping, path) -> bool:
    """True when ``path`` lies in the demo folder that the demo stage writes (it need not exist yet)."""
    d = config.get("demo", {})
    if not d.get("enabled"):
        return False
    demo, p = os.path.normpath(d["outdir"]), os.path.normpath(path)
    return p == demo or p.startswith(demo + os.sep)


def check_inputs(config: Mapping) -> None:
    """Check that every configured input (folder, glob or file) holds files, before any stage runs.

    Inputs inside the demo folder are skipped when the demo is enabled (the
    demo stage writes them).

    Raises
    ------
    ConfigError
        Naming the configuration key of every missing or empty input at once
        (``experiments.<name>.dic.path: ...``).
    """
    from .errors import DataError
    from .ingest.inputs import list_inputs

    keys = []
    for name, s in config.get("setups", {}).items():
        keys += [(f"setups.{name}.markers.path", s["markers"]["path"]),
                 (f"setups.{name}.target_image.path", s["target_image"]["path"])]
    for name, e in config.get("experiments", {}).items():
        keys += [(f"experiments.{name}.{kind}.path", e[kind]["path"]) for kind in ("dic", "ir", "machine")
                 if e.get(kind)]
    problems = []
    for key, path in keys:
        if _in_demo(config, path):
            continue
        try:
            list_inputs(path)
        except DataError as exc:
            problems.append(f"{key}: {exc}")
    if problems:
        raise ConfigError(f"{len(problems)} configured input(s) not found (paths are relative to the working "
                          f"directory {os.getcwd()}): " + "; ".join(problems))


def run(config: Mapping, *, stages: tuple[str, ...] = STAGES, threads: int | None = None,
        force: bool = False, name: str | None = None) -> dict:
    """Run the configured stages for every setup and experiment, in order.

    Parameters
    ----------
    config : mapping
        A validated configuration (see :func:`irdic.config.load_config`):
        its defaults are filled in.
    stages : tuple of str
        Which stages to run.
    threads : int, optional
        CPU threads for BLAS/OpenMP in every stage; default all cores this
        process may use.
    force : bool
        Run every job, also those whose inputs, parameters and code are
        unchanged since their last run (skipped otherwise).
    name : str, optional
        What the configuration is called on the report page (its file);
        default "configuration".

    Returns
    -------
    dict
        The output paths (see :func:`stage_paths`).
    """
    unknown = set(stages) - set(STAGES)
    if unknown:
        raise ConfigError(f"unknown stage(s) {sorted(unknown)}; expected {', '.join(STAGES)}")
    if {"ingest", "calibrate"} & set(stages):  # the only stages that read the raw exports
        check_inputs(config)
    from .runs import Ledger

    ledger = Ledger(config["results"], force=force)
    runners = {**_RUNNERS, "report": functools.partial(_report, title=name or "configuration")}
    with stage_threads(threads) as n:
        paths = stage_paths(config)
        for stage in STAGES:
            if stage in stages:
                runners[stage](config, paths, n, ledger)
    return paths


def _raw(path) -> list:
    """The files of a configured raw input (folder, glob or file): what a job reads from it."""
    from .ingest.inputs import list_inputs

    return list_inputs(path)


def _demo(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import demo

    d = config["demo"]
    manifest = Path(d["outdir"]) / "manifest.yaml"
    settings = {k: v for k, v in d.items() if k not in ("enabled", "outdir")}
    if d["enabled"]:
        # regenerated when its settings or code change; an edited demo file is an input change of ingest
        ledger.run("demo", code_hash("demo"), settings, [], [manifest],
                   lambda: demo.run({}, {"manifest": manifest}, threads=threads, **settings))


def _calibrate(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import calibrate

    for name, s in config["setups"].items():
        p = paths["setups"][name]
        params = dict(target_format=s["target_image"]["format"], seeds=s["seeds"], **config["calibration"])
        inputs = {"markers": s["markers"]["path"], "target": s["target_image"]["path"]}
        outputs = {"store": p["calibration"], "figure": p["figure"]}
        ledger.run(f"calibrate/{name}", code_hash("calibrate"), params,
                   _raw(inputs["markers"]) + _raw(inputs["target"]), outputs.values(),
                   lambda: calibrate.run(inputs, outputs, threads=threads, **params))


def _source(section: Mapping) -> tuple[dict, dict]:
    """``({"source": path}, the other settings)`` of an experiment's ``dic``/``ir``/``machine`` entry."""
    rest = dict(section)
    return {"source": rest.pop("path")}, rest


def _ingest(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import ingest_dic, ingest_ir, ingest_machine

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        stages = [("dic", ingest_dic, {}), ("ir", ingest_ir, {})]
        if e.get("machine"):  # optional: no schema default
            stages.append(("machine", ingest_machine, {"ir": p["ir"]}))
        for kind, stage, extra in stages:
            src, rest = _source(e[kind])
            out = {"store": p[kind]}
            ledger.run(f"ingest_{kind}/{name}", code_hash(f"ingest_{kind}"), {**src, **rest},
                       _raw(src["source"]) + list(extra.values()), out.values(),
                       lambda stage=stage, src=src, rest=rest, extra=extra, out=out:
                       stage.run({**src, **extra}, out, threads=threads, **rest))


def _chunked(stage, config, inputs, store, times_of, threads, params):
    """Run ``stage`` in the configured time chunks (then gather them into ``store``), or whole.

    ``times_of``: the store whose time axis is chunked (opened only when chunking is on).
    """
    from .chunks import chunk_path, n_chunks

    per_chunk = config.get("execution", {}).get("chunk_frames", 0)
    n = n_chunks(_n_times(times_of), per_chunk) if per_chunk else 1
    if n == 1:
        stage.run(inputs, {"store": store}, threads=threads, **params)
        return
    kind = Path(store).stem
    parts = [chunk_path(Path(store).parent, kind, i) for i in range(n)]
    for i, part in enumerate(parts):
        stage.run(inputs, {"store": part}, threads=threads, chunk=(i, n), **params)
    stage.run_gather({"chunks": parts}, {"store": store}, threads=threads, **params)


def _n_times(store) -> int:
    from .store import open_store

    return int(open_store(store).sizes["time"])


def _couple(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import couple

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        cal = paths["setups"][e["setup"]]["calibration"]
        inputs = {"dic": p["dic"], "ir": p["ir"], "calibration": cal}
        params = {**config["interpolation"], "chunk_frames": config.get("execution", {}).get("chunk_frames", 0)}
        ledger.run(f"couple/{name}", code_hash("couple"), params, inputs.values(), [p["points"]],
                   lambda inputs=inputs, p=p: _chunked(couple, config, inputs, p["points"], p["dic"], threads,
                                                       config["interpolation"]))


def _fields(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import fields

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        inputs = {"points": p["points"], "calibration": paths["setups"][e["setup"]]["calibration"],
                  "dic": p["dic"]}
        if "machine" in p:
            inputs["machine"] = p["machine"]
        params = {**config["fields"], "chunk_frames": config.get("execution", {}).get("chunk_frames", 0)}
        ledger.run(f"fields/{name}", code_hash("fields"), params, inputs.values(), [p["fields"]],
                   lambda inputs=inputs, p=p: _chunked(fields, config, inputs, p["fields"], p["points"], threads,
                                                       config["fields"]))


def _heat(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import heat

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        if "heat" not in p:  # only experiments with a material block
            continue
        inputs = {"fields": p["fields"], "points": p["points"]}
        params = {"fields_settings": config["fields"], **e["material"]}
        ledger.run(f"heat/{name}", code_hash("heat"), params, inputs.values(), [p["heat"]],
                   lambda inputs=inputs, p=p, params=params:
                   heat.run(inputs, {"store": p["heat"]}, threads=threads, **params))


def _heat_store(p):
    """An experiment's heat.zarr when it has a material block and the store was written, else None."""
    return p["heat"] if "heat" in p and Path(p["heat"]).exists() else None


def _figures(config, paths, threads, ledger):
    from .codehash import code_hash
    from .plot import FIGURES, HEAT_FIGURE
    from .stages import figures

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        have_fields = Path(p["fields"]).exists()
        folder = Path(p["points"]).parent / "figures"
        names = [n for n in FIGURES if n not in ("strain", "load") or have_fields]
        heat = _heat_store(p) if have_fields else None
        names += [HEAT_FIGURE] if heat is not None else []
        inputs = {"points": p["points"], "fields": p["fields"] if have_fields else None, "heat": heat}
        outputs = {n: folder / f"{n}.png" for n in names}
        params = dict(experiment=name, times=e["report"]["times"], points=e["report"]["points"])
        ledger.run(f"figures/{name}", code_hash("figures"), params, [v for v in inputs.values() if v],
                   outputs.values(),
                   lambda inputs=inputs, outputs=outputs, params=params:
                   figures.run(inputs, outputs, threads=threads, **params))


def _export(config, paths, threads, ledger):
    from .codehash import code_hash
    from .stages import export

    for name, e in config["experiments"].items():
        p = paths["experiments"][name]
        folder = Path(p["points"]).parent
        have_fields = Path(p["fields"]).exists()
        inputs = {"points": p["points"], "fields": p["fields"] if have_fields else None,
                  "heat": _heat_store(p) if have_fields else None}
        outputs = {"paraview": folder / "paraview", "csv": folder / "points.csv"}
        params = dict(experiment=name, points=e["report"]["points"], **config["export"])
        ledger.run(f"export/{name}", code_hash("export"), params, [v for v in inputs.values() if v],
                   outputs.values(),
                   lambda inputs=inputs, outputs=outputs, params=params:
                   export.run(inputs, outputs, threads=threads, **params))


def _report(config, paths, threads, ledger, title="configuration"):
    from .codehash import code_hash
    from .stages import report

    from .config import non_defaults
    from .plot import FIGURES, HEAT_FIGURE

    results = Path(config["results"])
    # exactly this configuration's setups and experiments (a results folder may hold others)
    figures = [paths["setups"][s]["figure"] for s in config["setups"]]
    for name in config["experiments"]:
        folder = Path(paths["experiments"][name]["points"]).parent / "figures"
        figures += [folder / f"{n}.png" for n in (*FIGURES, HEAT_FIGURE) if (folder / f"{n}.png").exists()]
    stores = [paths["setups"][s]["calibration"] for s in config["setups"]]
    stores += [paths["experiments"][e]["fields"] for e in config["experiments"]]
    params = {"title": title, "settings": non_defaults(config)}
    ledger.run("report", code_hash("report"), params, [*figures, *stores], [results / "report.html"],
               lambda: report.run({"figures": figures, "stores": stores}, {"html": results / "report.html"},
                                  threads=threads, **params))


_RUNNERS = {"demo": _demo, "ingest": _ingest, "calibrate": _calibrate, "couple": _couple, "fields": _fields,
            "heat": _heat, "figures": _figures, "export": _export, "report": _report}
