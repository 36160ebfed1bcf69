"""Writer of FLIR FFF frames: ``.seq`` chains, single ``.fff`` frames and radiometric JPEGs.

The layout is the one :mod:`irdic.io.flir` documents (its constants are
imported from there). Temperatures become counts through the inverse of the
reader's Planck model with the same object parameters, rounded to the
nearest count: a round trip returns each temperature to within half a count
(about 0.01 K near room temperature with the default constants).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ...errors import ConfigError
from ...io.flir import ENTRY_SIZE, HEADER_SIZE, MAGIC, RAW_HEADER_SIZE, RAW_JPEGLS, RAW_LE, RAW_PNG, REC_CAMERA, \
    REC_RAW
from ...io.flir_planck import celsius_to_counts

__all__ = ["write_flir", "flir_parameters", "counts_of", "DEFAULT_PARAMETERS"]

#: object parameters and constants of a FLIR SC660 (kelvin; the reader's ``params`` keys)
DEFAULT_PARAMETERS = {
    "emissivity": 0.95, "distance": 1.0, "reflected_k": 293.15, "atmosphere_k": 293.15, "window_k": 293.15,
    "window_transmission": 1.0, "humidity": 0.5, "r1": 21106.77, "b": 1501.0, "f": 1.0,
    "alpha1": 0.006569, "alpha2": 0.01262, "beta1": -0.002276, "beta2": -0.00667, "x": 1.9,
    "r2": 0.012545258, "o": -7340.0,
}
_OFFSETS = {"emissivity": 0x20, "distance": 0x24, "reflected_k": 0x28, "atmosphere_k": 0x2c, "window_k": 0x30,
            "window_transmission": 0x34, "humidity": 0x3c, "r1": 0x58, "b": 0x5c, "f": 0x60, "alpha1": 0x70,
            "alpha2": 0x74, "beta1": 0x78, "beta2": 0x7c, "x": 0x80, "r2": 0x30c}
CAMERA_INFO_LENGTH = 2476
_ENCODINGS = {"raw": RAW_LE, "png": RAW_PNG, "jpegls": RAW_JPEGLS}


def flir_parameters(params: Mapping[str, float] | None = None) -> dict:
    """:data:`DEFAULT_PARAMETERS` updated by ``params``, as the float32 values a file holds (``o`` an integer)."""
    p = dict(DEFAULT_PARAMETERS, **(params or {}))
    unknown = sorted(set(p) - set(DEFAULT_PARAMETERS))
    if unknown:
        raise ConfigError(f"unknown FLIR parameter(s) {', '.join(unknown)}; expected {', '.join(DEFAULT_PARAMETERS)}")
    out = {k: float(np.float32(v)) for k, v in p.items()}
    out["o"] = float(int(round(p["o"])))
    return out


def _camera_record(p: dict, bo: str, seconds: float, model: str, median: int, rng: int) -> bytes:
    rec = bytearray(CAMERA_INFO_LENGTH)
    struct.pack_into(bo + "H", rec, 0, 2)
    for k, off in _OFFSETS.items():
        struct.pack_into(bo + "f", rec, off, p[k])
    struct.pack_into(bo + "i", rec, 0x308, int(p["o"]))
    struct.pack_into(bo + "HH", rec, 0x338, median, rng)
    whole = int(np.floor(seconds))
    ms = int(round((seconds - whole) * 1000))
    if ms == 1000:
        whole, ms = whole + 1, 0
    struct.pack_into(bo + "IIh", rec, 0x384, whole, ms, 0)
    name = model.encode("latin-1")[:31]
    rec[0xd4:0xd4 + len(name)] = name
    return bytes(rec)


def _raw_record(counts: np.ndarray, bo: str, encoding: str, png_swap: bool) -> bytes:
    h, w = counts.shape
    head = bytearray(RAW_HEADER_SIZE)
    struct.pack_into(bo + "HHH", head, 0, 2, w, h)
    struct.pack_into(bo + "H", head, 12, w - 1)
    struct.pack_into(bo + "H", head, 16, h - 1)
    if encoding == "raw":
        return bytes(head) + counts.astype(bo + "u2").tobytes()
    import imagecodecs

    if encoding == "png":
        # cameras store the samples little-endian inside a big-endian format: pre-swap so the PNG bytes are LE
        return bytes(head) + imagecodecs.png_encode(counts.byteswap() if png_swap else counts)
    return bytes(head) + imagecodecs.jpegls_encode(counts)


def _block(counts: np.ndarray, p: dict, seconds: float, *, header_order: str, record_order: str,
           encoding: str, png_swap: bool, model: str, pad: int, subtype: int | None, extra_records: int = 0) -> bytes:
    """One FFF block: header, directory (raw image first), camera info, raw image, then ``extra_records``
    palette records (type 0x22, listed after the others) and an unused entry when there are extras."""
    median = int(np.median(counts))
    rng = int(np.abs(counts.astype(np.int64) - median).max()) + 1
    cam = _camera_record(p, record_order, seconds, model, median, min(rng, 65535))
    raw = _raw_record(counts, record_order, encoding, png_swap)
    n = 2 + extra_records + (1 if extra_records else 0)
    cam_off = HEADER_SIZE + n * ENTRY_SIZE + pad
    raw_off = cam_off + len(cam)
    head = bytearray(HEADER_SIZE)
    head[:4] = MAGIC
    head[4:4 + 10] = b"ResearchIR"
    struct.pack_into(header_order + "III", head, 0x14, 100, HEADER_SIZE, n)
    sub = _ENCODINGS[encoding] if subtype is None else subtype
    entry = header_order + "HHIIIIIII"
    entries = struct.pack(entry, REC_RAW, sub, 100, 2, raw_off, len(raw), 0, 0, 0) \
        + struct.pack(entry, REC_CAMERA, 0, 105, 1, cam_off, len(cam), 0, 0, 0)
    extra = bytes(range(64)) * extra_records
    for k in range(extra_records):
        entries += struct.pack(entry, 0x22, 1, 100, 3 + k, raw_off + len(raw) + 64 * k, 64, 0, 0, 0)
    entries += bytes(ENTRY_SIZE) if extra_records else b""
    return bytes(head) + entries + bytes(pad) + cam + raw + extra


def _jpeg(block: bytes) -> bytes:
    """A radiometric JPEG: a small grey picture with ``block`` in APP1 ``FLIR`` segments after SOI."""
    import imagecodecs

    picture = imagecodecs.jpeg8_encode(np.full((8, 8), 128, np.uint8))
    size = 65000
    chunks = [block[k:k + size] for k in range(0, len(block), size)]
    app1 = b"".join(b"\xff\xe1" + struct.pack(">H", 2 + 8 + len(c)) + b"FLIR\x00\x01" + bytes([k, len(chunks) - 1])
                    + c for k, c in enumerate(chunks))
    return picture[:2] + app1 + picture[2:]


def write_flir(path: str | os.PathLike, temperatures=None, *, counts=None, times: Sequence[float] | None = None,
               params: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None,
               header_order: str = "<", record_order: str = "<", encoding: str = "raw", png_swap: bool = True,
               jpeg: bool = False, model: str = "irdic synthetic", subtype: int | None = None,
               extra_records: int = 0) -> Path:
    """Write frames as a FLIR ``.seq`` (FFF blocks end to end), one ``.fff`` frame or a radiometric JPEG.

    Parameters
    ----------
    path : path-like
    temperatures : array-like, shape (V, U) or (T, V, U), or an iterable of 2-D arrays
        °C, converted to the nearest count; or give ``counts``. An iterable
        (a generator) is written frame by frame.
    counts : array-like of the same shapes, optional
        Raw counts (0..65535) written as they are.
    times : sequence of float, optional
        Unix time of each frame (s, millisecond resolution); default 1.6e9 + k / 30.
    params : mapping or sequence of mappings, optional
        Object parameters and constants (keys of :data:`DEFAULT_PARAMETERS`, kelvin), per file or per frame.
    header_order, record_order : {"<", ">"}
        Byte order of the FFF headers and of the records.
    encoding : {"raw", "png", "jpegls"}
        Raw image encoding (directory subtype 2, 3 or 4); ``png_swap`` stores the PNG samples little-endian
        as the cameras do.
    jpeg : bool
        Write a radiometric JPEG (one frame only).
    subtype : int, optional
        Directory subtype to declare instead of the encoding's (for tests of unknown encodings).
    extra_records : int
        Palette records (type 0x22) after the raw image in each frame, so that the raw image is neither the
        last record nor the last used directory entry.

    Returns
    -------
    pathlib.Path
    """
    if (temperatures is None) == (counts is None):
        raise ConfigError("write_flir needs either temperatures or counts")
    if encoding not in _ENCODINGS or header_order not in "<>" or record_order not in "<>":
        raise ConfigError(f"write_flir: encoding {encoding!r} / byte orders {header_order!r}, {record_order!r}")
    frames = temperatures if counts is None else counts
    if not isinstance(frames, (list, tuple)) and not hasattr(frames, "__next__"):  # an array, not frames one by one
        frames = np.asarray(frames)
        frames = [frames] if frames.ndim == 2 else frames
    per_frame = params if isinstance(params, (list, tuple)) else None
    path = Path(path)
    blocks = []
    with open(path, "wb") as fh:
        for k, f in enumerate(frames):  # one frame in memory at a time: a generator of frames streams
            p = flir_parameters(per_frame[k] if per_frame is not None else params)
            c = counts_of(f, p, converted=True) if counts is None else np.asarray(f).astype(np.uint16)
            t = times[k] if times is not None else 1.6e9 + k / 30.0
            # the first frame of a ResearchIR file has its records further down than the others
            block = _block(c, p, t, header_order=header_order, record_order=record_order, encoding=encoding,
                           png_swap=png_swap, model=model, pad=128 if k == 0 else 0, subtype=subtype,
                           extra_records=extra_records)
            if jpeg:
                blocks.append(block)
            else:
                fh.write(block)
        if jpeg:
            if len(blocks) != 1:
                raise ConfigError(f"a radiometric JPEG holds one frame, got {len(blocks)}")
            fh.write(_jpeg(blocks[0]))
    return path


def counts_of(temperatures, params: Mapping[str, float] | None = None, *, converted: bool = False) -> np.ndarray:
    """The counts :func:`write_flir` writes for ``temperatures`` (°C) under ``params`` (uint16).

    ``converted``: ``params`` already went through :func:`flir_parameters`.
    """
    p = params if converted else flir_parameters(params)
    return np.clip(np.rint(celsius_to_counts(np.asarray(temperatures, dtype=np.float64), p)), 0, 65535
                   ).astype(np.uint16)
