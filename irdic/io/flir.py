"""FLIR radiometric files: ``.seq``, ``.csq``, single ``.fff`` frames and radiometric JPEGs.

Every one is built from FFF blocks (one frame each):

- a 64-byte header: magic ``FFF\\0``, creator string[16], u32 version
  (100..199; read little-endian first, big-endian when that is out of
  range), u32 offset of the record directory, u32 number of entries;
- the directory: 32-byte entries (header byte order) of u16 type, u16
  subtype, u32 version, u32 index, u32 offset (from the block start), u32
  length, three more u32; type 0 entries are unused, and the directory order
  is not the order of the records in the file;
- records: type 0x01 the raw image (32-byte header of u16 words, [1] width,
  [2] height, word 0 = 2 in the record's byte order; the image at +32,
  encoded by the entry's subtype: 2 uncompressed u16, 3 a 16-bit PNG, 4
  JPEG-LS), type 0x20 the camera info (:mod:`irdic.io.flir_planck`).

``.seq`` and ``.csq`` files are such blocks end to end, with no index and no
fixed stride; a block ends at the largest ``offset + length`` of its
directory and the next one starts there. Frames are found by following that
chain: the 4 bytes ``FFF\\0`` also occur inside pixel data, so the file is
never searched for them. A radiometric JPEG carries one FFF block split over
APP1 segments (:mod:`irdic.io.flir_jpeg`). A block without a raw image record
(a file header, a damaged frame) is left out with a warning.

PNG samples are usually stored little-endian although PNG is big-endian (the
ThermaCAM EX320, whose records are big-endian, stores them as PNG says): the
byte order is chosen per image as the one that puts clearly more pixels
inside the raw range the camera displayed (RawValueMedian +- RawValueRange),
else the clearly smoother one, else the raw record's. Rows run top to
bottom, in the sensor's orientation (a picture turned afterwards in a photo
viewer keeps its raw image as recorded).

Frames are streamed: memory is one frame whatever the length of the record.
Times are the Unix times of each frame's camera info.
"""

from __future__ import annotations

import io
import os
import struct
import warnings
from typing import Iterator, Mapping

import numpy as np
import xarray as xr

from ..errors import DataError, FormatError, IrdicWarning
from ._common import check_file
from .flir_jpeg import fff_from_jpeg, is_radiometric_jpeg
from .flir_planck import camera_info, counts_table, object_parameters, parameter_attrs
from .stack import check_temperatures, temperature_dataarray

__all__ = ["read_flir", "iter_flir_frames", "iter_flir_headers", "iter_flir_dataarrays", "iter_flir_records",
           "is_radiometric_jpeg",
           "MAGIC", "HEADER_SIZE", "ENTRY_SIZE", "REC_RAW", "REC_CAMERA", "RAW_HEADER_SIZE"]

MAGIC = b"FFF\x00"
HEADER_SIZE = 64
ENTRY_SIZE = 32
RAW_HEADER_SIZE = 32
REC_RAW, REC_CAMERA = 0x01, 0x20
RAW_BE, RAW_LE, RAW_PNG, RAW_JPEGLS = 1, 2, 3, 4
MAX_ENTRIES = 4096
MAX_SIDE = 16384


# ----------------------------------------------------------------------------
# the FFF chain
# ----------------------------------------------------------------------------
def _header(head: bytes, where: str, path) -> tuple[str, int, int]:
    """``(byte order, directory offset, entries)`` of a 64-byte FFF header."""
    if len(head) < HEADER_SIZE or head[:4] not in (MAGIC, b"AFF\x00"):
        raise FormatError(f"{where}: no FFF header (found {head[:4]!r}, expected {MAGIC!r}); the chain of "
                          "frames is broken (damaged or not a FLIR file)", path)
    for bo in "<>":
        version, dir_offset, n = struct.unpack_from(bo + "III", head, 0x14)
        if 100 <= version < 200:
            break
    else:
        raise FormatError(f"{where}: FFF version {struct.unpack_from('<I', head, 0x14)[0]} is neither "
                          "100..199 little- nor big-endian (damaged header)", path)
    if dir_offset < HEADER_SIZE or not 0 < n <= MAX_ENTRIES:
        raise FormatError(f"{where}: FFF record directory at +{dir_offset} with {n} entries is not plausible "
                          "(damaged header)", path)
    return bo, dir_offset, n


def _directory(raw: bytes, bo: str) -> tuple[dict[int, tuple[int, int, int]], int]:
    """``{record type: (subtype, offset, length)}`` of the used entries (the first of each type), and the
    largest ``offset + length`` over all of them (the block's end)."""
    out: dict[int, tuple[int, int, int]] = {}
    end = 0
    for k in range(len(raw) // ENTRY_SIZE):
        rtype, sub, _ver, _idx, off, length = struct.unpack_from(bo + "HHIIII", raw, k * ENTRY_SIZE)
        if rtype:
            out.setdefault(rtype, (sub, off, length))
            end = max(end, off + length)
    return out, end


def _plausible_header(fh, pos: int, size: int) -> bool:
    """Whether a complete FFF header and a directory with a raw image record that fits the file start at ``pos``."""
    fh.seek(pos)
    head = fh.read(HEADER_SIZE)
    try:
        bo, dir_offset, n = _header(head, "", None)
    except FormatError:
        return False
    fh.seek(pos + dir_offset)
    raw = fh.read(ENTRY_SIZE * n)
    if len(raw) < ENTRY_SIZE * n:
        return False
    records, end = _directory(raw, bo)
    return REC_RAW in records and pos + records[REC_RAW][1] + RAW_HEADER_SIZE <= size


def _next_header(fh, start: int, size: int, chunk: int = 1 << 20) -> int | None:
    """The first plausible FFF header at or after ``start`` (bytes between blocks that are not a block: a gap or
    an index some writers leave); None when there is none. Only the gap is searched, never a known block."""
    pos = start
    while pos < size - HEADER_SIZE:
        fh.seek(pos)
        buf = fh.read(chunk + 3)
        found = []
        for magic in (MAGIC, b"AFF\x00"):
            k = buf.find(magic)
            while k >= 0:
                found.append(k)
                k = buf.find(magic, k + 1)
        for k in sorted(found):
            if _plausible_header(fh, pos + k, size):
                return pos + k
        pos += chunk
    return None


def _walk(fh, path, size: int) -> Iterator[dict]:
    """The blocks of a file that hold a frame, in chain order: ``{frame, offset, length, records}``.

    ``length`` may run past the end of the file for the last block only. A
    block without a raw image record (a header or a damaged frame) is left
    out with a warning; frames are numbered among the blocks that hold one.
    """
    offset, block, frame, skipped = 0, 0, 0, []
    while offset < size:
        where = f"frame {frame} (byte {offset})"
        fh.seek(offset)
        head = fh.read(HEADER_SIZE)
        if block > 0 and head[:4] not in (MAGIC, b"AFF\x00"):
            resume = _next_header(fh, offset, size)
            if resume is None:
                if size - offset >= HEADER_SIZE:  # less is padding (radiometric JPEGs end with a byte or two)
                    warnings.warn(f"{path}: {size - offset} bytes after frame {frame - 1} are not an FFF frame; "
                                  "ignored", IrdicWarning, stacklevel=3)
                break
            warnings.warn(f"{path}: {resume - offset} bytes after frame {frame - 1} (from byte {offset}) are not "
                          f"FFF data (padding, or a frame damaged beyond reading); skipped to the next FFF header "
                          f"at byte {resume}", IrdicWarning, stacklevel=3)
            offset = resume
            continue
        if block > 0 and len(head) < HEADER_SIZE:
            _cut(path, frame, "inside its header")
            break
        bo, dir_offset, n = _header(head, where, path)
        fh.seek(offset + dir_offset)
        raw = fh.read(ENTRY_SIZE * n)
        if len(raw) < ENTRY_SIZE * n:
            if block > 0:
                _cut(path, frame, "inside its record directory")
                break
            raise FormatError(f"{where}: the record directory runs past the end of the file (truncated)", path)
        records, end = _directory(raw, bo)
        length = max(dir_offset + ENTRY_SIZE * n, end)
        block += 1
        if REC_RAW not in records:
            skipped.append((offset, sorted(records)))
            offset += length
            continue
        # a file of one frame (a .fff, a radiometric JPEG) has no frame number: its position says nothing
        single = frame == 0 and size - (offset + length) < HEADER_SIZE
        yield {"frame": frame, "offset": offset, "length": length, "records": records,
               "frame_index": None if single else frame, "aff": head[:4] == b"AFF\x00"}
        offset += length
        frame += 1
    if skipped:
        kinds = sorted({f"0x{t:02x}" for _, types in skipped for t in types})
        what = (f"{len(skipped)} FFF block(s) (the first at byte {skipped[0][0]}) hold no raw image record "
                f"(type 1; record types {', '.join(kinds) or 'none'})")
        if frame == 0:
            raise FormatError(f"{what} and no block holds one: no frame to read", path)
        warnings.warn(f"{path}: {what}; left out", IrdicWarning, stacklevel=3)


def _cut(path, frame: int, where: str) -> None:
    warnings.warn(f"{path}: frame {frame} is cut off by the end of the file ({where}); left out", IrdicWarning,
                  stacklevel=4)


def _read_record(fh, block: dict, rtype: int, size: int) -> tuple[int, bytes, int]:
    """``(subtype, bytes, declared length)`` of a record; the bytes may be short at the end of the file."""
    sub, off, length = block["records"][rtype]
    fh.seek(block["offset"] + off)
    return sub, fh.read(max(0, min(length, size - block["offset"] - off))), length


def _open_blocks(p) -> tuple[object, int]:
    """A binary file object over the FFF chain of ``p`` (the file, or the FFF block of a JPEG) and its size."""
    fh = open(p, "rb")
    if fh.read(2) != b"\xff\xd8":
        return fh, p.stat().st_size
    fh.close()
    data = fff_from_jpeg(p)
    return io.BytesIO(data), len(data)


# ----------------------------------------------------------------------------
# frames
# ----------------------------------------------------------------------------
def _usable_camera(fh, block: dict, size: int, path) -> dict | None:
    """The camera info of a block; None for a last block cut off too early to give a frame (warns).

    A last block that runs past the end of the file is used when its camera
    info and its image are there (a ``.csq`` misses only padding) or, for
    uncompressed images, at least half of the pixels are.
    """
    if block["offset"] + block["length"] <= size:
        return _camera(fh, block, size, path)
    try:
        cam = _camera(fh, block, size, path)
        _frame_counts(fh, block, size, cam, path, warn=False)
    except FormatError as exc:
        warnings.warn(f"{path}: frame {block['frame']} is cut off by the end of the file ({exc.args[0]}); "
                      "left out", IrdicWarning, stacklevel=4)
        return None
    return cam


def _camera(fh, block: dict, size: int, path) -> dict:
    where = f"frame {block['frame']}"
    if REC_CAMERA not in block["records"]:
        raise FormatError(f"{where}: the FFF block has no camera-info record (type 0x20): no Planck constants "
                          "to convert counts to temperatures" + (" (an AFF file, as older FLIR software such as "
                          "ExaminIR writes, stores none: export temperatures from that software)"
                          if block.get("aff") else ""), path)
    _sub, raw, _length = _read_record(fh, block, REC_CAMERA, size)
    return camera_info(raw, where, path)


def _raw_shape(raw: bytes, where: str, path) -> tuple[str, int, int]:
    if len(raw) < RAW_HEADER_SIZE:
        raise FormatError(f"{where}: raw image record of {len(raw)} bytes (truncated)", path)
    bo = "<" if struct.unpack_from("<H", raw)[0] == 2 else ">" if struct.unpack_from(">H", raw)[0] == 2 else ""
    if not bo:
        raise FormatError(f"{where}: raw image record has no byte-order mark (first u16 = 2)", path)
    _, width, height = struct.unpack_from(bo + "HHH", raw)
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise FormatError(f"{where}: raw image size {width} x {height} px is not plausible", path)
    return bo, width, height


def _in_range(img: np.ndarray, median: int, rng: int) -> float:
    return float(np.count_nonzero(np.abs(img.astype(np.int32) - median) <= rng)) / img.size


def _roughness(img: np.ndarray) -> float:
    x = img.astype(np.float64)
    return float(np.abs(np.diff(x, axis=-1)).mean()) if x.shape[-1] > 1 else 0.0


def _png_order(img: np.ndarray, cam: dict, record_order: str) -> np.ndarray:
    """The PNG's samples in the byte order that makes them counts (see the module notes).

    The first clear answer of: the share of pixels inside the raw range the
    camera displayed (one order at least half, and a quarter more than the
    other), the roughness (one order at least 4 times smoother), the byte
    order of the raw record (in every file seen the PNG's samples follow it:
    little-endian records, byte-swapped PNG; big-endian, a plain PNG).
    """
    swapped = img.byteswap()
    if cam["range"] > 0:
        inside = _in_range(img, cam["median"], cam["range"]), _in_range(swapped, cam["median"], cam["range"])
        if max(inside) >= 0.5 and abs(inside[0] - inside[1]) >= 0.25:
            return img if inside[0] > inside[1] else swapped
    rough = _roughness(img), _roughness(swapped)
    if max(rough) > 4 * min(rough):
        return img if rough[0] < rough[1] else swapped
    return img if record_order == ">" else swapped


def _codestream_size(data: bytes, sub: int) -> tuple[int, int] | None:
    """``(width, height)`` a PNG (IHDR) or JPEG-LS (SOF55) stream declares, None when it declares none."""
    if sub == RAW_PNG:
        if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR" or len(data) < 24:
            return None
        return struct.unpack_from(">II", data, 16)
    pos = 2 if data[:2] == b"\xff\xd8" else len(data)
    while pos + 9 <= len(data) and data[pos] == 0xFF:
        marker, seg = data[pos + 1], struct.unpack_from(">H", data, pos + 2)[0]
        if marker == 0xF7:
            h, w = struct.unpack_from(">HH", data, pos + 5)
            return w, h
        pos += 2 + seg
    return None


def _decode(sub: int, data: bytes, bo: str, w: int, h: int, cam: dict, where: str, path) -> np.ndarray:
    """Counts (uint16, shape (h, w)) of a raw record's image; incomplete uncompressed rows are masked later."""
    if sub in (RAW_LE, RAW_BE):
        # the pixels are u16 words of the record, in the byte order its mark (word 0 = 2) gives, as exiftool reads
        # them: little-endian in every real file seen; the subtype (1 "big-", 2 "little-endian") agrees with the mark
        dtype = np.dtype(np.uint16).newbyteorder(bo)
        n = min(len(data) // 2, w * h)
        if n == w * h:  # the usual case: the counts as they lie in the record, no copy
            return np.frombuffer(data, dtype, count=n).reshape(h, w)
        out = np.zeros(w * h, np.uint16)
        out[:n] = np.frombuffer(data, dtype, count=n)
        return out.reshape(h, w)
    import imagecodecs

    if sub not in (RAW_PNG, RAW_JPEGLS):
        raise FormatError(f"{where}: raw image encoding (subtype) {sub} is not one irdic knows (2 uncompressed, "
                          "3 PNG, 4 JPEG-LS); export the record as an uncompressed .seq", path)
    what = "PNG" if sub == RAW_PNG else "JPEG-LS"
    declared = _codestream_size(data, sub)
    if declared != (w, h):  # checked before decoding: a damaged stream must not allocate a huge image
        raise FormatError(f"{where}: the {what} raw image " + ("has no readable size header" if declared is None
                          else f"is {declared[0]} x {declared[1]} px") + f", the record header says {w} x {h} px",
                          path)
    try:
        img = imagecodecs.png_decode(data) if sub == RAW_PNG else imagecodecs.jpegls_decode(data)
    except Exception as exc:  # the codecs raise their own error types
        raise FormatError(f"{where}: the {what} raw image cannot be decoded ({exc})", path) from None
    if img.dtype != np.uint16 or img.shape != (h, w):
        raise FormatError(f"{where}: the raw image decodes to {img.dtype} {img.shape}, the record header says "
                          f"{w} x {h} px of 16 bits", path)
    return _png_order(img, cam, bo) if sub == RAW_PNG else img


def _frame_counts(fh, block: dict, size: int, cam: dict, path, warn: bool = True) -> tuple[np.ndarray, int]:
    """Counts of one frame and the number of valid pixels (all unless the file ends inside them)."""
    where = f"frame {block['frame']}"
    sub, raw, length = _read_record(fh, block, REC_RAW, size)
    bo, w, h = _raw_shape(raw, where, path)
    data = raw[RAW_HEADER_SIZE:]
    if sub in (RAW_LE, RAW_BE) and (length < RAW_HEADER_SIZE + 2 * w * h or len(data) < w * h):
        raise FormatError(f"{where}: {w} x {h} uncompressed pixels need {RAW_HEADER_SIZE + 2 * w * h} bytes, the raw "
                          f"image record " + (f"declares {length}" if length < RAW_HEADER_SIZE + 2 * w * h else
                                               f"holds only {len(raw)} before the file ends")
                          + " (damaged or truncated)", path)
    counts = _decode(sub, data, bo, w, h, cam, where, path)
    valid = w * h
    if len(raw) < length and warn:
        if sub in (RAW_LE, RAW_BE):
            valid = min(valid, len(data) // 2)
        warnings.warn(f"{path}: frame {block['frame']} ends {length - len(raw)} bytes short of its raw image "
                      "record (truncated file)" + (f"; {w * h - valid} missing pixels are NaN" if valid < w * h
                                                    else "; the image itself is complete"),
                      IrdicWarning, stacklevel=4)
    return counts, valid


def iter_flir_headers(path: str | os.PathLike) -> Iterator[dict]:
    """Stream the frame headers of a FLIR file without decoding pixels.

    Yields
    ------
    dict
        ``frame`` (position in the chain), ``frame_index`` (the same, None
        in a file of one frame), ``offset`` (byte), ``width``,
        ``height``, ``seconds`` (Unix time, s, or None), ``tz_minutes``,
        ``model``, ``median``/``range`` (counts), ``params`` (camera info,
        see :func:`irdic.io.flir_planck.camera_info`).
    """
    p = check_file(path)
    fh, size = _open_blocks(p)
    with fh:
        for block in _walk(fh, p, size):
            cam = _usable_camera(fh, block, size, p)
            if cam is None:
                return
            fh.seek(block["offset"] + block["records"][REC_RAW][1])
            _bo, w, h = _raw_shape(fh.read(RAW_HEADER_SIZE), f"frame {block['frame']}", p)
            yield {"frame": block["frame"], "frame_index": block["frame_index"], "offset": block["offset"],
                   "width": w, "height": h, **cam}


def iter_flir_frames(path: str | os.PathLike, overrides: Mapping[str, float] | None = None
                     ) -> Iterator[tuple[dict, np.ndarray]]:
    """Stream the frames of a FLIR file one at a time.

    Parameters
    ----------
    path : path-like
        ``.seq``, ``.csq``, ``.fff`` or radiometric JPEG.
    overrides : mapping, optional
        ``emissivity`` and/or ``reflected_temperature`` (°C) replacing the
        file's object parameters.

    Yields
    ------
    meta : dict
        As :func:`iter_flir_headers`, ``params`` with the overrides applied.
    frame : ndarray of float32, shape (height, width)
        Temperatures in °C (NaN for counts too cold to have one and for
        pixels missing from a truncated last frame), top row first.

    Raises
    ------
    FormatError
        Broken chain, damaged header or record, an unknown raw encoding,
        camera info that cannot give temperatures.

    Warns
    -----
    IrdicWarning
        A truncated last frame (decoded as far as it goes), bytes after the
        last frame that are not one.
    """
    p = check_file(path)
    fh, size = _open_blocks(p)
    key = table = None
    with fh:
        for block in _walk(fh, p, size):
            cam = _usable_camera(fh, block, size, p)
            if cam is None:
                return
            params = object_parameters(cam["params"], overrides, f"frame {block['frame']}", p)
            counts, valid = _frame_counts(fh, block, size, cam, p)
            pkey = tuple(sorted(params.items()))
            if pkey != key:  # one table per parameter set: the parameters rarely change within a record
                table, key = counts_table(params), pkey
            frame = table.take(counts)
            if valid < frame.size:
                frame.reshape(-1)[valid:] = np.nan
            h, w = frame.shape
            yield {"frame": block["frame"], "frame_index": block["frame_index"], "offset": block["offset"],
                   "width": w, "height": h,
                   **cam, "params": params}, frame


def _attrs(info: dict, path) -> dict:
    attrs = {"format": "flir", "source": str(path), **parameter_attrs(info["params"]),
             "sensor_width": info["width"], "sensor_height": info["height"]}
    if info["model"]:
        attrs["camera"] = info["model"]
    return attrs


def iter_flir_records(path: str | os.PathLike, overrides: Mapping[str, float] | None = None
                      ) -> Iterator[tuple[np.ndarray, float | None, dict]]:
    """Stream the frames of a FLIR file as ``(values, time, attrs)``, without building DataArrays.

    The content of :func:`iter_flir_dataarrays` (series ingest takes it as
    it is: a DataArray per frame costs as much as decoding it).

    Yields
    ------
    values : ndarray of float32, shape (height, width)
        °C, top row first, full-sensor pixels from (0, 0).
    time : float or None
        The frame's Unix time (s, UTC).
    attrs : dict
        As :func:`read_flir` plus ``frame_index`` (the position in a file of
        several frames; absent for a file of one).
    """
    p = check_file(path)
    for info, frame in iter_flir_frames(p, overrides):
        # no check_temperatures scan: the counts table holds only NaN and finite values above 0 K
        attrs = _attrs(info, p)
        if info["frame_index"] is not None:
            attrs["frame_index"] = info["frame_index"]
        yield frame, info["seconds"], attrs


def iter_flir_dataarrays(path: str | os.PathLike, overrides: Mapping[str, float] | None = None
                         ) -> Iterator[xr.DataArray]:
    """Stream the frames of a FLIR file as DataArrays.

    Yields
    ------
    xarray.DataArray
        float32 °C, dims ``("v", "u")``; scalar coordinate ``time`` = the
        frame's Unix time (s, UTC), absent when the frame has none;
        ``attrs`` as :func:`iter_flir_records`.
    """
    for frame, t, attrs in iter_flir_records(path, overrides):
        yield temperature_dataarray(frame, time=t, attrs=attrs)


def check_series(heads: list[dict], path) -> None:
    """DataError when frames change size; warnings when camera parameters change or times do not increase.

    Raises
    ------
    FormatError
        No complete frame at all.
    DataError
        Frames of different sizes.
    """
    if not heads:
        raise FormatError("holds no complete FLIR frame (truncated or empty FFF data)", path)
    first = heads[0]
    for info in heads[1:]:
        k = info["frame"]
        if (info["width"], info["height"]) != (first["width"], first["height"]):
            raise DataError(f"{path}: frame {k} is {info['width']} x {info['height']} px, frame 0 is "
                            f"{first['width']} x {first['height']} px; a record needs one frame size")
    changed = next((info for info in heads[1:] if info["params"] != first["params"]), None)
    if changed is not None:
        names = sorted(n for n, v in changed["params"].items() if first["params"][n] != v)
        warnings.warn(f"{path}: frame {changed['frame']} changes the camera parameters ({', '.join(names)}) "
                      "within the record; each frame is converted with its own", IrdicWarning, stacklevel=3)
    t = [info["seconds"] for info in heads]
    if None not in t:
        bad = next((k for k in range(1, len(t)) if t[k] <= t[k - 1]), None)
        if bad is not None:
            warnings.warn(f"{path}: frame times do not increase (frame {bad} at {t[bad] - t[0]:.3f} s after frame "
                          f"{bad - 1} at {t[bad - 1] - t[0]:.3f} s)", IrdicWarning, stacklevel=3)


def read_flir(path: str | os.PathLike, *, emissivity: float | None = None,
              reflected_temperature: float | None = None) -> xr.DataArray:
    """Read a FLIR ``.seq``, ``.csq``, ``.fff`` or radiometric JPEG.

    Parameters
    ----------
    path : path-like
    emissivity : float, optional
        Replaces the file's emissivity (0..1].
    reflected_temperature : float, optional
        Replaces the file's reflected apparent temperature (°C).

    Returns
    -------
    xarray.DataArray
        float32 °C. One frame: dims ``("v", "u")`` with scalar ``time``
        (Unix s) when the frame has one. Several: dims ``("time", "v", "u")``
        with ``time`` in s relative to the first frame (the frame numbers,
        with a warning, when a frame has no time stamp) and ``frame_index``.
        ``attrs``: ``format="flir"``, ``source``, ``camera``, the object
        parameters (``emissivity``, ``distance`` m, ``reflected_temp``,
        ``env_temp`` (atmosphere), ``ir_window_temp`` °C,
        ``relative_humidity``, ``ir_window_transmission``) and the Planck
        constants (``planck_r1`` ... ``planck_o``) of the first frame, after
        the overrides.

    Raises
    ------
    FormatError, DataError
        See :func:`iter_flir_frames`; frames of different sizes.
    """
    p = check_file(path)
    overrides = {"emissivity": emissivity, "reflected_temperature": reflected_temperature}
    heads = list(iter_flir_headers(p))  # sizes and times first: nothing is decoded for a record that cannot be read
    check_series(heads, p)
    n = len(heads)
    stack = np.empty((n, heads[0]["height"], heads[0]["width"]), np.float32)
    first = None
    for k, (info, frame) in enumerate(iter_flir_frames(p, overrides)):
        if k >= n or info["offset"] != heads[k]["offset"]:
            raise DataError(f"{p}: the file changed while it was read")
        stack[k] = frame
        first = first or info
    check_temperatures(stack, p, allow_nan=True)
    attrs = _attrs(first, p)
    if n == 1:
        return temperature_dataarray(stack[0], time=first["seconds"], attrs=attrs)
    attrs["n_frames"] = n
    t = [info["seconds"] for info in heads]
    if None in t:
        warnings.warn(f"{p}: frame {t.index(None)} has no time stamp: the time coordinate numbers the frames "
                      "(0, 1, 2 ...) instead of giving seconds", IrdicWarning, stacklevel=2)
    # the stamps have millisecond resolution: relative times rounded to it drop float64 noise of Unix seconds
    time = np.arange(n, dtype=np.float64) if None in t else np.round(np.asarray(t) - t[0], 3)
    return temperature_dataarray(stack, time=time, extra_coords={"frame_index": np.arange(n)}, attrs=attrs)
