"""InfraTec ``.irb`` binary files: single images and sequences.

Layout (little-endian; see ``formats/README.md``):

- 64-byte file header: magic ``\\xffIRB\\0``, 8-byte type (``IRBACS``,
  ``IRBIS 3``, ``VARIOCAM``), 8-byte subtype, int32 flag, int32
  ``blockOffset`` (start of the block directory), int32 ``blockCount``.
- Block directory: ``blockCount`` entries of 32 bytes, eight int32 each:
  type (0 empty, 1 image, 2 preview, 3 text, 4 header, 7 audio), unknown,
  frame index, offset, size, three unknown. A *header* entry points to two
  more directory entries (how IRBIS sequences chain their frames).
- Image block: 60-byte image header (int16 bytes per pixel, int16
  compression, int16 width, int16 height; float32 emissivity at +24,
  distance (m) at +28, ambient temperature (K) at +32, path temperature (K)
  at +40, centre wavelength (µm) at +48), a 256-entry float32 palette (K) at
  +60, 644 bytes of metadata at +1084 (calibration range (K) at +92/+96,
  device name at +142, optics at +202, shot range centre/width (K) at
  +532/+536, OLE automation date (float64 days since 1899-12-30) at +540,
  milliseconds (int32) at +548), pixels at +1728.
- Uncompressed pixels are uint16 codes: high byte ``hi`` indexes the
  palette, low byte ``lo`` interpolates,
  ``T = pal[hi] + (pal[hi+1] - pal[hi]) * lo / 256``. Rows run top to
  bottom: the two sample images with the camera's screenshots beside them
  show the same scene the right way up without any flip (a public reader
  flips vertically, wrongly).
- VarioCAM HD sequences are complete IRB files written end to end, with a
  ``[Merge]`` text block between them; block offsets are taken relative to
  the start of each embedded file.

Compressed images (compression flag != 0) are refused with a clear message:
no compressed sample was available to verify a decoder against, and a
guessed decoder would return plausible-looking garbage.

Frames are streamed (:func:`iter_irb_frames`): memory does not grow with the
length of a sequence. Each frame is decoded through a 65536-entry lookup table
built from its palette (one table lookup per pixel).
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import os
import struct
import warnings
from typing import Iterator

import numpy as np
import xarray as xr

from ..errors import DataError, FormatError, IrdicWarning
from ._common import check_file
from .stack import check_temperatures, temperature_dataarray

__all__ = ["read_irb", "iter_irb_frames", "iter_irb_headers", "iter_irb_dataarrays", "iter_irb_records",
           "count_irb_frames", "unix_time"]

log = logging.getLogger(__name__)

MAGIC = b"\xffIRB\x00"
HEADER_SIZE = 64
ENTRY_SIZE = 32
IMAGE_HEADER_SIZE = 60
PALETTE_OFFSET = 60
META_OFFSET = 1084
PIXEL_OFFSET = 1728  # 60 + 1024 + 644
BLOCK_IMAGE, BLOCK_HEADER = 1, 4
KELVIN = 273.15
OLE_EPOCH = _dt.datetime(1899, 12, 30)
_UNIX_EPOCH_OLE = (_dt.datetime(1970, 1, 1) - OLE_EPOCH).total_seconds()
MAX_SIDE = 16384
_MERGE_SEARCH = 1 << 16  # bytes searched for the next embedded file after one ends


# ----------------------------------------------------------------------------
# directory
# ----------------------------------------------------------------------------
def _read_at(fh, offset: int, n: int, path, what: str) -> bytes:
    fh.seek(offset)
    data = fh.read(n)
    if len(data) != n:
        raise FormatError(f"{what} at byte {offset}: the file ends after {len(data)} of {n} bytes (truncated?)",
                          path)
    return data


def _file_header(fh, base: int, size: int, path) -> tuple[str, int, int]:
    head = _read_at(fh, base, HEADER_SIZE, path, "IRB file header")
    if head[:5] != MAGIC:
        raise FormatError(f"no IRB signature at byte {base} (found {head[:5]!r}, expected {MAGIC!r})", path)
    ftype = head[5:13].split(b"\x00", 1)[0].decode("latin-1").strip()
    _flag, block_offset, block_count = struct.unpack_from("<iii", head, 21)
    if block_offset < HEADER_SIZE or block_count < 0 or \
            base + block_offset + ENTRY_SIZE * block_count > size:
        raise FormatError(
            f"IRB header at byte {base}: block directory at +{block_offset} with {block_count} entries "
            f"does not fit in the {size}-byte file (damaged header or truncated file)", path)
    return ftype, block_offset, block_count


def _check_disjoint(images: list[dict], path) -> None:
    """Refuse image blocks that share bytes.

    Each image block of a real file holds its own pixels. A directory that
    lists one block many times (or blocks that overlap) would make a small
    file decode to any number of frames; with disjoint blocks, and the
    embedded files of a VarioCAM HD file following one another, the decoded
    float32 frames take at most twice the file's size (2-byte codes ->
    4-byte floats).
    """
    if len(images) < 2:
        return
    order = sorted(range(len(images)), key=lambda k: images[k]["offset"])
    for a, b in zip(order, order[1:]):
        first, second = images[a], images[b]
        if second["offset"] < first["offset"] + max(first["size"], 1):
            same = second["offset"] == first["offset"]
            raise FormatError(
                f"the IRB block directory lists image blocks {a} and {b} "
                + (f"at the same byte {first['offset']}" if same else
                   f"at bytes {first['offset']} (+{first['size']} bytes) and {second['offset']}, which overlap")
                + "; every image block of an IRB file holds its own pixels (damaged or forged directory)",
                path)


def _walk(fh, path, size: int) -> Iterator[dict]:
    """Image blocks of the file in order: ``{frame_index, offset, size, file_type, subfile}``.

    The directory of each embedded file is read completely before its first
    block is yielded, so that blocks listed twice or overlapping are refused
    before any pixel is decoded.
    """
    base = 0
    subfile = 0
    while True:
        ftype, block_offset, block_count = _file_header(fh, base, size, path)
        raw = _read_at(fh, base + block_offset, ENTRY_SIZE * block_count, path, "IRB block directory")
        pending = [np.frombuffer(raw, "<i4").reshape(block_count, 8)]
        seen_headers: set[int] = set()
        images: list[dict] = []
        sub_end = base + block_offset + ENTRY_SIZE * block_count
        while pending:
            entries = pending.pop(0)
            for btype, _w2, frame_index, offset, bsize, *_ in entries.tolist():
                if btype == 0:
                    continue
                if offset < 0 or bsize < 0 or base + offset + bsize > size:
                    raise FormatError(
                        f"IRB block of type {btype} at +{offset} with {bsize} bytes lies outside the "
                        f"{size}-byte file (truncated or damaged directory)", path)
                sub_end = max(sub_end, base + offset + bsize)
                if btype == BLOCK_IMAGE:
                    images.append({"frame_index": frame_index, "offset": base + offset, "size": bsize,
                                   "file_type": ftype, "subfile": subfile})
                elif btype == BLOCK_HEADER:
                    # a header entry points to the next two directory entries of a sequence
                    where = base + offset
                    if where in seen_headers or where + 2 * ENTRY_SIZE > size:
                        continue
                    seen_headers.add(where)
                    more = _read_at(fh, where, 2 * ENTRY_SIZE, path, "IRB sequence directory")
                    pending.append(np.frombuffer(more, "<i4").reshape(2, 8))
        _check_disjoint(images, path)
        yield from images
        # VarioCAM HD: the next complete IRB file follows after a [Merge] text block
        fh.seek(sub_end)
        window = fh.read(4096)  # the [Merge] block is about 2 kB
        hit = window.find(MAGIC)
        if hit < 0 and len(window) == 4096:
            window += fh.read(_MERGE_SEARCH - 4096)
            hit = window.find(MAGIC)
        if hit < 0:
            rest = size - sub_end
            if rest > 0:
                log.info("%s: %d bytes after the last IRB block ignored", path, rest)
            return
        base = sub_end + hit
        subfile += 1


def count_irb_frames(path: str | os.PathLike) -> int:
    """Number of image blocks in an ``.irb`` file, from its directories only.

    Parameters
    ----------
    path : path-like
        ``.irb`` image or sequence (also VarioCAM HD files of several
        embedded IRB files).

    Returns
    -------
    int
        Number of frames :func:`iter_irb_frames` will yield.

    Raises
    ------
    FormatError
        Not an IRB file, or a damaged/truncated directory.
    """
    p = check_file(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        return sum(1 for _ in _walk(fh, p, size))


# ----------------------------------------------------------------------------
# image blocks
# ----------------------------------------------------------------------------
def _cstring(raw: bytes) -> str:
    return raw.split(b"\x00", 1)[0].decode("latin-1", errors="replace").strip()


def _finite(x: float) -> float | None:
    """A float32 header value as the decimal it was meant to be (7 significant digits)."""
    return float(f"{x:.7g}") if math.isfinite(x) else None


def _ole_seconds(ole: float, ms: int) -> float | None:
    """Seconds since 1899-12-30 from the OLE date and the millisecond field.

    The sample files store whole seconds in the OLE date and 0 ms; when the
    date holds whole seconds and 0 < ms < 1000, the milliseconds are added.
    A date that already has a sub-second part is taken as it is.
    """
    if not math.isfinite(ole) or not 1.0 < ole < 2958465.0:  # 1900 .. 9999
        return None
    seconds = ole * 86400.0
    whole = round(seconds)
    if abs(seconds - whole) < 5e-4:
        seconds = float(whole)
        if 0 < ms < 1000:
            seconds += ms / 1000.0
    return seconds


def _iso(seconds: float | None) -> str | None:
    if seconds is None:
        return None
    return (OLE_EPOCH + _dt.timedelta(seconds=seconds)).isoformat(timespec="milliseconds")


def _parse_image_header(head: bytes, block: dict, path) -> dict:
    bpp, compressed, width, height = struct.unpack_from("<hhhh", head, 0)
    where = f"image block at byte {block['offset']}"
    if compressed != 0:
        raise FormatError(
            f"{where} uses compression {compressed} which irdic cannot decode; export the sequence "
            "as IRBIS text or as uncompressed .irb", path)
    if bpp != 2:
        raise FormatError(f"{where} has {bpp} bytes per pixel; irdic reads 2-byte palette codes only", path)
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise FormatError(f"{where}: image size {width} x {height} px is not plausible", path)
    need = PIXEL_OFFSET + 2 * width * height
    if block["size"] < need:
        raise FormatError(
            f"{where}: {width} x {height} pixels need {need} bytes, the block holds {block['size']} "
            "(truncated or damaged)", path)
    emissivity, distance, env_k = struct.unpack_from("<fff", head, 24)
    (path_k,) = struct.unpack_from("<f", head, 40)
    (wavelength,) = struct.unpack_from("<f", head, 48)
    meta = head[META_OFFSET:PIXEL_OFFSET]
    cal_lo, cal_hi = struct.unpack_from("<ff", meta, 92)
    shot_mid, shot_width = struct.unpack_from("<ff", meta, 532)
    (ole,) = struct.unpack_from("<d", meta, 540)
    (ms,) = struct.unpack_from("<i", meta, 548)
    seconds = _ole_seconds(ole, ms)

    def celsius(k):  # metadata temperatures: float32 kelvins, kept to 0.01 K
        return None if not math.isfinite(k) or k <= 0 else round(float(k) - KELVIN, 2)

    info = {
        "frame_index": block["frame_index"],
        "width": width,
        "height": height,
        "emissivity": _finite(emissivity),
        "distance": _finite(distance),
        "env_temp": celsius(env_k),
        "path_temp": celsius(path_k),
        "wavelength": _finite(wavelength),
        "calib_range": [celsius(cal_lo), celsius(cal_hi)],
        "shot_range": None,
        "device": _cstring(meta[142:154]),
        "optics": _cstring(meta[202:234]),
        "lens": _cstring(meta[234:266]),
        "serial": _cstring(meta[450:466]),
        "seconds": seconds,
        "rec_datetime": _iso(seconds),
        "file_type": block["file_type"],
        "subfile": block["subfile"],
        "offset": block["offset"],
    }
    if math.isfinite(shot_mid) and math.isfinite(shot_width) and shot_mid > 0 and shot_width > 0:
        info["shot_range"] = [round(shot_mid - shot_width / 2 - KELVIN, 2),
                              round(shot_mid + shot_width / 2 - KELVIN, 2)]
    return info


def _palette_table(palette: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """°C for all 65536 pixel codes, and which palette intervals are a temperature scale.

    Returns
    -------
    table : ndarray of float32, shape (65536,)
    good : ndarray of bool, shape (256,)
        Interval ``hi`` runs from a positive, finite kelvin value up to a
        larger one. Real files fill the low entries with other numbers; pixel
        codes must stay in the good part.
    pal : ndarray of float64, shape (257,)
        Palette with the last interval extended (K).
    """
    pal = np.empty(257)
    # damaged palettes hold NaN/inf (even signalling NaN): flagged below, not warned about
    with np.errstate(invalid="ignore", over="ignore"):
        pal[:256] = palette
        pal[256] = 2 * pal[255] - pal[254]  # codes 0xFFxx: extend the last interval
        good = np.isfinite(pal[:256]) & np.isfinite(pal[1:]) & (pal[:256] > 0) & (pal[1:] < 1e5) \
            & (pal[1:] > pal[:256])
        frac = np.arange(256) / 256.0
        table = (pal[:256, None] - KELVIN) + (pal[1:] - pal[:256])[:, None] * frac[None, :]
    return table.astype(np.float32).ravel(), good, pal


def _check_codes(good: np.ndarray, pal: np.ndarray, codes: np.ndarray, where: str, path) -> None:
    lo, hi = int(codes.min()) >> 8, int(codes.max()) >> 8
    if not good[lo:hi + 1].all():
        bad = lo + int(np.flatnonzero(~good[lo:hi + 1])[0])
        raise FormatError(
            f"{where}: pixel codes use palette entries {lo}..{hi}, but entry {bad} "
            f"({pal[bad]:.6g} K -> {pal[bad + 1]:.6g} K) is not part of an increasing temperature scale "
            "(damaged file or an encoding irdic does not know)", path)


def iter_irb_headers(path: str | os.PathLike) -> Iterator[dict]:
    """Stream the image headers of an ``.irb`` file without decoding pixels.

    Reads 1728 bytes per frame, so that a series can be counted, timed and
    checked (duplicate time stamps, frame sizes) before any frame is decoded
    or written.

    Parameters
    ----------
    path : path-like
        ``.irb`` image or sequence.

    Yields
    ------
    dict
        The ``meta`` of :func:`iter_irb_frames`, one per frame, in the same
        order.

    Raises
    ------
    FormatError
        As :func:`iter_irb_frames`, except for problems in the pixel codes.
    """
    p = check_file(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        for block in _walk(fh, p, size):
            pos = fh.tell()
            head = _read_at(fh, block["offset"], PIXEL_OFFSET, p, f"image block at byte {block['offset']}")
            fh.seek(pos)
            yield _parse_image_header(head, block, p)


def iter_irb_frames(path: str | os.PathLike) -> Iterator[tuple[dict, np.ndarray]]:
    """Stream the frames of an ``.irb`` file one at a time.

    Parameters
    ----------
    path : path-like
        ``.irb`` image or sequence.

    Yields
    ------
    meta : dict
        ``frame_index`` (from the directory), ``width``, ``height``,
        ``seconds`` (recording time, s since 1899-12-30, or None),
        ``rec_datetime`` (ISO 8601 or None), ``emissivity``, ``distance``
        (m), ``env_temp``/``path_temp`` (°C), ``wavelength`` (µm),
        ``calib_range``/``shot_range`` ([low, high] °C), ``device``,
        ``optics``, ``lens``, ``serial``, ``file_type``, ``subfile`` (index
        of the embedded IRB file), ``offset`` (byte offset of the block).
    frame : ndarray of float32, shape (height, width)
        Temperatures in °C, top row first.

    Raises
    ------
    FormatError
        Not an IRB file, damaged or truncated directory or image block,
        compressed images, palette codes outside the palette's temperature
        scale.
    """
    p = check_file(path)
    size = p.stat().st_size
    table_key = table = good = pal = None
    with open(p, "rb") as fh:
        for block in _walk(fh, p, size):
            pos = fh.tell()
            where = f"image block at byte {block['offset']}"
            head = _read_at(fh, block["offset"], PIXEL_OFFSET, p, where)
            info = _parse_image_header(head, block, p)
            w, h = info["width"], info["height"]
            raw = _read_at(fh, block["offset"] + PIXEL_OFFSET, 2 * w * h, p, where + " pixels")
            codes = np.frombuffer(raw, "<u2").reshape(h, w)
            palette_bytes = head[PALETTE_OFFSET:META_OFFSET]
            if palette_bytes != table_key:  # cameras keep one palette: build the table once
                table, good, pal = _palette_table(np.frombuffer(palette_bytes, "<f4"))
                table_key = palette_bytes
            _check_codes(good, pal, codes, where, p)
            frame = table.take(codes)
            fh.seek(pos)
            yield info, frame


def _attrs(info: dict, path) -> dict:
    attrs = {"format": "irb", "source": str(path)}
    for key in ("rec_datetime", "emissivity", "distance", "env_temp", "path_temp", "wavelength",
                "calib_range", "shot_range", "device", "optics", "lens", "serial", "file_type"):
        value = info.get(key)
        if value is not None and value != "" and not (isinstance(value, list) and None in value):
            attrs[key] = value
    return attrs


def iter_irb_records(path: str | os.PathLike) -> Iterator[tuple[np.ndarray, float | None, dict]]:
    """Stream the frames of an ``.irb`` file as ``(values, time, attrs)``, without building DataArrays.

    The content of :func:`iter_irb_dataarrays` (series ingest takes it as
    it is), each frame checked as it is decoded.

    Yields
    ------
    values : ndarray of float32, shape (height, width)
        °C, top row first, full-sensor pixels from (0, 0).
    time : float or None
        Recording time in s since 1970-01-01 00:00 of the camera's clock,
        None when the frame has no valid date.
    attrs : dict
        As :func:`read_irb` plus ``frame_index``.
    """
    p = check_file(path)
    for info, frame in iter_irb_frames(p):
        check_temperatures(frame, p)
        attrs = _attrs(info, p)
        attrs["frame_index"] = int(info["frame_index"])
        yield frame, unix_time(info), attrs


def iter_irb_dataarrays(path: str | os.PathLike) -> Iterator[xr.DataArray]:
    """Stream the frames of an ``.irb`` file as DataArrays.

    Parameters
    ----------
    path : path-like
        ``.irb`` image or sequence.

    Yields
    ------
    xarray.DataArray
        float32 °C, dims ``("v", "u")``; scalar coordinate ``time`` =
        recording time in s since 1970-01-01 00:00 of the camera's clock
        (absolute, so that frames of several files keep their order and
        spacing; subtract the first frame's time for a relative axis), absent
        when the frame has no valid date. ``attrs`` as :func:`read_irb` plus
        ``frame_index``.
    """
    for frame, t, attrs in iter_irb_records(path):
        yield temperature_dataarray(frame, time=t, attrs=attrs)


def unix_time(info: dict) -> float | None:
    """Recording time of a frame (``meta`` of :func:`iter_irb_headers`) in s since 1970-01-01, or None."""
    return None if info["seconds"] is None else info["seconds"] - _UNIX_EPOCH_OLE


def read_irb(path: str | os.PathLike) -> xr.DataArray:
    """Read an InfraTec ``.irb`` image or sequence.

    Parameters
    ----------
    path : path-like
        ``.irb`` file: one image, a sequence of image blocks, or a VarioCAM
        HD file of several IRB files written end to end.

    Returns
    -------
    xarray.DataArray
        float32 °C. One image: dims ``("v", "u")``. Several: dims
        ``("time", "v", "u")`` with ``time`` (s, from the recorded date and
        milliseconds, relative to the first frame) and ``frame_index``
        coordinates. ``attrs`` (of the first frame): ``format="irb"``,
        ``source``, ``rec_datetime`` (ISO 8601), ``emissivity``,
        ``distance`` (m), ``env_temp``/``path_temp`` (°C), ``wavelength``
        (µm), ``calib_range``/``shot_range`` (°C), ``device``, ``optics``,
        ``lens``, ``serial``, ``file_type``.

    Raises
    ------
    FormatError
        See :func:`iter_irb_frames`; also no image block at all.
    DataError
        Frames of different sizes in one sequence.
    """
    p = check_file(path)
    # sizes and times from the headers first: nothing is decoded or allocated
    # for a sequence that cannot be read
    heads = list(iter_irb_headers(p))
    n = len(heads)
    if n == 0:
        raise FormatError("holds no image block (only previews or text?)", p)
    first = heads[0]
    shape = (first["height"], first["width"])
    for k, info in enumerate(heads):
        if (info["height"], info["width"]) != shape:
            raise DataError(f"{p}: frame {k} is {info['width']} x {info['height']} px, frame 0 is "
                            f"{shape[1]} x {shape[0]} px; a sequence needs one frame size")
    seconds = [info["seconds"] for info in heads]
    indices = [info["frame_index"] for info in heads]
    time = None
    if n > 1:
        if any(s is None for s in seconds):
            warnings.warn(f"{p}: some frames have no valid recording time; the time coordinate is the "
                          "frame number", IrdicWarning, stacklevel=2)
            time = np.arange(n, dtype=np.float64)
        else:
            t = np.asarray(seconds, dtype=np.float64)
            time = t - t[0]
            if (np.diff(time) <= 0).any():
                k = int(np.flatnonzero(np.diff(time) <= 0)[0]) + 1
                warnings.warn(f"{p}: frame times do not increase (frame {k} at {time[k]:.3f} s after frame "
                              f"{k - 1} at {time[k - 1]:.3f} s)", IrdicWarning, stacklevel=2)
    stack = np.empty((n,) + shape, np.float32)
    for k, (info, frame) in enumerate(iter_irb_frames(p)):
        if k >= n or info["offset"] != heads[k]["offset"]:
            raise DataError(f"{p}: the file changed while it was read")
        stack[k] = frame
    check_temperatures(stack, p)
    attrs = _attrs(first, p)
    if n == 1:
        attrs["frame_index"] = int(indices[0])
        return temperature_dataarray(stack[0], attrs=attrs)
    attrs["n_frames"] = n
    return temperature_dataarray(stack, time=time, extra_coords={"frame_index": np.asarray(indices)},
                                 attrs=attrs)
