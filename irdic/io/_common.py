"""Helpers shared by the file readers: checks and text decoding."""

from __future__ import annotations

import codecs
import os
import stat
from pathlib import Path
from typing import Iterator

from ..errors import FormatError

__all__ = ["check_file", "decode_text", "read_text", "head_bytes", "non_regular_kind", "TextFile"]


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


class TextFile:
    """A text export read once as bytes and decoded a block of lines at a time.

    Parsing a large export line by line must not hold the whole text several
    times over (the text, a list of its lines, a joined copy...): only the
    bytes are kept, and lines are decoded in blocks of about
    :attr:`BLOCK` bytes that end at a line end. The lines are those of
    :meth:`str.splitlines` on the whole decoded text (CRLF, CR and LF alike),
    and the encoding is that of :func:`decode_text`.

    Parameters
    ----------
    path : path-like

    Raises
    ------
    FormatError
        The file is missing, empty, not a regular file, or binary (contains
        NUL bytes).
    """

    BLOCK = 1 << 18

    def __init__(self, path: str | os.PathLike):
        self.path = check_file(path)
        raw = self.path.read_bytes()
        if b"\x00" in raw:
            raise FormatError("contains NUL bytes: this is a binary file, expected a text export", self.path)
        self._raw = raw
        self._start = 3 if raw.startswith(b"\xef\xbb\xbf") else 0
        self.encoding = "utf-8" if _is_utf8(raw, self._start, self.BLOCK) else "cp1252"

    def blocks(self) -> Iterator[tuple[int, list[str]]]:
        """``(k, lines)`` for successive blocks; ``k`` = 0-based index of the block's first line."""
        raw, pos, k = self._raw, self._start, 0
        while pos < len(raw):
            cut = raw.find(b"\n", pos + self.BLOCK - 1)
            # cutting just after a LF keeps CRLF pairs and UTF-8 sequences whole
            cut = len(raw) if cut < 0 else cut + 1
            lines = raw[pos:cut].decode(self.encoding, errors="replace").splitlines()
            yield k, lines
            k += len(lines)
            pos = cut

    def lines(self) -> Iterator[tuple[int, str]]:
        """``(k, line)`` for every line, ``k`` 0-based (line ``k + 1`` of the file)."""
        for k0, lines in self.blocks():
            yield from enumerate(lines, start=k0)

    def head(self, n: int) -> list[str]:
        """The first ``n`` lines (all of them when the file has fewer)."""
        out: list[str] = []
        for _k0, lines in self.blocks():
            out += lines[: n - len(out)]
            if len(out) >= n:
                break
        return out

    def line(self, number: int) -> str:
        """Text of the 1-based line ``number`` ("" beyond the end), for messages."""
        for k0, lines in self.blocks():
            if number - 1 < k0 + len(lines):
                return lines[number - 1 - k0]
        return ""


def _is_utf8(raw: bytes, start: int, block: int) -> bool:
    """Whether ``raw[start:]`` is valid UTF-8, checked a block at a time (no full decoded copy)."""
    dec = codecs.getincrementaldecoder("utf-8")()
    try:
        for pos in range(start, len(raw), block):
            dec.decode(raw[pos:pos + block], final=False)
        dec.decode(b"", final=True)
    except UnicodeDecodeError:
        return False
    return True
