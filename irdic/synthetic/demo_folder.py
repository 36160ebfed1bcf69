"""The demo folder: the bundled synthetic experiment, raw exports in real formats plus the analytic truth.

What an earlier demo wrote is replaced file by file from the record it kept;
a folder holding anything else is refused before anything is touched.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path

import yaml

from ..errors import ConfigError
from ..store import jsonable
from ..parameters import settings

__all__ = ["make_demo"]

log = logging.getLogger(__name__)


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


def make_demo(outdir: str | os.PathLike, *, manifest: str | os.PathLike | None = None, **params) -> Path:
    """Generate the synthetic demo (raw exports + truth) under ``outdir``.

    What an earlier demo wrote into ``outdir`` is removed first, file by
    file, from the record it kept (``.irdic-demo-files.json``); a folder
    holding anything else (dot files included) is refused before anything
    is touched, as is a symbolic link. ``manifest`` (default
    ``outdir/manifest.yaml``) summarises what was written and is written
    last, so its presence means the demo is complete.

    ``params``: ``scale``, ``ir_noise`` (K), ``dic_noise`` (mm), ``seed``, ``ir_format`` as
    in the ``demo`` section of the configuration; absent ones take the
    schema's defaults.

    Raises
    ------
    ConfigError
        An invalid argument, or ``outdir`` holds files the demo did not
        write, is a file or is a symbolic link.
    """
    from .. import synthetic
    from ..validation import as_int, choice, positive
    from ..synthetic.experiments import SCALES

    p = settings("demo", params, drop=("enabled", "outdir"))
    scale, ir_noise, dic_noise, seed = p["scale"], p["ir_noise"], p["dic_noise"], p["seed"]
    # every argument is checked before the disk is touched
    choice(scale, "scale", SCALES)
    ir_format = choice(p["ir_format"], "ir_format", synthetic.demo.IR_FORMATS)
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
    written = synthetic.make_demo(out, scale=scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed,
                                  ir_format=ir_format)
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
                                            "seed": seed, "ir_format": ir_format, "n_files": len(files),
                                            "contents": jsonable(written)},
                                           sort_keys=False))
    log.info("demo written to %s (%d files)", out, len(files))
    return out


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
