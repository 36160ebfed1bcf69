"""A self-contained HTML page of the figures of one run, each with its own caption.

The captions are the ones the figures carry (PNG ``Description``, written by
:func:`irdic.plot.maps.save_figure`), so the page and the images say the
same. The page shows the figures it is given (the setups and experiments
of one configuration) in pipeline order: each setup's calibration, then per
experiment temperature, gradient, rate, strain, history and load. A header
says what was run: the configuration, irdic's version, the date, the
parameters that differ from the schema's defaults and what each ``auto``
setting chose (read from the stores the run wrote). ``snakemake --report``
gives Snakemake's richer report of the same figures; this page needs no
Snakemake.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import os
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from .errors import DataError

__all__ = ["figure_caption", "collect_figures", "order_figures", "auto_choices", "write_report", "REPORT_ORDER"]

#: order of an experiment's figures on the page (the pipeline's: the fields, then their history and the load)
REPORT_ORDER = ("temperature", "gradient", "rate", "strain", "history", "load", "heat")


def figure_caption(path: str | os.PathLike) -> str:
    """The caption stored in a PNG's ``Description`` text chunk ('' when it has none)."""
    from PIL import Image

    with Image.open(path) as im:
        return str(getattr(im, "text", {}).get("Description", ""))


def _section(png: Path) -> str:
    """``setup <name>`` for ``setups/<name>/calibration.png``, else ``experiment <name>`` (``<name>/figures/x.png``)."""
    if png.parent.parent.name == "setups":
        return f"setup {png.parent.name}"
    return f"experiment {png.parent.parent.name}"


def order_figures(figures: Iterable[str | os.PathLike]) -> list[tuple[str, Path]]:
    """``(section, PNG)`` in pipeline order: setups, then experiments (each in the order first given).

    An experiment's figures follow :data:`REPORT_ORDER`; others after them by name.
    """
    pngs = [Path(f) for f in figures]
    rank = {name: k for k, name in enumerate(REPORT_ORDER)}
    first: dict[str, int] = {}
    for k, p in enumerate(pngs):
        first.setdefault(_section(p), k)

    def key(p: Path):
        sec = _section(p)
        return (not sec.startswith("setup "), first[sec], rank.get(p.stem, len(rank)), p.stem)

    return [(_section(p), p) for p in sorted(pngs, key=key)]


def collect_figures(results: str | os.PathLike) -> list[tuple[str, Path]]:
    """``(section, PNG)`` of every figure under ``results``, in pipeline order (:func:`order_figures`).

    Raises
    ------
    DataError
        ``results`` is not a folder or holds no figure.
    """
    root = Path(results)
    if not root.is_dir():
        raise DataError(f"{root}: results folder not found; run the pipeline first (snakemake --cores 2)")
    found = sorted(root.glob("setups/*/calibration.png"))
    found += [p for p in sorted(root.glob("*/figures/*.png")) if p.parent.parent.name != "setups"]
    if not found:
        raise DataError(f"{root}: no figures (setups/*/calibration.png, <experiment>/figures/*.png); "
                        "run the figures stage first")
    return order_figures(found)


def _chosen(attrs: Mapping) -> dict:
    """The settings a stage used, with every ``auto`` resolved, from a store's attributes."""
    out = {}
    for name in ("settings", "irdic_settings_used"):
        try:
            got = json.loads(attrs.get(name, "{}"))
        except (TypeError, ValueError):
            continue
        if isinstance(got, dict):
            out.update(got)
    return out


def _clock(points: Path) -> str | None:
    """The IR clock line of an experiment's ``points.zarr`` (:func:`irdic.timing.summary.clock_summary`)."""
    if not points.exists():
        return None
    from .store import open_store
    from .timing.summary import clock_summary

    return clock_summary(open_store(points).attrs)


#: per option, the spacing attributes :func:`_spacing_summary` reads: (attribute, label, unit)
_SHOWN = {"temperature_smoothing": (("temperature_smoothing_spacing", "", "DIC stages"),
                                    ("temperature_smoothing_rate_spacing", "rate", ""),
                                    ("temperature_smoothing_value_spacing", "value", "")),
          "temperature_smoothing_space": (("temperature_smoothing_space_spacing", "", "point spacings"),),
          "surface_smoothing": (("surface_smoothing_spacing", "", "point spacings"),
                                ("surface_smoothing_shape_spacing", "shape", "")),
          "surface_smoothing_time": (("surface_smoothing_time_spacing", "", "DIC stages"),)}


def _spacing_summary(option: str, attrs: Mapping) -> str | None:
    """The centre spacing(s) a store's ``attrs`` record for the smoothing ``option``
    (:func:`irdic.fields.dataset.spacing_attrs`), as ``"centres every 3 DIC stages (rate 2, value 3)"``; None where
    none is recorded (a regression that is off, or a store written before they were recorded)."""
    got = [(label, unit, attrs[a]) for a, label, unit in _SHOWN.get(option, ()) if attrs.get(a) is not None]
    if not got or got[0][0]:
        return None
    _, unit, main = got[0]
    extra = ", ".join(f"{label} {v:.3g}" for label, _, v in got[1:])
    return f"centres every {main:.3g} {unit}" + (f" ({extra})" if extra else "")


def auto_choices(stores: Iterable[str | os.PathLike]) -> list[str]:
    """What each ``auto`` parameter chose, per store: ``"<store>: <key> auto -> <value>"``.

    A store's ``irdic_parameters`` hold the settings as given; the value used
    is read from its ``settings`` (calibration) or from the attribute of the
    same name (the fields stage records each smoothing it chose, with why).
    """
    from .store import open_store

    lines = []
    for path in stores:
        p = Path(path)
        if not p.exists():
            continue
        attrs = open_store(p).attrs
        try:
            given = json.loads(attrs.get("irdic_parameters", "{}"))
        except (TypeError, ValueError):
            continue
        used = _chosen(attrs)
        where = f"{p.parent.name}/{p.name}"
        for key in sorted(k for k, v in given.items() if v == "auto"):
            names = [f"{key}_chosen", key, f"surface_{key}"]  # the fields stage's names for what it used
            found = [attrs[n] for n in names if n in attrs]
            if key in used:
                value = used[key]
            elif found:
                value = found[0]
            else:
                continue
            if value == "auto":
                continue
            why = attrs.get(f"{key}_reason")
            shown = "null" if value in (None, "None") else value
            spacing = _spacing_summary(key, attrs)
            lines.append(f"{where}: {key} auto \u2192 {shown}" + (f", {spacing}" if spacing else "")
                         + (f" ({why})" if why else ""))
    return lines


def _header(title: str, settings: Mapping | None, choices: Sequence[str]) -> list[str]:
    from . import __version__

    date = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    rows = [("configuration", html.escape(title)), ("irdic", html.escape(__version__)), ("date", date)]
    if settings is not None:
        rows.append(("non-default parameters", "<br>".join(f"<code>{html.escape(k)}: {html.escape(json.dumps(v))}"
                                                             "</code>" for k, v in settings.items()) or "none"))
    rows.append(("auto chose", "<br>".join(html.escape(c) for c in choices) or "nothing (no auto setting)"))
    return ["<table class='run'>"] + [f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows] + ["</table>"]


def write_report(figures: Sequence[tuple[str, Path]], out: str | os.PathLike, *, title: str,
                 settings: Mapping | None = None, stores: Iterable[str | os.PathLike] = ()) -> Path:
    """Write the HTML page of ``figures`` (:func:`order_figures`) to ``out`` (images embedded: one file to share).

    Parameters
    ----------
    figures : sequence of (str, Path)
        Section and PNG of each figure, in page order.
    out : path-like
        The page.
    title : str
        What the page is of (the configuration file, or the results folder).
    settings : mapping, optional
        The non-default parameters (:func:`irdic.config.non_defaults`); None: not known.
    stores : iterable of path-like
        Stores of the run, whose ``auto`` choices the header lists (:func:`auto_choices`).
    """
    anchors = {sec: f"s{k}" for k, sec in enumerate(dict.fromkeys(sec for sec, _ in figures))}
    parts = ["<!DOCTYPE html>", f"<html><head><meta charset='utf-8'><title>irdic: {html.escape(title)}</title>",
             "<style>body{font-family:sans-serif;max-width:1200px;margin:auto}img{max-width:100%}"
             "figcaption{color:#333;margin-bottom:2em}table.run th{text-align:left;padding-right:1em;"
             "vertical-align:top}</style></head><body>",
             f"<h1>irdic results of {html.escape(title)}</h1>", *_header(title, settings, auto_choices(stores)),
             "<h2>Contents</h2><ol class='toc'>"]
    parts += [f"<li><a href='#{a}'>{html.escape(sec)}</a></li>" for sec, a in anchors.items()]
    parts.append("</ol>")
    section = None
    for sec, png in figures:
        if sec != section:
            parts.append(f"<h2 id='{anchors[sec]}'>{html.escape(sec)}</h2>")
            section = sec
            # an experiment's figures lie in results/<experiment>/figures/, beside its points.zarr
            clock = _clock(png.parent.parent / "points.zarr") if sec.startswith("experiment ") else None
            if clock:
                parts.append(f"<p>{html.escape(clock)}</p>")
        data = base64.b64encode(png.read_bytes()).decode("ascii")
        caption = figure_caption(png) or png.stem
        parts.append(f"<figure><img alt='{html.escape(png.stem)}' src='data:image/png;base64,{data}'>"
                     f"<figcaption><b>{html.escape(png.stem)}</b>: {html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>")
    p = Path(out)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.tmp-{os.getpid()}")
    try:  # written beside and renamed: a reader never sees half a page
        tmp.write_text("\n".join(parts), encoding="utf-8")
        os.replace(tmp, p)
    finally:
        if tmp.exists():
            tmp.unlink()
    return p
