"""The FFF block of a FLIR radiometric JPEG (R-JPEG).

An R-JPEG is an ordinary JPEG (the colour-mapped picture) that carries one
FFF block (:mod:`irdic.io.flir`) split over APP1 segments whose payload
starts ``FLIR\\0``: byte 5 = 1, byte 6 = the chunk's index, byte 7 = the index
of the last chunk; the data from byte 8 on, concatenated in index order, is
the block (1 to 23 segments in the files seen). The segments sit before the
image data; they are found by walking the JPEG's segment lengths.
"""

from __future__ import annotations

import io
import os
import struct

from ..errors import FormatError
from ._common import check_file

__all__ = ["flir_segments", "fff_from_jpeg", "is_radiometric_jpeg"]

SOI = b"\xff\xd8"
FLIR_APP1 = b"FLIR\x00"


def flir_segments(fh, path, strict: bool) -> list[bytes]:
    """The FLIR APP1 payloads of a JPEG (after their 8-byte header), in chunk order; empty when it has none.

    Fill bytes 0xFF before a marker and markers without a length (TEM, RSTn)
    are stepped over; a chunk that occurs twice with the same content (a
    picture saved again) counts once.

    Raises
    ------
    FormatError
        With ``strict``: a chunk twice with different contents, or chunks
        missing from 0 to the last index.
    """
    fh.seek(0)
    if fh.read(2) != SOI:
        return []
    chunks: dict[int, bytes] = {}
    last = 0
    while True:
        marker = fh.read(2)
        if len(marker) < 2 or marker[0] != 0xFF or marker[1] in (0xD9, 0xDA):
            break  # end of the header segments (start of scan) or a damaged file
        if marker[1] == 0xFF:  # a fill byte before the marker
            fh.seek(-1, io.SEEK_CUR)
            continue
        if marker[1] == 0x01 or 0xD0 <= marker[1] <= 0xD7:
            continue
        size = fh.read(2)
        if len(size) < 2:
            break
        payload = fh.read(max(0, struct.unpack(">H", size)[0] - 2))
        if marker[1] == 0xE1 and payload[:5] == FLIR_APP1 and len(payload) >= 8:
            k, data = payload[6], payload[8:]
            if k in chunks and chunks[k] != data:
                if strict:
                    raise FormatError(f"radiometric JPEG: the FLIR APP1 segment {k} occurs twice with different "
                                      "contents (edited picture)", path)
                continue
            chunks[k] = data
            last = max(last, payload[7])
    missing = sorted(set(range(max([last, *chunks]) + 1)) - set(chunks)) if chunks else []
    if strict and missing:
        raise FormatError(f"radiometric JPEG: FLIR APP1 segment(s) {missing} of 0..{last} are missing "
                          "(truncated or edited picture)", path)
    return [chunks[k] for k in sorted(chunks)]


def is_radiometric_jpeg(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a JPEG with FLIR radiometric data (APP1 ``FLIR`` segments)."""
    with open(check_file(path), "rb") as fh:
        return bool(flir_segments(fh, path, strict=False))


def plain_jpeg_message(path) -> str:
    """Why a JPEG without FLIR segments cannot be read (DJI's own radiometric JPEGs named as such)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if b"DJI" in head:
        return ("a DJI radiometric JPEG in DJI's own format (no APP1 'FLIR' segment; DJI's Zenmuse XT and XT2 "
                "write FLIR's format, its later cameras their own): convert it to temperatures with DJI's Thermal "
                "SDK and give irdic a TIFF stack of °C")
    return ("a JPEG without FLIR radiometric data (no APP1 'FLIR' segment): a plain picture holds colours, not "
            "temperatures; save radiometric JPEGs or record a .seq")


def fff_from_jpeg(path) -> bytes:
    """The FFF block of a radiometric JPEG.

    Raises
    ------
    FormatError
        No FLIR segment (a plain picture, or a DJI radiometric JPEG in DJI's
        own format), chunks missing or contradicting each other.
    """
    with open(path, "rb") as fh:
        chunks = flir_segments(fh, path, strict=True)
    if not chunks:
        raise FormatError(plain_jpeg_message(path), path)
    return b"".join(chunks)
