"""A self-contained HTML page of every figure of a results folder, each with its own caption.

The captions are the ones the figures carry (PNG ``Description``, written by
:func:`irdic.plot.maps.save_figure`), so the page and the images say the
same. ``snakemake --report`` gives Snakemake's richer report of the same
figures (with the workflow's run statistics); this page needs no Snakemake.
"""

from __future__ import annotations

import base64
import html
import os
from pathlib import Path

from .errors import DataError

__all__ = ["figure_caption", "collect_figures", "write_report"]


def figure_caption(path: str | os.PathLike) -> str:
    """The caption stored in a PNG's ``Description`` text chunk ('' when it has none)."""
    from PIL import Image

    with Image.open(path) as im:
        return str(getattr(im, "text", {}).get("Description", ""))


def collect_figures(results: str | os.PathLike) -> list[tuple[str, Path]]:
    """``(section, PNG)`` of every figure under ``results``: the setups' calibrations, then each experiment's figures.

    Raises
    ------
    DataError
        ``results`` is not a folder or holds no figure.
    """
    root = Path(results)
    if not root.is_dir():
        raise DataError(f"{root}: results folder not found; run the pipeline first (snakemake --cores 2)")
    out = [(f"setup {p.parent.name}", p) for p in sorted(root.glob("setups/*/calibration.png"))]
    out += [(f"experiment {p.parent.parent.name}", p) for p in sorted(root.glob("*/figures/*.png"))
            if p.parent.parent.name != "setups"]
    if not out:
        raise DataError(f"{root}: no figures (setups/*/calibration.png, <experiment>/figures/*.png); "
                        "run the figures stage first")
    return out


def _clock(points: Path) -> str | None:
    """The IR clock line of an experiment's ``points.zarr`` (:func:`irdic.timing.summary.clock_summary`)."""
    if not points.exists():
        return None
    from .store import open_store
    from .timing.summary import clock_summary

    return clock_summary(open_store(points).attrs)


def write_report(results: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Write the HTML page of :func:`collect_figures` to ``out`` (images embedded: one file to share)."""
    figures = collect_figures(results)
    parts = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'><title>irdic results</title>",
             "<style>body{font-family:sans-serif;max-width:1200px;margin:auto}img{max-width:100%}"
             "figcaption{color:#333;margin-bottom:2em}</style></head><body>",
             f"<h1>irdic results: {html.escape(str(results))}</h1>"]
    section = None
    for sec, png in figures:
        if sec != section:
            parts.append(f"<h2>{html.escape(sec)}</h2>")
            section = sec
            clock = _clock(Path(results) / sec.split(" ", 1)[1] / "points.zarr") if sec.startswith("experiment ") \
                else None
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
