"""ASCII PLY bodies: one element entry per line, parsed in bounded blocks with numpy.

Each element is read block by block (:func:`~service.io._shared.text.line_blocks`). Elements without
list properties are tables of fixed width: a line with another number of values is an error
naming it (never shifted into the next entry). Elements with lists take a fast path when every
line of a block has the layout of its first line, otherwise a vectorized per-line path driven by
each line's token count. Values are stored in the declared types (an integer property must hold
integers), so memory is the input plus the element arrays plus one block.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io._shared.numfmt import Digits
from service.io._shared.text import (
    LineBlock,
    flat_numbers,
    line_blocks,
    line_number,
    table_rows,
    tokens_per_line,
)
from service.io.errors import FormatError
from service.io.formats.ply.header import PlyElement, PlyHeader
from service.io.formats.ply.model import ElementData

__all__ = ["read_ascii_body"]


def _typed(values: NDArray[np.float64], dtype: str, el: PlyElement, name: str) -> NDArray[Any]:
    """Values in the declared type; integers must be integral and in range."""
    dt = np.dtype(dtype)
    if dt.kind in "iu":
        info = np.iinfo(dt)
        bad = (values != np.round(values)) | (values < info.min) | (values > info.max)
        bad |= ~np.isfinite(values)
        if bad.any():
            v = float(values[np.flatnonzero(bad)[0]])
            raise FormatError(
                f"{el.name} property {name!r} is declared {dt.name} but holds {v!r}", fmt="ply"
            )
        return values.astype(dt)
    with np.errstate(over="ignore", invalid="ignore"):
        return values.astype(dt)


def _uniform(
    flat: NDArray[np.float64], counts: NDArray[np.int64], el: PlyElement
) -> list[tuple[int, int]] | None:
    """Column and list length of each property if every line has the first line's layout."""
    if counts.size == 0:
        return None
    pos = 0
    layout: list[tuple[int, int]] = []
    for p in el.properties:
        if pos >= flat.size:
            return None
        if p.is_list:
            k = flat[pos]
            if k < 0 or k != int(k):
                return None
            layout.append((pos, int(k)))
            pos += 1 + int(k)
        else:
            layout.append((pos, -1))
            pos += 1
    if not np.all(counts == pos) or flat.size != pos * counts.size:
        return None
    table = flat.reshape(counts.size, pos)
    for col, k in layout:
        if k >= 0 and not np.all(table[:, col] == k):
            return None
    return layout


def _lists_block(
    block: LineBlock, buf: bytes, el: PlyElement
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.int64]] | NDArray[np.float64]]:
    """One block of an element with list properties: values per property (float64)."""
    flat, widths = flat_numbers(block, buf, fmt="ply", what=f"a {el.name} entry")
    layout = _uniform(flat, widths, el)
    out: dict[str, Any] = {}
    if layout is not None:
        width = int(widths[0])
        table = flat.reshape(widths.size, width)
        for p, (col, k) in zip(el.properties, layout, strict=True):
            if k < 0:
                out[p.name] = table[:, col]
            else:
                items = table[:, col + 1 : col + 1 + k].reshape(-1)
                out[p.name] = (items, np.full(widths.size, k, dtype=np.int64))
        return out
    line_start = np.concatenate([[0], np.cumsum(widths)[:-1]])
    line_end = line_start + widths
    pos = line_start.copy()

    def fail(mask: NDArray[np.bool_], message: str) -> FormatError:
        row = int(np.flatnonzero(mask)[0])
        lines = block.data.split(b"\n")
        nonblank = [i for i, line in enumerate(lines) if line.strip()]
        offset = block.offset + sum(len(x) + 1 for x in lines[: nonblank[row]])
        n = line_number(buf, offset)
        return FormatError(f"line {n}: {message}", fmt="ply", line=n)

    for p in el.properties:
        if np.any(pos >= line_end):
            raise fail(pos >= line_end, f"too few values for {el.name} property {p.name!r}")
        head = flat[pos]
        if not p.is_list:
            out[p.name] = head
            pos = pos + 1
            continue
        bad = (head < 0) | (head != np.round(head))
        if bad.any():
            raise fail(bad, f"bad list length for {el.name} property {p.name!r}")
        k = head.astype(np.int64)
        if np.any(pos + 1 + k > line_end):
            raise fail(pos + 1 + k > line_end, f"the list {p.name!r} is longer than the line")
        total = int(k.sum())
        offsets = np.concatenate([[0], np.cumsum(k)[:-1]])
        idx = np.arange(total, dtype=np.int64) + np.repeat(pos + 1 - offsets, k)
        out[p.name] = (flat[idx], k)
        pos = pos + 1 + k
    if np.any(pos != line_end):
        raise fail(pos != line_end, f"too many values for a {el.name} entry")
    return out


def _ascii_element(
    buf: bytes, pos: int, el: PlyElement, digits: Digits | None
) -> tuple[ElementData, int]:
    """Parse ``el.count`` non-blank lines from ``pos``; return the element and the new pos."""
    props = el.properties
    scalars = not any(p.is_list for p in props)
    cols: dict[str, list[NDArray[Any]]] = {p.name: [] for p in props}
    lens: dict[str, list[NDArray[Any]]] = {p.name: [] for p in props if p.is_list}
    got = 0
    for block in line_blocks(buf, pos, el.count):
        got += block.rows
        pos = block.offset + len(block.data)
        if scalars:
            table = table_rows(block, buf, len(props), fmt="ply", what=f"a {el.name} entry")
            if digits is not None:
                digits.update(block.data, table)
            for i, p in enumerate(props):
                cols[p.name].append(_typed(table[:, i], p.type, el, p.name))
            continue
        parsed = _lists_block(block, buf, el)
        for p in props:
            got_p = parsed[p.name]
            if isinstance(got_p, tuple):
                cols[p.name].append(_typed(got_p[0], p.type, el, p.name))
                counts = got_p[1].astype(np.float64)
                lens[p.name].append(_typed(counts, str(p.count_type), el, p.name))
            else:
                cols[p.name].append(_typed(got_p, p.type, el, p.name))
    if got < el.count:
        raise FormatError(
            f"the header declares {el.count} {el.name} entries but the file ends after {got}"
            " (element counts do not match the data)",
            fmt="ply",
        )
    out: ElementData = {}
    for p in props:
        values = np.concatenate(cols[p.name]) if cols[p.name] else np.zeros(0, p.type)
        if p.is_list:
            counts = np.concatenate(lens[p.name]) if lens[p.name] else np.zeros(0, np.uint8)
            out[p.name] = (values, counts)
        else:
            out[p.name] = values
    return out, pos


def read_ascii_body(
    data: bytes, header: PlyHeader, vertex_digits: Digits | None = None
) -> list[ElementData]:
    """Read every element of an ASCII body, in header order.

    ``vertex_digits`` (optional) measures the digits of the ``vertex`` element's columns.
    """
    pos = header.body_offset
    out: list[ElementData] = []
    measured = False
    for el in header.elements:
        digits = vertex_digits if el.name == "vertex" and not measured else None
        measured = measured or digits is not None
        element, pos = _ascii_element(data, pos, el, digits) if el.count else ({}, pos)
        out.append(element)
    rest = data[pos:]
    if rest.strip():
        offset = pos + (len(rest) - len(rest.lstrip()))
        n = line_number(data, offset)
        extra = int(np.count_nonzero(tokens_per_line(rest, rest.count(b"\n") + 1)))
        raise FormatError(
            f"line {n}: {extra} more lines than the header declares (element counts do not"
            " match the data)",
            fmt="ply",
            line=n,
        )
    return out
