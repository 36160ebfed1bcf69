"""The table machinery the DIC readers share (package-private to :mod:`irdic.io`).

Header parsing and row parsing with line-precise errors (the stage Dataset
they return is built by :mod:`irdic.io._stage`), used by :mod:`~irdic.io.table` (generic CSV), :mod:`~irdic.io.nodemap`,
:mod:`~irdic.io.dice`, :mod:`~irdic.io.vic` and :mod:`~irdic.io.markers`, so
that every DIC reader returns the same structure and reports problems the
same way.

Parsing strategy: the field count of every data line is checked in Python
(cheap: one ``str.count`` per line) because pandas silently pads short rows
with NaN; the numbers themselves are parsed by pandas' C parser. Only when a
column fails to parse as numbers is the offending cell searched for, so that
the error names its line and column.

Memory: :func:`read_body` parses a :class:`~irdic.io._common.TextFile` a
block of lines at a time, so that the file's text is never held as a whole
next to its list of lines and a joined copy; besides the file's bytes only
the parsed numbers are kept.
"""

from __future__ import annotations

import csv
import io
import itertools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np
import pandas as pd

from ..errors import ConfigError, DataError, FormatError
from ._common import TextFile, read_text
from .units import split_unit


# Cell texts that mean "no value" (compared lower-case, stripped).
NA_TOKENS = frozenset(
    {"", "nan", "-nan", "+nan", "na", "n/a", "nan(ind)", "null", "none", "#n/a", "<na>",
     "1.#qnan", "-1.#qnan", "1.#ind", "-1.#ind"}
)


# --------------------------------------------------------------------------- text


def read_lines(path: str | os.PathLike) -> tuple[Path, list[str]]:
    """Decode a text export and split it into lines (CRLF, CR and LF alike).

    Returns
    -------
    path : Path
    lines : list of str
        Without line ends; line ``k`` of the file is ``lines[k - 1]``.

    Raises
    ------
    FormatError
        The file is missing, empty, or binary (contains NUL bytes).
    """
    text = read_text(path)
    p = Path(path)
    if "\x00" in text:
        raise FormatError("contains NUL bytes: this is a binary file, expected a text export", p)
    return p, text.splitlines()


def data_lines(lines: Sequence[str], start: int, comment: str | None = "#") -> tuple[list[str], np.ndarray]:
    """Non-blank, non-comment lines from index ``start`` on, with 1-based line numbers."""
    keep: list[str] = []
    nos: list[int] = []
    for k in range(start, len(lines)):
        s = lines[k].strip()
        if not s or (comment and s.startswith(comment)):
            continue
        keep.append(lines[k])
        nos.append(k + 1)
    return keep, np.asarray(nos, dtype=np.int64)


def detect_decimal(lines: Sequence[str], sep: str | None) -> str:
    """Decimal mark of the data lines: ``","`` when commas outnumber points.

    Only possible when the separator is not a comma itself. Counting over the
    whole sample (rather than looking for any comma) keeps one corrupted cell
    from turning every other cell into an error.
    """
    if sep == ",":
        return "."
    sample = "\n".join(lines[:2000])
    return "," if sample.count(",") > sample.count(".") else "."


def split_fields(line: str, sep: str | None) -> list[str]:
    """Split ``line`` at ``sep`` (``None``: any whitespace), stripping spaces and quotes."""
    if sep is None:
        raw = line.split()
        # keep "x [mm]" together when the header itself is whitespace separated
        merged: list[str] = []
        for tok in raw:
            if merged and tok[:1] in "[(" and tok[-1:] in "])":
                merged[-1] = f"{merged[-1]} {tok}"
            else:
                merged.append(tok)
        raw = merged
    elif '"' in line:
        raw = next(csv.reader([line], delimiter=sep, skipinitialspace=True))
    else:
        raw = line.split(sep)
    fields = [f.strip().strip('"').strip("'").strip() for f in raw]
    # a trailing separator is common in Windows exports
    while fields and fields[-1] == "" and len(fields) > 1:
        fields.pop()
    return fields


# --------------------------------------------------------------------------- header


@dataclass(frozen=True)
class Header:
    """Column names of a table as found in its header line.

    Attributes
    ----------
    names : tuple of str
        Names as written (stripped of spaces and quotes).
    bare : tuple of str
        Names without a trailing unit in brackets.
    units : tuple of (str or None)
        The bracketed units.
    line : int
        1-based line number of the header (0: the file has none).
    path : Path
    """

    names: tuple[str, ...]
    bare: tuple[str, ...]
    units: tuple[str | None, ...]
    line: int
    path: Path

    @classmethod
    def from_fields(cls, fields: Sequence[str], line: int, path: Path) -> "Header":
        split = [split_unit(f) for f in fields]
        return cls(tuple(fields), tuple(b for b, _ in split), tuple(u for _, u in split), line, path)

    def __len__(self) -> int:
        return len(self.names)

    def describe(self) -> str:
        return ", ".join(repr(n) for n in self.names)

    def find(self, name: str, *, case: bool = False) -> int | None:
        """Index of the column whose bare name is ``name``; None when absent.

        Raises
        ------
        FormatError
            The name occurs more than once.
        """
        if case:
            hits = [j for j, b in enumerate(self.bare) if b == name]
        else:
            low = name.lower()
            hits = [j for j, b in enumerate(self.bare) if b.lower() == low]
        if len(hits) > 1:
            raise FormatError(
                f"column {name!r} appears {len(hits)} times in the header (columns {', '.join(str(j + 1) for j in hits)}); "
                "expected each column once",
                self.path, self.line or None,
            )
        return hits[0] if hits else None

    def require(self, names: Sequence[str], *, what: str, case: bool = False) -> list[int]:
        """Indices of ``names``; FormatError listing what is missing, found and expected."""
        idx = [self.find(n, case=case) for n in names]
        missing = [n for n, j in zip(names, idx) if j is None]
        if missing:
            raise FormatError(
                f"missing column{'s' if len(missing) > 1 else ''} {', '.join(repr(m) for m in missing)}; "
                f"found {self.describe()}; {what} needs {', '.join(repr(n) for n in names)}",
                self.path, self.line or None,
            )
        return [int(j) for j in idx]  # type: ignore[arg-type]


# --------------------------------------------------------------------------- rows


class Rows:
    """Parsed data rows of a table, with access to numeric columns by index.

    Use :func:`read_rows` to build one.
    """

    def __init__(self, frame: pd.DataFrame, line_text: Callable[[int], str], line_nos: np.ndarray, header: Header,
                 sep: str | None, decimal: str):
        self.frame = frame
        self._line_text = line_text  # row index -> its line as written; only needed for messages
        self.line_nos = line_nos
        self.header = header
        self.sep = sep
        self.decimal = decimal
        self.path = header.path

    def __len__(self) -> int:
        return len(self.frame)

    def cell(self, i: int, j: int) -> str:
        """Text of cell (row ``i``, column ``j``) as written, for messages."""
        fields = split_fields(self._line_text(i), self.sep)
        return fields[j] if j < len(fields) else ""

    def _expected(self) -> str:
        mark = "decimal comma" if self.decimal == "," else "decimal point"
        return f"a number (with {mark}) or nan"

    def is_numeric(self, j: int) -> bool:
        """Whether pandas parsed column ``j`` as numbers (NaN allowed)."""
        dt = self.frame.iloc[:, j].dtype
        return pd.api.types.is_numeric_dtype(dt) and not pd.api.types.is_bool_dtype(dt)

    def number(self, j: int, *, finite: bool = True) -> np.ndarray:
        """Column ``j`` as float64, NaN for empty/NaN cells, shape ``(n,)``.

        Parameters
        ----------
        j : int
            Column index.
        finite : bool
            Reject infinite values (a coordinate of ``inf`` is a broken file).

        Raises
        ------
        FormatError
            A cell is not a number; the message names line, column and cell.
        """
        col = self.frame.iloc[:, j]
        name = self.header.names[j]
        if self.is_numeric(j):
            values = col.to_numpy(dtype=np.float64, na_value=np.nan)
        else:
            values = self._coerce(col, j, name)
        if finite:
            inf = np.flatnonzero(np.isinf(values))
            if inf.size:
                i = int(inf[0])
                raise FormatError(
                    f"column {name!r}: found {self.cell(i, j)!r}, expected a finite number or nan",
                    self.path, int(self.line_nos[i]),
                )
        return values

    def _coerce(self, col: pd.Series, j: int, name: str) -> np.ndarray:
        # pandas leaves a column as text when one cell is not a number: find that cell
        raw = col.to_numpy(dtype=object)
        present = ~pd.isna(raw)
        text = pd.Series(raw[present], dtype=object).astype(str).str.strip()
        if self.decimal == ",":
            text = text.str.replace(",", ".", regex=False)
        vals = pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        is_na = text.str.lower().isin(NA_TOKENS).to_numpy()
        bad = np.flatnonzero(np.isnan(vals) & ~is_na)
        if bad.size:
            i = int(np.flatnonzero(present)[bad[0]])
            raise FormatError(
                f"column {name!r}: cannot read {self.cell(i, j)!r} as a number; expected {self._expected()}",
                self.path, int(self.line_nos[i]),
            )
        out = np.full(len(raw), np.nan)
        out[present] = vals
        return out

    def integers(self, j: int, *, what: str = "point ID") -> np.ndarray:
        """Column ``j`` as int64 IDs; every cell must hold an integer.

        Raises
        ------
        FormatError
            A cell is empty, not a number or not an integer.
        """
        col = self.frame.iloc[:, j]
        name = self.header.names[j]
        if pd.api.types.is_signed_integer_dtype(col.dtype):
            return col.to_numpy(dtype=np.int64)
        try:
            values = self.number(j, finite=False)
        except FormatError as exc:
            raise FormatError(f"{what}s must be integers; {exc.message}", exc.path, exc.line) from None
        missing = np.flatnonzero(np.isnan(values))
        if missing.size:
            i = int(missing[0])
            raise FormatError(f"column {name!r}: missing {what}; expected an integer", self.path,
                              int(self.line_nos[i]))
        bad = np.flatnonzero((values != np.round(values)) | (np.abs(values) > 2.0**53))
        if bad.size:
            i = int(bad[0])
            raise FormatError(f"column {name!r}: {what} {self.cell(i, j)!r} is not an integer; expected integer {what}s",
                              self.path, int(self.line_nos[i]))
        return values.astype(np.int64)


def _count_fields(lines: list[str], sep: str | None, quoting: int) -> np.ndarray:
    if sep is None:
        return np.fromiter((len(ln.split()) for ln in lines), dtype=np.int64, count=len(lines))
    counts = np.fromiter((ln.count(sep) for ln in lines), dtype=np.int64, count=len(lines)) + 1
    if quoting != csv.QUOTE_NONE:
        # a quoted field may hold the separator: count those lines properly
        for i, ln in enumerate(lines):
            if '"' in ln:
                try:
                    counts[i] = len(next(csv.reader([ln], delimiter=sep)))
                except (csv.Error, StopIteration):
                    pass
    return counts


def read_rows(lines: Sequence[str], line_nos: np.ndarray, header: Header, *, sep: str | None,
              decimal: str = ".", quoting: int = csv.QUOTE_NONE) -> Rows:
    """Parse data lines into a :class:`Rows` table with the header's columns.

    Parameters
    ----------
    lines : sequence of str
        Data lines only (no header, comments or blank lines).
    line_nos : ndarray of int, shape (len(lines),)
        Their 1-based line numbers in the file, for messages.
    header : Header
    sep : str or None
        Field separator; None for runs of whitespace.
    decimal : {".", ","}
    quoting : int
        ``csv.QUOTE_NONE`` (numeric exports: a stray quote is just a bad
        character) or ``csv.QUOTE_MINIMAL`` (generic tables).

    Raises
    ------
    FormatError
        No data rows, or a line with a field count other than the header's.

    See Also
    --------
    read_body : the same from a :class:`~irdic.io._common.TextFile`, a block at a time.
    """
    lines = list(lines)
    line_nos = np.asarray(line_nos, dtype=np.int64)
    step = 20_000
    pieces = ((lines[i:i + step], line_nos[i:i + step]) for i in range(0, len(lines), step))
    frame, nos = _parse_pieces(pieces, header, sep, decimal, quoting)
    return Rows(frame, lines.__getitem__, nos, header, sep, decimal)


def read_body(text: TextFile, start: int, header: Header, *, sep: str | None, decimal: str | None = ".",
              quoting: int = csv.QUOTE_NONE, comment: str | None = "#") -> Rows:
    """Parse the data lines of a file from line index ``start`` on, a block at a time.

    The same as :func:`data_lines` followed by :func:`read_rows`, but the
    file's lines are never all in memory at once: each block of lines
    (:attr:`TextFile.BLOCK` bytes) is filtered, checked and parsed, and only
    the parsed numbers are kept. A cell named in an error message is read
    from the file again.

    Parameters
    ----------
    text : TextFile
    start : int
        0-based index of the first line that may hold data (the line after
        the header).
    header : Header
    sep : str or None
        Field separator; None for runs of whitespace.
    decimal : {".", ",", None}
        Decimal mark; None detects it from the first 2000 data lines (see
        :func:`detect_decimal`).
    quoting : int
        As in :func:`read_rows`.
    comment : str, optional
        Lines starting with it (after blanks) are skipped, as are blank lines.

    Returns
    -------
    Rows
        ``rows.decimal`` is the decimal mark used.

    Raises
    ------
    FormatError
        No data rows, or a line with a field count other than the header's
        (named by line).
    """
    pieces = _data_pieces(text, start, comment)
    if decimal is None:
        # the sample of detect_decimal: the first 2000 data lines
        first: list[tuple[list[str], np.ndarray]] = []
        for piece in pieces:
            first.append(piece)
            if sum(len(lines) for lines, _ in first) >= 2000:
                break
        decimal = detect_decimal([ln for lines, _ in first for ln in lines][:2000], sep)
        pieces = itertools.chain(first, pieces)
    frame, nos = _parse_pieces(pieces, header, sep, decimal, quoting)
    return Rows(frame, lambda i: text.line(int(nos[i])), nos, header, sep, decimal)


def _data_pieces(text: TextFile, start: int, comment: str | None) -> Iterator[tuple[list[str], np.ndarray]]:
    """Per block of the file: its data lines from index ``start`` on and their 1-based line numbers."""
    for k0, lines in text.blocks():
        if k0 + len(lines) <= start:
            continue
        keep, nos = data_lines(lines, max(start - k0, 0), comment)
        if keep:
            yield keep, nos + k0


def _parse_pieces(pieces: Iterable[tuple[list[str], np.ndarray]], header: Header, sep: str | None, decimal: str,
                  quoting: int) -> tuple[pd.DataFrame, np.ndarray]:
    """One DataFrame of all pieces of data lines, and their line numbers."""
    frames, nos = [], []
    for lines, line_nos in pieces:
        frames.append(_parse_piece(lines, line_nos, header, sep, decimal, quoting))
        nos.append(line_nos)
    if not frames:
        where = f" after the header on line {header.line}" if header.line else ""
        raise FormatError(f"no data rows{where}; expected at least one row of numbers", header.path)
    frame = frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True)
    return frame, np.concatenate(nos)


def _parse_piece(lines: list[str], line_nos: np.ndarray, header: Header, sep: str | None, decimal: str,
                 quoting: int) -> pd.DataFrame:
    """Check the field count of every line (``lines`` may be edited: trailing separators) and parse them."""
    path = header.path
    n = len(header)
    counts = _count_fields(lines, sep, quoting)
    for i in np.flatnonzero(counts != n):
        stripped = lines[i].rstrip(" ")
        if sep is not None and counts[i] == n + 1 and stripped.endswith(sep):
            lines[i] = stripped[: -len(sep)]  # trailing separator
            continue
        hdr = f"the header (line {header.line})" if header.line else "the first row"
        raise FormatError(
            f"found {counts[i]} fields, expected {n} like {hdr}: {header.describe()}",
            path, int(line_nos[i]),
        )
    try:
        frame = pd.read_csv(
            io.BytesIO("\n".join(lines).encode("utf-8")), sep=r"\s+" if sep is None else sep, header=None,
            names=list(range(n)), index_col=False, skipinitialspace=True, decimal=decimal,
            quoting=quoting, engine="c", low_memory=False, skip_blank_lines=False,
        )
    except (ValueError, pd.errors.ParserError, csv.Error, OverflowError) as exc:
        raise FormatError(f"cannot parse the data rows ({exc})", path) from exc
    if len(frame) != len(lines):
        raise FormatError(f"parsed {len(frame)} rows from {len(lines)} data lines; check quotes in the file", path)
    return frame


def check_unique(ids: np.ndarray, line_nos: np.ndarray, path: Path, *, what: str = "point ID") -> None:
    """Raise DataError naming both lines when an ID occurs twice."""
    if ids.size < 2:
        return
    order = np.argsort(ids, kind="stable")
    s = ids[order]
    dup = np.flatnonzero(s[1:] == s[:-1])
    if dup.size:
        k = int(dup[np.argmin(order[dup + 1])])  # the first repetition in file order
        a, b = int(line_nos[order[k]]), int(line_nos[order[k + 1]])
        raise DataError(f"{path}: {what} {s[k]} appears twice, on lines {a} and {b}; each {what} must be unique in a file")


# --------------------------------------------------------------------------- user-named columns

_SNIFF_SEPS: tuple[str | None, ...] = ("\t", ";", ",", None)


def match_column(header: Header, name: str) -> int | None:
    """Column index of a user-given name: exact, then without unit, then case-insensitive."""
    name = name.strip().strip('"').strip()
    for keys, want in ((header.names, name), (header.bare, split_unit(name)[0])):
        hits = [j for j, n in enumerate(keys) if n == want]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise FormatError(f"column {want!r} appears {len(hits)} times in the header; expected it once",
                              header.path, header.line or None)
    low = split_unit(name)[0].lower()
    hits = [j for j, n in enumerate(header.bare) if n.lower() == low]
    if len(hits) == 1:
        return hits[0]
    if len(hits) > 1:
        raise FormatError(f"column {name!r} matches several columns ignoring case "
                          f"({', '.join(header.names[j] for j in hits)}); give the exact name",
                          header.path, header.line or None)
    return None


def count_matches(header: Header, names: Sequence[str]) -> int:
    """How many of ``names`` the candidate header has (a repeated name counts; it is reported later)."""
    n = 0
    for nm in names:
        try:
            n += match_column(header, nm) is not None
        except FormatError:
            n += 1
    return n


def find_named_header(lines: Sequence[str], names: Sequence[str], sep: str | None, header_line: int | None,
                      path: Path) -> tuple[int, str | None, Header]:
    """The header line that names all of ``names`` (user-given column names).

    Parameters
    ----------
    lines : sequence of str
        The file's lines.
    names : sequence of str
        Column names as the user wrote them (see :func:`match_column`).
    sep : str or None
        Field separator; None sniffs tab, ``;``, ``,`` and whitespace.
    header_line : int, optional
        1-based line of the header; searched in the first 1000 lines when None.
    path : Path
        Named in messages.

    Returns
    -------
    k : int
        0-based index of the header line.
    sep : str or None
        The separator that splits it.
    header : Header

    Raises
    ------
    ConfigError
        A name is in no candidate header (the message lists the closest
        header's columns), or ``header_line`` is out of range.
    """
    seps = (sep,) if sep is not None else _SNIFF_SEPS
    if header_line is not None:
        if not isinstance(header_line, (int, np.integer)) or isinstance(header_line, bool) \
                or not 1 <= header_line <= len(lines):
            raise ConfigError(f"header_line must be a line number between 1 and {len(lines)} (1-based), "
                              f"got {header_line!r}")
        candidates = [header_line - 1]
    else:
        candidates = range(min(len(lines), 1000))
    best: tuple[int, Header] | None = None  # the line matching most names, for the message
    for k in candidates:
        s = lines[k].strip().lstrip("#").strip()
        if not s:
            continue
        for cand in seps:
            if cand is not None and cand not in s:
                continue
            header = Header.from_fields(split_fields(s, cand), k + 1, path)
            hits = count_matches(header, names)
            if hits == len(names):
                return k, cand, header
            if hits and (best is None or hits > best[0]):
                best = (hits, header)
    if best is None:
        # nothing matched at all: show the first line, split at its likeliest separator
        k = header_line - 1 if header_line is not None else next((i for i, ln in enumerate(lines) if ln.strip()), 0)
        s = lines[k].strip().lstrip("#").strip() if lines else ""
        cand = sep if sep is not None else next((c for c in _SNIFF_SEPS if c is None or c in s), None)
        best = (0, Header.from_fields(split_fields(s, cand), k + 1, path))
    header = best[1]
    missing = [nm for nm in names if count_matches(header, [nm]) == 0]
    where = "the header" if header_line is not None else "the closest header candidate"
    raise ConfigError(f"column(s) {', '.join(map(repr, missing))} given in columns not found in {path}; "
                      f"{where} (line {header.line}) has the columns {header.describe()}")
