"""Helpers shared by the file readers: checks and text decoding."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import FormatError

__all__ = ["check_file", "decode_text", "read_text", "head_bytes"]


def check_file(path: str | os.PathLike) -> Path:
    """Return ``path`` as a Path if it is a readable, non-empty regular file.

    Raises
    ------
    FormatError
        The file is missing, a directory, empty or unreadable.
    """
    p = Path(path)
    if not p.exists():
        raise FormatError("file not found", p)
    if p.is_dir():
        raise FormatError("is a folder, expected a file", p)
    try:
        size = p.stat().st_size
        with open(p, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise FormatError(f"cannot read the file ({exc.strerror})", p) from exc
    if size == 0:
        raise FormatError("file is empty", p)
    return p


def head_bytes(path: str | os.PathLike, n: int = 4096) -> bytes:
    """First ``n`` bytes of a file (for format detection)."""
    with open(check_file(path), "rb") as fh:
        return fh.read(n)


def decode_text(raw: bytes) -> str:
    """Text of an export: UTF-8 (BOM dropped) when valid, else cp1252 (never fails)."""
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


def read_text(path: str | os.PathLike) -> str:
    """Read a text export whatever its encoding.

    UTF-8 (with or without BOM) is tried first; exports of Windows software are
    usually cp1252/latin-1 (the ``°`` sign), which is the fallback and never
    fails. CRLF and CR line ends are kept; use ``str.splitlines``.
    """
    return decode_text(check_file(path).read_bytes())
