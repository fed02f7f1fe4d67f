"""Text tables read in bounded blocks: lines, their numbers, numeric rows, header comments.

A text body is never split into one Python object per line or per token for the whole file:
:func:`line_blocks` hands out blocks of complete lines (about :data:`BLOCK_BYTES` each), which are
parsed with numpy (``loadtxt``'s C parser for tables of fixed width, one ``split`` per block for
ragged rows). Memory is the input plus the parsed arrays plus ``O(block)``. Line numbers are
computed only when an error needs one (:func:`line_number`), by counting newlines.
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError

__all__ = [
    "BLOCK_BYTES",
    "NUMBER",
    "LineBlock",
    "flat_numbers",
    "header_comments",
    "line_blocks",
    "line_number",
    "one_line",
    "shown",
    "table_rows",
    "tokens_per_line",
]

BLOCK_BYTES = 1 << 20

_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True  # what bytes.split() splits on
NUMBER = re.compile(
    rb"[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf|infinity)",
    re.IGNORECASE,
)


@dataclass(frozen=True)
class LineBlock:
    """Complete lines of a buffer: ``data`` starts at byte ``offset``; ``rows`` non-blank lines
    (``-1``: not counted, when the caller set no row budget)."""

    data: bytes
    offset: int
    rows: int


def line_number(buf: bytes, offset: int) -> int:
    """1-based number of the line holding byte ``offset``."""
    return buf.count(b"\n", 0, offset) + 1


def tokens_per_line(joined: bytes, n_lines: int) -> NDArray[np.int64]:
    """Number of whitespace-separated tokens on each line of ``joined`` (vectorized)."""
    raw = np.frombuffer(joined, dtype=np.uint8)
    if raw.size == 0:
        return np.zeros(n_lines, dtype=np.int64)
    space = _SPACE[raw]
    start = ~space
    start[1:] &= space[:-1]
    ends = np.flatnonzero(raw == 10)
    if ends.size < n_lines:  # the last line has no newline
        ends = np.append(ends, raw.size - 1)
    at = np.cumsum(start, dtype=np.int64)[ends]
    return np.diff(at, prepend=0)


def line_blocks(
    buf: bytes, pos: int, rows: int | None = None, *, end: int | None = None
) -> Iterator[LineBlock]:
    """Blocks of complete lines from ``pos`` until ``rows`` non-blank lines (or the end).

    The caller compares the rows it got with the rows it wanted.
    """
    stop = len(buf) if end is None else end
    left = rows
    while pos < stop and (left is None or left > 0):
        hi = min(pos + BLOCK_BYTES, stop)
        window = buf[pos:hi]
        if hi < stop:
            cut = window.rfind(b"\n")
            if cut < 0:  # one very long line: extend to its end
                nl = buf.find(b"\n", hi, stop)
                hi = stop if nl < 0 else nl + 1
                window = buf[pos:hi]
            else:
                window = window[: cut + 1]
        if left is None:  # no row budget: the parsers count the rows themselves
            yield LineBlock(window, pos, -1)
            pos += len(window)
            continue
        counts = tokens_per_line(window, window.count(b"\n") + 1)
        nonblank = np.flatnonzero(counts > 0)
        if nonblank.size > left:
            last_line = int(nonblank[left - 1])
            cut_at = _nth_newline(window, last_line)
            window = window[: cut_at + 1]
            nonblank = nonblank[:left]
        yield LineBlock(window, pos, int(nonblank.size))
        pos += len(window)
        left -= int(nonblank.size)


def _nth_newline(window: bytes, k: int) -> int:
    """Index of the newline ending line ``k`` (0-based) of ``window`` (its end if none)."""
    nl = np.flatnonzero(np.frombuffer(window, dtype=np.uint8) == 10)
    return int(nl[k]) if k < nl.size else len(window) - 1


def _bad_token_error(
    block: LineBlock, buf: bytes, fmt: str, what: str, width: int | None
) -> FormatError:
    """The first line of ``block`` with a wrong token count or a token that is not a number."""
    offset = block.offset
    for line in block.data.split(b"\n"):
        tokens = line.split()
        if tokens and width is not None and len(tokens) != width:
            n = line_number(buf, offset)
            return FormatError(
                f"line {n}: expected {width} values for {what}, found {len(tokens)}",
                fmt=fmt,
                line=n,
            )
        for tok in tokens:
            if not NUMBER.fullmatch(tok):
                n = line_number(buf, offset)
                return FormatError(f"line {n}: {shown(tok)} is not a number", fmt=fmt, line=n)
        offset += len(line) + 1
    n = line_number(buf, block.offset)
    return FormatError(f"line {n}: could not parse the numbers of {what}", fmt=fmt, line=n)


def table_rows(
    block: LineBlock, buf: bytes, width: int, *, fmt: str, what: str
) -> NDArray[np.float64]:
    """The non-blank lines of ``block`` as a ``(rows, width)`` float64 array.

    Raises
    ------
    FormatError
        Naming the first line with another number of values (never shifted into the next row)
        or a token that is not a number.
    """
    counts = tokens_per_line(block.data, block.data.count(b"\n") + 1)
    if np.any((counts != 0) & (counts != width)):
        raise _bad_token_error(block, buf, fmt, what, width)
    rows = int(np.count_nonzero(counts))
    if rows == 0:
        return np.zeros((0, width))
    try:
        values = np.loadtxt(io.BytesIO(block.data), dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        raise _bad_token_error(block, buf, fmt, what, width) from None
    if values.shape != (rows, width) or b"_" in block.data:
        raise _bad_token_error(block, buf, fmt, what, width)
    return values


def flat_numbers(
    block: LineBlock, buf: bytes, *, fmt: str, what: str
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """All numbers of ``block`` and the token count of each of its non-blank lines."""
    counts = tokens_per_line(block.data, block.data.count(b"\n") + 1)
    counts = counts[counts > 0]
    tokens = block.data.split()
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise _bad_token_error(block, buf, fmt, what, None) from None
    if b"_" in block.data:  # float() takes "1_000"; a file must not
        raise _bad_token_error(block, buf, fmt, what, None)
    return values, counts


WRITTEN_BY = "written by geosmooth"


def header_comments(comments: Sequence[str]) -> list[str]:
    """Comments to write: each on one line, plus ours once (not again on every round trip)."""
    out = [one_line(c) for c in comments]
    return out if WRITTEN_BY in out else [*out, WRITTEN_BY]


def one_line(text: str) -> str:
    """``text`` with line breaks replaced by spaces (for header comments)."""
    return text.replace("\r", " ").replace("\n", " ")


def shown(token: bytes, limit: int = 40) -> str:
    """A token as it should appear in an error message."""
    text = token.decode("utf-8", errors="replace")
    return repr(text if len(text) <= limit else text[:limit] + "...")
