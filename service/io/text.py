"""Shared helpers for the text formats: lines with their numbers, numeric blocks, formatting.

Blocks of lines are parsed with one ``b" ".join(lines).split()`` and one numpy conversion
(linear time, no per-line Python parsing). Only when that fails are the lines scanned one by
one, to name the first offending line in the error.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError

__all__ = [
    "LineNumbers",
    "format_rows",
    "header_comments",
    "numeric_block",
    "one_line",
    "shown",
    "split_lines",
    "tokens_per_line",
]

LineNumbers = Sequence[int] | NDArray[np.int64]
"""1-based line numbers of a block of lines (for error messages)."""

_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True  # what bytes.split() splits on


def split_lines(data: bytes) -> list[bytes]:
    """Split on ``\\n`` (a trailing ``\\r`` is whitespace and vanishes on token splitting)."""
    return data.split(b"\n")


def tokens_per_line(joined: bytes, n_lines: int) -> NDArray[np.int64]:
    """Number of whitespace-separated tokens on each line of ``b"\\n".join(lines)`` (vectorized).

    Parameters
    ----------
    joined : bytes
        The lines joined with ``b"\\n"``.
    n_lines : int
        Number of lines joined.
    """
    raw = np.frombuffer(joined, dtype=np.uint8)
    if raw.size == 0:
        return np.zeros(n_lines, dtype=np.int64)
    space = _SPACE[raw]
    start = ~space
    start[1:] &= space[:-1]
    newlines = np.flatnonzero(raw == 10)
    line_of_token = np.searchsorted(newlines, np.flatnonzero(start), side="right")
    return np.bincount(line_of_token, minlength=n_lines).astype(np.int64)


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


def _first_bad_line(
    lines: Sequence[bytes], numbers: LineNumbers, width: int | None, fmt: str, what: str
) -> FormatError:
    for line, number in zip(lines, numbers, strict=True):
        tokens = line.split()
        if width is not None and len(tokens) != width:
            return FormatError(
                f"line {number}: expected {width} values for {what}, found {len(tokens)}",
                fmt=fmt,
                line=number,
            )
        for tok in tokens:
            try:
                float(tok)
            except ValueError:
                return FormatError(
                    f"line {number}: {shown(tok)} is not a number", fmt=fmt, line=number
                )
    return FormatError(f"could not parse the numbers of {what}", fmt=fmt)


def numeric_block(
    lines: Sequence[bytes],
    numbers: LineNumbers,
    width: int | None,
    *,
    fmt: str,
    what: str,
) -> NDArray[np.float64]:
    """Parse lines of whitespace-separated numbers into a float64 array.

    Parameters
    ----------
    lines : sequence of bytes
        The lines (each one record).
    numbers : sequence of int
        1-based line number of each line, for messages.
    width : int or None
        Values per line; ``None`` returns the flat array of all values.
    fmt, what : str
        Format and record name for messages (e.g. ``"ply"``, ``"a vertex"``).

    Raises
    ------
    FormatError
        Naming the first line with the wrong number of values or a non-numeric token.
    """
    tokens = b" ".join(lines).split()
    if width is not None and len(tokens) != width * len(lines):
        raise _first_bad_line(lines, numbers, width, fmt, what)
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise _first_bad_line(lines, numbers, width, fmt, what) from None
    return values.reshape(len(lines), width) if width is not None else values


def format_rows(values: NDArray[np.float64] | NDArray[np.int64], prefix: str = "") -> str:
    """Rows of numbers as text lines, floats in shortest round-trip form (``repr``).

    Every float64 is written with ``repr``, which Python guarantees to read back bit-identical.
    One ``%``-format over the whole table keeps this in C.
    """
    if values.size == 0:
        return ""
    rows, cols = values.shape
    spec = "%r" if values.dtype.kind == "f" else "%d"
    template = prefix + " ".join([spec] * cols) + "\n"
    return (template * rows) % tuple(values.ravel().tolist())
