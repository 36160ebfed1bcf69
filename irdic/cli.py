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
    irdic run --config config/config.yaml
    irdic info results/tube/ir.zarr
"""

from __future__ import annotations

import argparse
import json
import sys
import traceback
from pathlib import Path
from typing import Sequence

from .errors import IrdicError

__all__ = ["main", "describe_store"]


def describe_store(path) -> str:
    """A readable summary of an irdic zarr store: dims, variables with units, provenance."""
    from .store import open_store

    ds = open_store(path)
    lines = [f"{path}", "  dimensions: " + ", ".join(f"{k}={v}" for k, v in ds.sizes.items())]
    lines.append("  coordinates:")
    for name, c in ds.coords.items():
        lines.append(f"    {name:<28} {str(c.dims):<28} {c.attrs.get('units', '')}")
    lines.append("  variables:")
    for name, v in ds.data_vars.items():
        desc = v.attrs.get("long_name", "")
        lines.append(f"    {name:<28} {str(v.dims):<28} {v.attrs.get('units', ''):<8} {desc}")
    a = ds.attrs
    lines.append(f"  stage: {a.get('irdic_stage', '?')}  irdic {a.get('irdic_version', '?')}  created {a.get('irdic_created', '?')}")
    params = a.get("irdic_parameters")
    if params:
        try:
            lines.append("  parameters: " + json.dumps(json.loads(params), sort_keys=True))
        except ValueError:
            lines.append(f"  parameters: {params}")
    other = {k: v for k, v in a.items() if not k.startswith("irdic_")}
    for k, v in list(other.items())[:20]:
        lines.append(f"  {k}: {v}")
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="irdic", description="Couple stereo DIC and infrared thermography.")
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    # --debug is also accepted after the command; SUPPRESS keeps a top-level --debug from being reset
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show the traceback of an error")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="CPU threads for BLAS/OpenMP (default: all cores this process may use)")
    common.add_argument("--threads", type=int, default=argparse.SUPPRESS, metavar="N",
                        help="CPU threads for BLAS/OpenMP (default: all cores this process may use)")
    sub = p.add_subparsers(dest="command", required=True)

    def add_parser(name, **kw):
        return sub.add_parser(name, parents=[common], **kw)

    s = add_parser("info", help="summarise an irdic zarr store")
    s.add_argument("store")

    s = add_parser("demo", help="write the synthetic demo experiment")
    s.add_argument("outdir")
    s.add_argument("--scale", choices=["tiny", "demo", "paper"], help="default: the schema's demo.scale")
    s.add_argument("--ir-noise", type=float, help="K")
    s.add_argument("--dic-noise", type=float, help="mm")
    s.add_argument("--seed", type=int)

    for kind in ("ir", "dic"):
        s = add_parser(f"ingest-{kind}", help=f"{kind.upper()} exports -> {kind}.zarr")
        s.add_argument("source", help="folder, glob or file")
        s.add_argument("out", help="store to write")
        s.add_argument("--format")
        s.add_argument("--frame-rate", type=float, help="Hz")
        s.add_argument("--time-source", choices=["file", "frame_rate"])
        s.add_argument("--time-origin", choices=["first", "file"])
        s.add_argument("--time-offset", type=float, help="s")

    s = add_parser("calibrate", help="calibrate the IR camera from one target image")
    s.add_argument("--markers", required=True, help="marker centres export (ID, x, y, z in mm)")
    s.add_argument("--target", required=True, help="IR image of the reference object")
    s.add_argument("--out", required=True, help="calibration.zarr to write")
    s.add_argument("--figure", default=None, help="PNG of detections and residuals")
    s.add_argument("--distortion", choices=["none", "k1", "k1k2"])
    s.add_argument("--polarity", choices=["auto", "dark", "bright"])

    s = add_parser("couple", help="temperatures at the DIC points -> points.zarr")
    s.add_argument("--dic", required=True, help="dic.zarr")
    s.add_argument("--ir", required=True, help="ir.zarr")
    s.add_argument("--calibration", required=True, help="calibration.zarr")
    s.add_argument("--out", required=True, help="points.zarr to write")
    s.add_argument("--method", choices=["rbf", "bilinear", "cubic"])

    s = add_parser("fields", help="gradient, rate and strain fields -> fields.zarr")
    s.add_argument("--points", required=True, help="points.zarr")
    s.add_argument("--calibration", required=True, help="calibration.zarr")
    s.add_argument("--out", required=True, help="fields.zarr to write")
    s.add_argument("--temperature-smoothing", help="none (default), gcv or a number >= 1")
    s.add_argument("--dic", default=None, help="dic.zarr: its testing machine signals at the DIC times")
    s.add_argument("--machine", default=None, help="machine.zarr: the machine record at the DIC times")

    s = add_parser("run", help="run all stages of a configuration without Snakemake")
    s.add_argument("--config", default="config/config.yaml")
    return p


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
        from .errors import ConfigError

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
        from .errors import ConfigError

        raise ConfigError(f"--temperature-smoothing must be none, gcv or a number >= 1, got {text!r}") from None


def _dispatch(args) -> None:
    """Run the sub-command of the parsed ``args`` (threads are set once, by :func:`_run`)."""
    if args.command == "info":
        print(describe_store(args.store))
        return
    if args.command == "run":
        from .config import load_config
        from .pipeline import run

        paths = run(load_config(args.config), threads=args.threads)
        print(json.dumps(paths, default=str, indent=2))
        return
    if args.command == "demo":
        from .stages import demo

        demo.run({}, {"manifest": Path(args.outdir) / "manifest.yaml"}, threads=args.threads,
                 **_given(args, "scale", "ir_noise", "dic_noise", "seed"))
        return
    if args.command in ("ingest-ir", "ingest-dic"):
        from .stages import ingest_dic, ingest_ir

        stage = ingest_ir if args.command == "ingest-ir" else ingest_dic
        stage.run({"source": args.source}, {"store": args.out}, threads=args.threads,
                  **_given(args, "format", "frame_rate", "time_source", "time_origin", "time_offset"))
    elif args.command == "calibrate":
        from .stages import calibrate

        calibrate.run({"markers": args.markers, "target": args.target}, {"store": args.out, "figure": args.figure},
                      threads=args.threads, **_given(args, "distortion", "polarity"))
    elif args.command == "couple":
        from .stages import couple

        couple.run({"dic": args.dic, "ir": args.ir, "calibration": args.calibration}, {"store": args.out},
                   threads=args.threads, **_given(args, "method"))
    elif args.command == "fields":
        from .stages import fields

        params = {}
        if args.temperature_smoothing is not None:
            params["temperature_smoothing"] = _smoothing(args.temperature_smoothing)
        fields.run({"points": args.points, "calibration": args.calibration, "dic": args.dic,
                    "machine": args.machine}, {"store": args.out}, threads=args.threads, **params)
    print(describe_store(args.out))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
