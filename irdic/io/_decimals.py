"""Vectorised decoder of plain decimal numbers in text (package-private to :mod:`irdic.io`).

The fast path of the IRBIS text reader (:mod:`irdic.io.irbis`): the data
section is cut into blocks of whole lines; in each block every number is
located by its first and last byte, its characters are gathered a position at
a time (counted from its last character) and the digits are summed with their
powers of ten, all in NumPy and in scratch arrays that are reused from block
to block. It gives the correctly rounded value of each decimal number (the
same as :func:`float`). Anything it does not expect makes it return None, and
the caller falls back to a line-by-line parser that names the bad line.
"""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["parse_fast", "decode_block", "Workspace", "WORK", "BLOCK", "POW10"]

POW10 = 10.0 ** np.arange(0, 23)
BLOCK = 1 << 18  # bytes per block of the fast decoder: temporaries stay cache- and allocator-friendly


def parse_fast(data: bytes, sep: bytes, mark: int, newline: int, expected: int | None = None,
               start: int = 0, stop: int | None = None,
               convert: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Vectorised decoder of plain decimal numbers.

    The section is cut into blocks of whole lines (~256 KiB) so that the
    temporaries stay small (repeated large temporaries cost more in page
    faults than in arithmetic). In each block every number is located by its
    first and last byte; its characters, counted from the last one, are
    gathered a row at a time (row ``j`` = ``j``-th character from the end of
    every number) and the digits are summed with their powers of ten in
    float64. The integer sum is exact, so dividing by ``10**decimals`` gives
    the correctly rounded value, the same as :func:`float` on the text.

    Parameters
    ----------
    data : bytes
        The data section, or the whole file with ``start``/``stop`` marking
        the data section (saves a copy of the section).
    sep : bytes
        Separator (one byte).
    mark : int
        Decimal mark byte.
    newline : int
        Line end byte.
    expected : int, optional
        Expected number of values (ImageWidth x ImageHeight).
    start, stop : int, optional
        Byte range of the data section in ``data``.
    convert : (scale, offset), optional
        Return ``float32(value * scale + offset)`` (computed in float64),
        for example (1, -273.15) for kelvin to °C; default: float64 values.

    Returns
    -------
    (values, per_line) or None
        ``values``: float64 (N,) in file order (float32 with ``convert``);
        ``per_line``: number of
        values on each line. None when the section holds anything beyond
        ``[sign] digits [mark digits]`` numbers separated by ``sep``, or more
        numbers than expected (the caller then uses the line-by-line parser,
        which says what is wrong).
    """
    end = len(data) if stop is None else stop
    b_all = np.frombuffer(data, np.uint8)
    size = end - start
    capacity = min(expected, size // 2 + 1) if expected is not None else size // 2 + 1
    values = np.empty(capacity, np.float64 if convert is None else np.float32)
    counts = []
    n_done = 0
    pos = start
    nl = bytes([newline])
    while pos < end:
        cut = data.find(nl, min(pos + BLOCK, end - 1), end)
        cut = end if cut < 0 else cut + 1
        found = decode_block(b_all[pos:cut], sep[0], mark, newline, values, n_done, convert)
        if found is None:
            return None
        n, per_line = found
        counts.append(per_line)
        n_done += n
        pos = cut
    per_line = np.concatenate(counts) if counts else np.zeros(0, np.int64)
    # the last line may lack its line end; every block reported its lines so far
    return values[:n_done], per_line


class Workspace(threading.local):
    """Scratch arrays of the fast decoder, kept per thread and reused.

    Fresh multi-100-kB temporaries for every block would be page-faulted in
    again and again (the allocator hands large blocks back to the system);
    reusing them keeps the decoder at memory speed whatever the allocator's
    state.
    """

    def __init__(self):
        self.arrays: dict = {}

    def get(self, name: str, dtype, n: int) -> np.ndarray:
        a = self.arrays.get(name)
        if a is None or a.size < n:
            a = np.empty(max(n, 2 * (0 if a is None else a.size), 1024), dtype)
            self.arrays[name] = a
        return a[:n]


WORK = Workspace()


def decode_block(b: np.ndarray, sep0: int, mark: int, newline: int, out: np.ndarray,
                 offset: int, convert: tuple[float, float] | None = None) -> tuple[int, np.ndarray] | None:
    """Decode one block of whole lines into ``out[offset:]``; see :func:`parse_fast`.

    Parameters
    ----------
    b : ndarray of uint8, shape (size,)
        The block's bytes.
    sep0, mark, newline : int
        Separator, decimal mark and line end bytes.
    out : ndarray, shape (capacity,)
        Destination of all values of the section.
    offset : int
        Values already decoded (from earlier blocks).
    convert : (scale, offset), optional
        See :func:`parse_fast`.

    Returns
    -------
    (n, per_line) or None
        ``n`` values written to ``out[offset:offset + n]`` and the number of
        values on each line of the block; None when the block holds anything
        the fast decoder does not read (or more values than ``out`` holds).
    """
    ws = WORK
    masks = _classify(b, sep0, mark, ws)
    if masks is None:
        return None
    tmp, delim, digits, n_marks, n_signs = masks
    start, end = _number_bounds(delim, tmp, ws)
    n = start.size
    if n == 0:
        return 0, np.zeros(np.count_nonzero(b == newline) + 1, np.int64)
    if offset + n > out.size:
        return None
    shape = _lengths(start, end, b, n_signs, ws)
    if shape is None:
        return None
    length, signed, width = shape
    k = _common_mark_position(b, end, length, width, mark, n_marks, ws)
    if k is not None:
        if (length - signed).min() < 2:  # a lone mark
            return None
        acc = ws.get("acc", np.float64, n) if convert is not None else out[offset:offset + n]
        _sum_fixed(digits, end, length, width, k, acc, ws)
    else:
        padded, last = _right_aligned(b, end, width, ws)
        acc = out[offset:offset + n] if convert is None else ws.get("acc", np.float64, n)
        acc[:] = 0.0
        if not _sum_general(padded, last, length, signed, width, mark, acc):
            return None
    if n_signs:
        row = ws.get("row", np.uint8, n)
        use = ws.get("use", bool, n)
        np.take(b, start, out=row, mode="clip")
        np.equal(row, ord("-"), out=use)
        np.negative(acc, out=acc, where=use)
    if convert is not None:
        scale, shift = convert
        if scale != 1.0:
            acc *= scale
        if shift != 0.0:
            acc += shift
        out[offset:offset + n] = acc
    return n, _values_per_line(b, newline, end, n, tmp)


#: zero digits in front of every block's digit values, so that the j-th digit
#: from the end of a number can be gathered for all numbers from one shifted
#: view without running off the front (numbers have at most 15 characters)
_PAD = 16


def _classify(b: np.ndarray, sep0: int, mark: int, ws: Workspace):
    """Scratch, delimiter mask, digit values, mark and sign counts of the block; None for a byte or cell not expected.

    Only digits, the mark, signs, the separator and line ends may occur (a
    blank separator also admits TABs), and no cell may be empty. The digit
    values (``byte - '0'``, 0 for every other byte) are returned behind
    :data:`_PAD` zeros.
    """
    size = b.size
    tmp = ws.get("tmp", bool, size)
    delim = ws.get("delim", bool, size)
    np.equal(b, sep0, out=delim)
    for other in ((10, 13, 9) if sep0 == 32 else (10, 13)):
        np.equal(b, other, out=tmp)
        delim |= tmp
    padded = ws.get("digits", np.uint8, size + _PAD)
    padded[:_PAD] = 0
    digits = padded[_PAD:]
    np.subtract(b, np.uint8(48), out=digits)
    ok = ws.get("ok", bool, size)
    np.less(digits, 10, out=ok)
    # every byte is a digit, a delimiter, the mark or a sign: their counts add up to the block's size
    n_digits = int(np.count_nonzero(ok))
    digits *= ok
    n_delim = int(np.count_nonzero(delim))
    n_marks = _count(b, mark, tmp)
    n_signs = _count(b, 45, tmp) + _count(b, 43, tmp)
    if n_digits + n_delim + n_marks + n_signs != size:
        return None
    if sep0 != 32:
        # an empty cell (a separator after a separator or at a line start) would shift the row silently
        if b[0] == sep0:
            return None
        t = tmp[:size - 1]
        np.equal(b[1:], sep0, out=t)
        t &= delim[:size - 1]
        if t.any():
            return None
    return tmp, delim, padded, n_marks, n_signs


def _count(b: np.ndarray, byte: int, tmp: np.ndarray) -> int:
    np.equal(b, byte, out=tmp)
    return int(np.count_nonzero(tmp))


def _number_bounds(delim: np.ndarray, tmp: np.ndarray, ws: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the first and the last byte of every number in the block."""
    size = delim.size
    inside = ws.get("inside", bool, size + 2)
    inside[0] = inside[-1] = False
    np.logical_not(delim, out=inside[1:-1])
    np.greater(inside[1:-1], inside[:-2], out=tmp)
    # (np.compress into a kept buffer would avoid these two allocations but is 4x slower)
    start = np.flatnonzero(tmp)
    np.greater(inside[1:-1], inside[2:], out=tmp)
    return start, np.flatnonzero(tmp)


def _lengths(start: np.ndarray, end: np.ndarray, b: np.ndarray, n_signs: int, ws: Workspace):
    """(length, signed, width) of the numbers; None unless the decoder can sum them exactly.

    A sign may only lead a number and must have something after it, and a
    number has at most 15 characters, so that its digit sum is an integer
    that float64 holds exactly. ``signed`` is 0 or a bool array.
    """
    n = start.size
    length = ws.get("length", np.intp, n)
    np.subtract(end, start, out=length)
    length += 1
    width = int(length.max())
    if width >= _PAD:
        return None
    if not n_signs:
        return length, 0, width
    row = ws.get("row", np.uint8, n)
    signed = ws.get("signed", bool, n)
    np.take(b, start, out=row, mode="clip")
    np.equal(row, 45, out=signed)
    use = ws.get("use", bool, n)
    np.equal(row, 43, out=use)
    signed |= use
    if int(np.count_nonzero(signed)) != n_signs or (length[signed] < 2).any():
        return None
    return length, signed, width


def _right_aligned(b: np.ndarray, end: np.ndarray, width: int, ws: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """The block behind ``width`` blanks, and each number's last byte in it.

    The padding lets the ``j``-th character from the end be gathered for all
    numbers at once without running off the front of the block.
    """
    size = b.size
    padded = ws.get("padded", np.uint8, size + width)
    padded[:width] = ord(" ")
    padded[width:] = b
    last = ws.get("last", np.intp, end.size)
    np.add(end, width, out=last)
    return padded, last


def _common_mark_position(b: np.ndarray, end: np.ndarray, length: np.ndarray, width: int, mark: int,
                          n_marks: int, ws: Workspace) -> int | None:
    """Position ``k`` of the decimal mark, counted from the end, when every number has it there; else None.

    Every number is longer than ``k`` and the block holds as many marks as
    numbers, so each number holds exactly one mark, at ``k``.
    """
    n = end.size
    if n_marks != n:
        return None
    first = b[end[0] - np.arange(min(width, int(length[0])))]
    hits = np.flatnonzero(first == mark)
    if hits.size != 1:
        return None
    k = int(hits[0])
    if int(length.min()) <= k:
        return None
    row = ws.get("row", np.uint8, n)
    idx = ws.get("idx", np.intp, n)
    np.subtract(end, k, out=idx)
    np.take(b, idx, out=row, mode="clip")
    return k if (row == mark).all() else None


def _sum_fixed(digits: np.ndarray, end: np.ndarray, length: np.ndarray, width: int, k: int, acc: np.ndarray,
               ws: Workspace) -> None:
    """Values of numbers that all have ``k`` decimals (the usual export), into ``acc``.

    ``digits`` holds the digit values of the block behind :data:`_PAD`
    zeros. The digits are summed as an integer (int32 when it fits, else
    int64; exact either way), which is divided by ``10**k`` once.
    """
    n = end.size
    size = digits.size - _PAD
    itype = np.int32 if width <= 10 else np.int64
    total = ws.get("total" + np.dtype(itype).char, itype, n)
    term = ws.get("term" + np.dtype(itype).char, itype, n)
    row = ws.get("row", np.uint8, n)
    use = ws.get("use", bool, n)
    # the byte just before a number is a delimiter, a sign or padding (digit value 0); only bytes further
    # back belong to the previous number and must be masked out
    unmasked = int(length.min()) + 1
    total[:] = 0
    for j in range(width):
        if j == k:
            continue
        np.take(digits[_PAD - j:_PAD - j + size], end, out=row, mode="clip")
        if j >= unmasked:
            np.greater(length, j, out=use)
            row *= use
        np.multiply(row, itype(POW10[j - (j > k)]), out=term)
        total += term
    np.divide(total, POW10[k], out=acc)


def _sum_general(padded: np.ndarray, last: np.ndarray, length: np.ndarray, signed: np.ndarray, width: int,
                 mark: int, acc: np.ndarray) -> bool:
    """Values of numbers with any number of decimals (or none), into ``acc``; False for a malformed number."""
    n = last.size
    rows = [padded.take(last - j) for j in range(width)]
    n_mark = np.zeros(n, np.int64)
    kk = np.full(n, width + 1)
    for j, r in enumerate(rows):
        m = (r == mark) & (length > j)
        n_mark += m
        kk[m] = j
    if n_mark.max() > 1 or (length - signed - n_mark).min() < 1:
        return False
    for j, r in enumerate(rows):
        dj = r - np.uint8(48)
        ok_j = (dj < 10) & (length > j)
        dj[~ok_j] = 0
        acc += dj * POW10[j - (j > kk)]
    acc /= POW10[np.where(n_mark == 1, kk, 0)]
    return True


def _values_per_line(b: np.ndarray, newline: int, end: np.ndarray, n: int, tmp: np.ndarray) -> np.ndarray:
    """Number of values on each line of the block.

    The part after the block's last line end is one more (possibly empty)
    line unless the block ends with a line end.
    """
    np.equal(b, newline, out=tmp)
    ends_of_lines = np.flatnonzero(tmp)
    before = np.searchsorted(end, ends_of_lines)
    per_line = np.diff(np.concatenate(([0], before, [n])))
    if ends_of_lines.size and ends_of_lines[-1] == b.size - 1:
        per_line = per_line[:-1]
    return per_line
