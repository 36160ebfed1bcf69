"""Writer of uncompressed InfraTec ``.irb`` images and sequences, read by :mod:`irdic.io.irb`.

The byte layout is documented in :mod:`irdic.io.irb`; its offsets and
constants are imported from there so that reader and writer cannot disagree.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import struct
from pathlib import Path
from typing import Iterator

import numpy as np

from ...errors import ConfigError
from ...io.irb import (BLOCK_IMAGE, ENTRY_SIZE, HEADER_SIZE, KELVIN, MAGIC, MAX_SIDE, META_OFFSET, OLE_EPOCH,
                       PALETTE_OFFSET, PIXEL_OFFSET)

__all__ = ["write_irb"]


def _encode(frame_c: np.ndarray, min_range: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Palette (float32 K, linear over the frame's range) and uint16 codes of one frame."""
    t = frame_c.astype(np.float64) + KELVIN
    lo, hi = float(t.min()), float(t.max())
    span = max(hi - lo, min_range)
    # codes up to 254*256+255 so that pal[hi + 1] always exists
    step = span * 256.0 / (255 * 256 - 1)
    pal = (lo + step * np.arange(256)).astype(np.float32)
    p64 = pal.astype(np.float64)
    idx = np.clip(np.searchsorted(p64, t, side="right") - 1, 0, 254)
    frac = (t - p64[idx]) / (p64[idx + 1] - p64[idx])
    code = np.clip(np.rint(frac * 256.0).astype(np.int64), 0, 256)
    # a fraction that rounds up to 256/256 is code 0 of the next entry (the last entry keeps 255)
    carry = code == 256
    up = carry & (idx < 254)
    idx = np.where(up, idx + 1, idx)
    code = np.where(up, 0, np.where(carry, 255, code))
    return pal, (idx * 256 + code).astype("<u2")


def _checked_frame(frame, k: int, shape: tuple | None) -> np.ndarray:
    """One frame for the writer as float64 °C, or ConfigError naming what is wrong."""
    f = np.asarray(frame)
    if f.dtype.kind not in "fiu":
        raise ConfigError(f"frame {k} must hold real numbers, got dtype {f.dtype}")
    if f.ndim != 2 or 0 in f.shape:
        raise ConfigError(f"frame {k} must be a non-empty 2-D array (rows, columns), got shape {f.shape}")
    if shape is not None and f.shape != shape:
        raise ConfigError(f"frame {k} has shape {f.shape}, frame 0 has {shape}; one size per file")
    if f.shape[0] > MAX_SIDE or f.shape[1] > MAX_SIDE:
        raise ConfigError(f"frames of {f.shape[1]} x {f.shape[0]} px are larger than the {MAX_SIDE} px "
                          "an IRB image can hold")
    f = f.astype(np.float64)
    if not np.isfinite(f).all():
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(f))[0])
        raise ConfigError(f"frame {k}{list(idx)} = {f[idx]}; an IRB file cannot hold non-finite temperatures")
    lo, hi = float(f.min()), float(f.max())
    if lo <= -KELVIN or hi + KELVIN >= 5e4:
        raise ConfigError(f"frame {k} holds {lo} .. {hi} °C; expected temperatures above absolute zero "
                          "and below 50000 K")
    return f


def write_irb(
    path: str | os.PathLike,
    frames,
    times=None,
    *,
    rec_datetime: _dt.datetime = _dt.datetime(2000, 1, 1),
    emissivity: float = 1.0,
    distance: float = 1.0,
    env_temp: float = 25.0,
    path_temp: float | None = None,
    wavelength: float = 9.5,
    calib_range: tuple[float, float] = (-40.0, 120.0),
    device: str = "irdic",
    frame_indices=None,
) -> Path:
    """Write an uncompressed ``.irb`` image or sequence (one file, several image blocks).

    Each frame gets its own palette, linear over the frame's temperature
    range (at least 1 K), so the quantisation is ``range / 65279`` K
    (about (range/256)/256) and :func:`read_irb` returns the frame to within
    half of that plus float32 rounding.

    Parameters
    ----------
    path : path-like
        Output file. Removed again if writing fails half-way.
    frames : array_like of shape (H, W) or (N, H, W), or iterable of (H, W) arrays
        Temperatures in °C, top row first; finite. An iterable (for example
        a generator, so that a long sequence never sits in memory) needs
        ``times``, which gives the number of frames.
    times : array_like, shape (N,), optional
        Frame times (s) after ``rec_datetime``; default 0, 1, 2, ... s.
        Stored as whole seconds in the OLE date plus the millisecond field,
        so they come back rounded to 1 ms.
    rec_datetime : datetime.datetime
        Recording time of ``times = 0``.
    emissivity, distance, env_temp, path_temp, wavelength
        Image header values (distance in m, temperatures in °C,
        ``path_temp`` defaults to ``env_temp``, wavelength in µm).
    calib_range : (float, float)
        Calibration range of the camera (°C), metadata only.
    device : str
        Device name (at most 11 characters are kept).
    frame_indices : array_like of int, optional
        Frame numbers for the directory; default 1, 2, ..., N.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        An argument is invalid (named), or the file cannot be written.
    """
    n, source = _frame_source(frames, times)
    t = _checked_times(times, n)
    fidx = _checked_metadata(n, rec_datetime, frame_indices, emissivity, distance, env_temp, wavelength)
    values = (emissivity, distance, env_temp, env_temp if path_temp is None else path_temp, wavelength,
              calib_range, device)
    first = _checked_frame(next(source, np.empty((0, 0))), 0, None)
    epoch = (rec_datetime - OLE_EPOCH).total_seconds()
    p = Path(path)
    try:
        with open(p, "wb") as fh:
            fh.write(_file_head(fidx, PIXEL_OFFSET + 2 * first.size))
            for k, frame in enumerate(_checked_frames(first, source, n)):
                fh.write(_image_block(frame, epoch + t[k], *values))
    except OSError as exc:
        p.unlink(missing_ok=True)
        raise ConfigError(f"cannot write {p}: {exc}") from exc
    except BaseException:
        p.unlink(missing_ok=True)
        raise
    return p


def _checked_frames(first: np.ndarray, source: Iterator, n: int) -> Iterator[np.ndarray]:
    """``first``, then the next ``n - 1`` frames of ``source``, each checked against the first's size."""
    yield first
    for k in range(1, n):
        nxt = next(source, None)
        if nxt is None:
            raise ConfigError(f"frames ended after {k} frames; times has {n}")
        yield _checked_frame(nxt, k, first.shape)


def _frame_source(frames, times) -> tuple[int, Iterator]:
    """Number of frames and an iterator over them (arrays, lists of frames or a generator with ``times``)."""
    arr = None
    if isinstance(frames, (np.ndarray, list, tuple)):
        try:
            arr = np.asarray(frames)
        except ValueError:  # a list of frames of different sizes: checked frame by frame below
            n, source = len(frames), iter(frames)
    if arr is not None:
        if arr.ndim == 2:
            arr = arr[None]
        if arr.ndim != 3:
            raise ConfigError(f"frames must have shape (H, W) or (N, H, W), got {arr.shape}")
        n = arr.shape[0]
        source = iter(arr)
    elif not isinstance(frames, (list, tuple)):
        if times is None:
            raise ConfigError("times is required when frames is an iterator (it gives the number of frames)")
        try:
            source = iter(frames)
        except TypeError:
            raise ConfigError(f"frames must be an array or an iterable of 2-D arrays, "
                              f"got {type(frames).__name__}") from None
        n = int(np.size(times))
    if n == 0:
        raise ConfigError("frames is empty; an IRB file needs at least one frame")
    return n, source


def _checked_times(times, n: int) -> np.ndarray:
    """Frame times (s), shape (n,); 0, 1, 2, ... s when ``times`` is None."""
    if times is None:
        return np.arange(n, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.shape != (n,):
        raise ConfigError(f"times must have one value per frame ({n}), got shape {np.shape(times)}")
    if not np.isfinite(t).all():
        raise ConfigError("times must be finite (s)")
    return t


def _checked_metadata(n: int, rec_datetime, frame_indices, emissivity, distance, env_temp,
                      wavelength) -> np.ndarray:
    """Check the recording time and image header values; return the directory's frame numbers, shape (n,)."""
    if not isinstance(rec_datetime, _dt.datetime):
        raise ConfigError(f"rec_datetime must be a datetime.datetime, got {type(rec_datetime).__name__}")
    if frame_indices is None:
        fidx = np.arange(1, n + 1)
    else:
        fidx = np.asarray(frame_indices).reshape(-1)
        if fidx.shape != (n,) or fidx.dtype.kind not in "iu":
            raise ConfigError(f"frame_indices must be {n} integers, got {np.shape(frame_indices)}")
    for name, value in (("emissivity", emissivity), ("distance", distance), ("env_temp", env_temp),
                        ("wavelength", wavelength)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
            raise ConfigError(f"{name}={value!r}; expected a finite number")
    if not 0 < emissivity <= 1:
        raise ConfigError(f"emissivity={emissivity}; expected 0 < emissivity <= 1")
    return fidx


def _file_head(fidx: np.ndarray, block_size: int) -> bytes:
    """File header and block directory of ``len(fidx)`` image blocks of ``block_size`` bytes each."""
    n = len(fidx)
    first = HEADER_SIZE + ENTRY_SIZE * n
    header = bytearray(HEADER_SIZE)
    header[:5] = MAGIC
    header[5:13] = (b"IRBACS\x00\x00" if n == 1 else b"IRBIS 3\x00")
    struct.pack_into("<iii", header, 21, 100, HEADER_SIZE, n)
    directory = bytearray()
    for k in range(n):
        directory += struct.pack("<8i", BLOCK_IMAGE, 101, int(fidx[k]), first + k * block_size,
                                 block_size, 0, 1, 0)
    return bytes(header + directory)


def _image_block(frame: np.ndarray, seconds: float, emissivity, distance, env_temp, path_temp,
                 wavelength, calib_range, device: str) -> bytes:
    """One uncompressed image block (header, palette, metadata, pixels) of a °C frame."""
    h, w = frame.shape
    pal, codes = _encode(frame)
    head = bytearray(PIXEL_OFFSET)
    struct.pack_into("<hhhhihhhh", head, 0, 2, 0, w, h, 0, 0, w - 1, 0, h - 1)
    struct.pack_into("<fff", head, 24, emissivity, distance, env_temp + KELVIN)
    struct.pack_into("<f", head, 40, path_temp + KELVIN)
    struct.pack_into("<f", head, 48, wavelength)
    head[PALETTE_OFFSET:META_OFFSET] = pal.tobytes()
    m = META_OFFSET
    struct.pack_into("<ff", head, m + 92, calib_range[0] + KELVIN, calib_range[1] + KELVIN)
    head[m + 142:m + 142 + 11] = device.encode("latin-1", "replace")[:11].ljust(11, b"\x00")
    lo, hi = float(frame.min()), float(frame.max())
    struct.pack_into("<ff", head, m + 532, (lo + hi) / 2 + KELVIN, max(hi - lo, 1.0))
    whole, ms = divmod(round(seconds * 1000.0), 1000)  # whole seconds in the date, as cameras do
    struct.pack_into("<di", head, m + 540, whole / 86400.0, int(ms))
    return bytes(head) + codes.tobytes()
