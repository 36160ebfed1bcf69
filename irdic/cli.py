"""``irdic`` command line: run a stage without Snakemake, or look into a store.

Examples
--------
::

    irdic demo resources/demo --scale tiny
    irdic ingest-ir resources/demo/tube/ir results/tube/ir.zarr
    irdic ingest-dic resources/demo/tube/dic results/tube/dic.zarr
    irdic calibrate --markers resources/demo/setup/markers.txt \\
        --target resources/demo/setup/target.txt --out results/setups/lab/calibration.zarr
    irdic couple --dic results/tube/dic.zarr --ir results/tube/ir.zarr \\
        --calibration results/setups/lab/calibration.zarr --out results/tube/points.zarr
    irdic fields --points results/tube/points.zarr \\
        --calibration results/setups/lab/calibration.zarr --out results/tube/fields.zarr \\
        --set fields.c_space=1.2 --set fields.temperature_smoothing=gcv
    irdic heat --fields results/tube/fields.zarr --points results/tube/points.zarr \\
        --out results/tube/heat.zarr --density 7850 --specific-heat 470 --conductivity 50 \\
        --loss-time-constant 60
    irdic figures --points results/tube/points.zarr --fields results/tube/fields.zarr \\
        --out results/tube/figures --experiment tube
    irdic export --points results/tube/points.zarr --fields results/tube/fields.zarr --out results/tube
    irdic report results
    irdic run --config config/config.yaml --set interpolation.c_space=2.5
    irdic info results/tube/ir.zarr
    irdic --version
"""

from __future__ import annotations

import argparse
import json
import sys
import traceback
from pathlib import Path
from typing import Sequence

from .errors import ConfigError, IrdicError

__all__ = ["main", "describe_store"]


def _table(rows: Sequence[Sequence[str]], indent: str = "    ") -> list[str]:
    """Rows of text cells with every column as wide as its widest cell (the last one left ragged)."""
    if not rows:
        return []
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]) - 1)]
    return [(indent + "  ".join(c.ljust(w) for c, w in zip(r, widths)) + "  " + r[-1]).rstrip() for r in rows]


def _span(c) -> str:
    """The range of a coordinate: ``first .. last`` of numbers, the first labels of text."""
    import numpy as np

    v = np.asarray(c.values)
    if v.size == 0:
        return "(empty)"
    if v.dtype.kind in "iuf":
        finite = v[np.isfinite(v)] if v.dtype.kind == "f" else v
        if finite.size == 0:
            return "(all NaN)"
        return f"{finite.min():.6g} .. {finite.max():.6g}"
    labels = [str(x) for x in v.ravel()[:6]]
    return ", ".join(labels) + (", ..." if v.size > 6 else "")


def _time_offset(text: str):
    """``--time-offset``: seconds, or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds or auto, got {text!r}") from None


def describe_store(path) -> str:
    """A readable summary of an irdic zarr store.

    Dimensions; coordinates with their units and ranges; variables with
    dimensions, units and ``long_name``; the meaning of each value of a
    flag variable (``flag_values``/``flag_meanings``, e.g. ``points.status``);
    provenance and the other dataset attributes. Columns are aligned.
    """
    from .store import open_store

    ds = open_store(path)
    lines = [f"{path}", "  dimensions: " + ", ".join(f"{k}={v}" for k, v in ds.sizes.items())]
    lines.append("  coordinates:")
    lines += _table([(name, str(c.dims), c.attrs.get("units", ""), _span(c), c.attrs.get("long_name", ""))
                     for name, c in ds.coords.items()])
    lines.append("  variables:")
    lines += _table([(name, str(v.dims), str(v.attrs.get("units", "")), v.attrs.get("long_name", ""))
                     for name, v in ds.data_vars.items()])
    for name, v in {**ds.coords, **ds.data_vars}.items():
        values, meanings = v.attrs.get("flag_values"), v.attrs.get("flag_meanings")
        if values is not None and meanings:
            lines.append(f"  meaning of {name}:")
            lines += _table([(str(k), m.replace("_", " ")) for k, m in zip(values, str(meanings).split())])
    a = ds.attrs
    lines.append(f"  stage: {a.get('irdic_stage', '?')}  irdic {a.get('irdic_version', '?')}  created {a.get('irdic_created', '?')}")
    from .timing.summary import clock_summary

    if clock_summary(a):
        lines.append("  " + clock_summary(a))
    params = a.get("irdic_parameters")
    if params:
        try:
            lines.append("  parameters: " + json.dumps(json.loads(params), sort_keys=True))
        except ValueError:
            lines.append(f"  parameters: {params}")
    other = {k: v for k, v in a.items() if not k.startswith("irdic_")}
    if other:
        lines.append("  attributes:")
        lines += _table([(k, str(v)) for k, v in list(other.items())[:30]])
    return "\n".join(lines)


#: the configuration section whose keys ``--set`` may change, per command (schema node, when it differs)
SECTIONS = {"demo": ("demo", None), "ingest-ir": ("ir", "ir_source"), "ingest-dic": ("dic", "dic_source"),
            "calibrate": ("calibration", None), "couple": ("interpolation", None), "fields": ("fields", None),
            "heat": ("material", None), "export": ("export", None)}

_SET_HELP = ("set a parameter as in config.yaml, e.g. {example}; repeatable; checked by the configuration "
             "schema (irdic/schemas/config.schema.yaml lists every key, its default and unit)")


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    p = argparse.ArgumentParser(prog="irdic", description="Couple stereo DIC and infrared thermography.",
                                epilog="Each stage command reads stores or exports and writes one output; "
                                "'irdic COMMAND --help' describes it.")
    p.add_argument("--version", action="version", version=f"irdic {__version__}")
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    # --debug is also accepted after the command; SUPPRESS keeps a top-level --debug from being reset
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show the traceback of an error")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="CPU threads for BLAS/OpenMP (default: all cores this process may use)")
    common.add_argument("--threads", type=int, default=argparse.SUPPRESS, metavar="N",
                        help="CPU threads for BLAS/OpenMP (default: all cores this process may use)")
    sub = p.add_subparsers(dest="command", required=True)

    def add_parser(name, help, **kw):
        s = sub.add_parser(name, parents=[common], help=help, description=kw.pop("description", help), **kw)
        if name in SECTIONS:
            section = SECTIONS[name][0]
            s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="settings",
                           help=_SET_HELP.format(example=f"{section}.KEY=VALUE"))
        return s

    s = add_parser("info", "summarise an irdic zarr store: dimensions, coordinate ranges, variables, "
                   "flag meanings, provenance")
    s.add_argument("store")

    s = add_parser("demo", "write the synthetic demo experiment")
    s.add_argument("outdir")
    s.add_argument("--scale", choices=["tiny", "demo", "paper"], help="default: the schema's demo.scale")
    s.add_argument("--ir-noise", type=float, help="K")
    s.add_argument("--dic-noise", type=float, help="mm")
    s.add_argument("--seed", type=int)
    s.add_argument("--ir-format", choices=["irbis", "flir"], help="default: the schema's demo.ir_format")

    for kind in ("ir", "dic"):
        s = add_parser(f"ingest-{kind}", f"{kind.upper()} exports -> {kind}.zarr")
        s.add_argument("source", help="folder, glob or file")
        s.add_argument("out", help="store to write")
        s.add_argument("--format")
        s.add_argument("--frame-rate", type=float, help="Hz")
        s.add_argument("--time-source", choices=["file", "frame_rate"])
        s.add_argument("--time-origin", choices=["first", "file"])
        s.add_argument("--time-offset", type=_time_offset, help="s, or auto (IR: estimated by the couple stage)")
        if kind == "ir":
            s.add_argument("--emissivity", type=float, help="FLIR files: replaces the camera's emissivity")
            s.add_argument("--reflected-temperature", type=float,
                           help="FLIR files: replaces the camera's reflected apparent temperature (°C)")

    _stage_parsers(add_parser)
    _heat_parser(add_parser)
    _output_parsers(add_parser)
    return p


def _stage_parsers(add_parser) -> None:
    """The sub-commands of the stages that write stores."""
    s = add_parser("calibrate", "calibrate the IR camera from one target image")
    s.add_argument("--markers", required=True, help="marker centres export (ID, x, y, z in mm)")
    s.add_argument("--target", required=True, help="IR image of the reference object")
    s.add_argument("--out", required=True, help="calibration.zarr to write")
    s.add_argument("--figure", default=None, help="PNG of detections and residuals")
    s.add_argument("--distortion", choices=["none", "k1", "k1k2"])
    s.add_argument("--polarity", choices=["auto", "dark", "bright"])

    s = add_parser("couple", "temperatures at the DIC points -> points.zarr")
    s.add_argument("--dic", required=True, help="dic.zarr")
    s.add_argument("--ir", required=True, help="ir.zarr")
    s.add_argument("--calibration", required=True, help="calibration.zarr")
    s.add_argument("--out", required=True, help="points.zarr to write")
    s.add_argument("--method", choices=["rbf", "bilinear", "cubic"])

    s = add_parser("fields", "gradient, rate and strain fields -> fields.zarr")
    s.add_argument("--points", required=True, help="points.zarr")
    s.add_argument("--calibration", required=True, help="calibration.zarr")
    s.add_argument("--out", required=True, help="fields.zarr to write")
    s.add_argument("--temperature-smoothing", help="none (default), gcv or a number >= 1")
    s.add_argument("--dic", default=None, help="dic.zarr: its testing machine signals at the DIC times")
    s.add_argument("--machine", default=None, help="machine.zarr: the machine record at the DIC times")


def _heat_parser(add_parser) -> None:
    s = add_parser("heat", "heat source and the terms of the local heat balance -> heat.zarr",
                   description="The heat source s = rho c (dTheta/dt + (Theta - Theta0)/tau) - k Laplacian(Theta) "
                   "of a thin wall at the DIC points (docs/heat.md); the material as in an experiment's material "
                   "block (--set material.cooling=[t0,t1] etc.).")
    s.add_argument("--fields", required=True, help="fields.zarr")
    s.add_argument("--points", required=True, help="points.zarr")
    s.add_argument("--out", required=True, help="heat.zarr to write")
    s.add_argument("--density", type=float, help="kg/m^3")
    s.add_argument("--specific-heat", dest="specific_heat", type=float, help="J/(kg K)")
    s.add_argument("--conductivity", type=float, help="W/(m K)")
    s.add_argument("--loss-time-constant", dest="loss_time_constant", help="s, none or auto (needs material.cooling)")


def _time_constant(text):
    """``--loss-time-constant``: a number (s), none or auto (checked by the schema)."""
    if text in ("none", "auto"):
        return None if text == "none" else "auto"
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"--loss-time-constant must be a number (s), none or auto, got {text!r}") from None


def _output_parsers(add_parser) -> None:
    """The sub-commands that present results: figures, export, report, and run."""
    for name, what in (("figures", "the PNG figures of one experiment -> OUTDIR/<figure>.png"),
                       ("export", "ParaView time series and CSV table of one experiment -> OUTDIR/paraview, "
                        "OUTDIR/points.csv")):
        s = add_parser(name, what)
        s.add_argument("--points", required=True, help="points.zarr")
        s.add_argument("--fields", default=None, help="fields.zarr (gradients, rates, strains, signals)")
        s.add_argument("--out", required=True, metavar="OUTDIR", help="folder to write")
        s.add_argument("--experiment", default="experiment", help="name of the experiment (titles, messages)")
        s.add_argument("--point-ids", type=int, nargs="+", default=[], metavar="ID",
                       help="DIC point IDs to show (default: the point nearest the centre)")
        if name == "figures":
            s.add_argument("--times", type=float, nargs="+", default=[], metavar="T",
                           help="times (s) of the maps (default: the middle and the last DIC time)")

    s = add_parser("report", "an HTML page of every figure under a results folder, each with its caption",
                   description="Collect the figures (calibration.png and <experiment>/figures/*.png) under RESULTS "
                   "into one self-contained HTML page, each with the caption the figure carries. "
                   "'snakemake --report' gives Snakemake's richer report of the same figures.")
    s.add_argument("results", nargs="?", default="results", help="results folder (default: results)")
    s.add_argument("--out", default=None, help="HTML file to write (default: RESULTS/report.html)")

    s = add_parser("run", "run all stages of a configuration without Snakemake",
                   description="Run every stage (demo, ingest, calibrate, couple, fields, figures, export, "
                   "report) for every setup and experiment of a configuration, in order, without Snakemake. "
                   "A job whose inputs, parameters and code are unchanged since it wrote its outputs is skipped "
                   "(records in RESULTS/.irdic/runs); --force runs every job. Outputs go to the configuration's "
                   "results folder; the output paths are printed as JSON.")
    s.add_argument("--config", default="config/config.yaml", help="configuration file (default: config/config.yaml)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="settings",
                   help=_SET_HELP.format(example="interpolation.c_space=2.5 or experiments.s07.ir.time_offset=0.2"))
    s.add_argument("--force", action="store_true",
                   help="run every stage, also those whose inputs, parameters and code are unchanged")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``irdic`` command."""
    args = _parser().parse_args(argv)
    try:
        _run(args)
    except BaseException as exc:  # noqa: BLE001 - the command line answers everything in one line
        if isinstance(exc, SystemExit):
            raise
        if args.debug:
            traceback.print_exc()
        code, line = _one_line(exc)
        print(f"irdic: {line}", file=sys.stderr)
        return code
    return 0


def _one_line(exc: BaseException) -> tuple[int, str]:
    """Exit status and the one line the user sees for an exception."""
    if isinstance(exc, IrdicError):
        code, text = 2, f"error: {exc}"
    elif isinstance(exc, KeyboardInterrupt):
        code, text = 130, "interrupted; outputs being written were discarded, finished ones are kept"
    elif isinstance(exc, MemoryError):
        code, text = 1, ("error: out of memory; process fewer frames or points at a time "
                         "(e.g. a coarser scale or a subset), or use a machine with more memory")
    elif isinstance(exc, OSError):
        what = exc.strerror or str(exc) or type(exc).__name__
        where = exc.filename if exc.filename is not None else None
        code, text = 1, f"error: {where}: {what}" if where is not None else f"error: {what}"
    else:
        code, text = 1, (f"internal error: {type(exc).__name__}: {exc} (a bug in irdic; run again with --debug "
                         "for the traceback and report it)")
    return code, " ".join(text.split())  # one line, whatever the message holds


def _run(args: argparse.Namespace) -> None:
    from .logs import configure

    configure(None)
    if args.threads is not None and args.threads < 1:  # checked for every command, info included
        raise ConfigError(f"--threads must be a whole number of CPU threads >= 1, got {args.threads}")
    # each stage entry (and pipeline.run) applies --threads once
    _dispatch(args)


def _given(args, *names) -> dict:
    """The options among ``names`` given on the command line (the others take the schema's defaults)."""
    return {n: getattr(args, n) for n in names if getattr(args, n) is not None}


def _smoothing(text: str):
    """``--temperature-smoothing``: none, gcv or a number (checked by the fields stage)."""
    if text == "none":
        return None
    if text == "gcv":
        return "gcv"
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"--temperature-smoothing must be none, gcv or a number >= 1, got {text!r}") from None


def _section(args, flags: dict) -> dict:
    """The parameters of a stage command: its section from ``--set``, the flags on top, checked by the schema."""
    from .config import parse_setting, validate_section

    section, node = SECTIONS[args.command]
    values: dict = {}
    for text in args.settings:
        keys, value = parse_setting(text)
        if keys[0] != section or len(keys) != 2:
            raise ConfigError(f"--set {text!r}: irdic {args.command} takes {section}.KEY=VALUE "
                              f"(its keys: irdic/schemas/config.schema.yaml, section {node or section})")
        values[keys[1]] = value
    values.update(flags)
    if node in ("ir_source", "dic_source"):
        values["path"] = args.source  # required by the schema; the stage takes it as its input
        return {k: v for k, v in validate_section(section, values, schema_node=node).items() if k != "path"}
    return validate_section(section, values, schema_node=node)


def _with_settings(config: dict, settings: Sequence[str]) -> dict:
    """``config`` with each ``--set a.b.c=value`` applied, validated again as a whole."""
    from .config import parse_setting, validate_config

    for text in settings:
        keys, value = parse_setting(text)
        node = config
        for k in keys[:-1]:
            if not isinstance(node.get(k), dict):
                node[k] = {}
            node = node[k]
        node[keys[-1]] = value
    return validate_config(config)


def _dispatch(args) -> None:
    """Run the sub-command of the parsed ``args`` (threads are set once, by :func:`_run`)."""
    if args.command == "info":
        print(describe_store(args.store))
        return
    if args.command == "run":
        from .config import load_config
        from .pipeline import run

        config = load_config(args.config)
        if args.settings:
            try:
                config = _with_settings(config, args.settings)
            except ConfigError as exc:
                raise ConfigError(f"{args.config} with --set: {exc}") from None
        paths = run(config, threads=args.threads, force=args.force, name=args.config)
        print(json.dumps(paths, default=str, indent=2))
        return
    if args.command == "report":
        from .stages import report

        out = Path(args.out) if args.out else Path(args.results) / "report.html"
        root = Path(args.results)
        stores = sorted(root.glob("setups/*/calibration.zarr")) + sorted(root.glob("*/fields.zarr"))
        report.run({"results": args.results, "stores": stores}, {"html": out}, threads=args.threads)
        print(out)
        return
    if args.command == "demo":
        from .stages import demo

        params = _section(args, _given(args, "scale", "ir_noise", "dic_noise", "seed", "ir_format"))
        params.pop("enabled", None)
        params.pop("outdir", None)
        demo.run({}, {"manifest": Path(args.outdir) / "manifest.yaml"}, threads=args.threads, **params)
        return
    if args.command in ("figures", "export"):
        _present(args)
        return
    if args.command in ("ingest-ir", "ingest-dic"):
        from .stages import ingest_dic, ingest_ir

        stage = ingest_ir if args.command == "ingest-ir" else ingest_dic
        flags = ("format", "frame_rate", "time_source", "time_origin", "time_offset") + \
            (("emissivity", "reflected_temperature") if args.command == "ingest-ir" else ())
        stage.run({"source": args.source}, {"store": args.out}, threads=args.threads,
                  **_section(args, _given(args, *flags)))
    elif args.command == "calibrate":
        from .stages import calibrate

        calibrate.run({"markers": args.markers, "target": args.target}, {"store": args.out, "figure": args.figure},
                      threads=args.threads, **_section(args, _given(args, "distortion", "polarity")))
    elif args.command == "couple":
        from .stages import couple

        couple.run({"dic": args.dic, "ir": args.ir, "calibration": args.calibration}, {"store": args.out},
                   threads=args.threads, **_section(args, _given(args, "method")))
    elif args.command == "fields":
        from .stages import fields

        flags = {}
        if args.temperature_smoothing is not None:
            flags["temperature_smoothing"] = _smoothing(args.temperature_smoothing)
        fields.run({"points": args.points, "calibration": args.calibration, "dic": args.dic,
                    "machine": args.machine}, {"store": args.out}, threads=args.threads, **_section(args, flags))
    elif args.command == "heat":
        from .stages import heat

        flags = _given(args, "density", "specific_heat", "conductivity")
        if args.loss_time_constant is not None:
            flags["loss_time_constant"] = _time_constant(args.loss_time_constant)
        heat.run({"fields": args.fields, "points": args.points}, {"store": args.out}, threads=args.threads,
                 **_section(args, flags))
    print(describe_store(args.out))


def _present(args) -> None:
    """``irdic figures`` / ``irdic export``: the figures or the export of one experiment into ``args.out``."""
    from .plot import FIGURES
    from .stages import export, figures

    out = Path(args.out)
    inputs = {"points": args.points, "fields": args.fields}
    if args.command == "figures":
        names = [n for n in FIGURES if n not in ("strain", "load") or args.fields]
        outputs = {n: out / f"{n}.png" for n in names}
        figures.run(inputs, outputs, threads=args.threads, experiment=args.experiment, times=args.times,
                    points=args.point_ids)
        print("\n".join(str(p) for p in outputs.values()))
    else:
        export.run(inputs, {"paraview": out / "paraview", "csv": out / "points.csv"}, threads=args.threads,
                   experiment=args.experiment, points=args.point_ids, **_section(args, {}))
        print(f"{out / 'paraview'}\n{out / 'points.csv'}")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
