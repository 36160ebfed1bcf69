"""Helpers shared by the file readers: checks and text decoding."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import FormatError

__all__ = ["check_file", "decode_text", "read_text", "head_bytes", "non_regular_kind"]


def non_regular_kind(mode: int) -> str | None:
    """What a non-regular file is, in words, from its ``st_mode``; None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_file(path: str | os.PathLike) -> Path:
    """Return ``path`` as a Path if it is a readable, non-empty regular file.

    Every reader opens its file through here, so pipes, devices and sockets
    are refused before anything opens them: opening a FIFO blocks until a
    writer appears, and a device such as ``/dev/zero`` never ends.

    Raises
    ------
    FormatError
        The file is missing, a directory, a pipe/device/socket, empty or
        unreadable.
    """
    p = Path(path)
    try:
        st = p.stat()  # follows links: a link to a regular file is fine
    except (FileNotFoundError, NotADirectoryError):
        raise FormatError("file not found", p) from None
    except OSError as exc:
        raise FormatError(f"cannot read the file ({exc.strerror})", p) from exc
    kind = non_regular_kind(st.st_mode)
    if kind == "a folder":
        raise FormatError("is a folder, expected a file", p)
    if kind is not None:
        raise FormatError(f"is {kind}, not a regular file; irdic reads exports stored as files on disk", p)
    try:
        size = st.st_size
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
