"""ASCII PLY bodies: one element entry per line, parsed a block at a time with numpy.

Elements without list properties are one ``numeric_block``. Elements with lists take a fast path
when every line has the layout of the first, otherwise a vectorized per-line path driven by the
token count of each line. Elements nobody needs (e.g. ``range_grid``) are skipped by counting
lines, without parsing. Values are returned as float64; callers cast to the declared types.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.io.errors import FormatError
from service.io.ply_header import PlyElement, PlyHeader
from service.io.ply_types import ElementData
from service.io.text import LineNumbers, numeric_block, tokens_per_line

__all__ = ["read_ascii_body"]


def _ascii_element(lines: list[bytes], numbers: LineNumbers, el: PlyElement) -> ElementData:
    """Parse the lines of one element (one entry per line)."""
    props = el.properties
    what = f"a {el.name} entry"
    if el.count == 0:
        return {}
    if not any(p.is_list for p in props):
        vals = numeric_block(lines, numbers, len(props), fmt="ply", what=what)
        return {p.name: vals[:, i] for i, p in enumerate(props)}
    flat = numeric_block(lines, numbers, None, fmt="ply", what=what)
    out = _ascii_uniform_lists(flat, el)
    if out is None:
        out = _ascii_per_line(lines, numbers, flat, el)
    return out


def _ascii_uniform_lists(flat: NDArray[np.float64], el: PlyElement) -> ElementData | None:
    """Fast path: every line has the layout of the first one. ``None`` if not."""
    pos = 0
    layout: list[tuple[int, int]] = []  # (column, list length or -1 for a scalar)
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
    width = pos
    if flat.size != width * el.count:
        return None
    table = flat.reshape(el.count, width)
    out: ElementData = {}
    for p, (col, k) in zip(el.properties, layout, strict=True):
        if k < 0:
            out[p.name] = table[:, col]
            continue
        if not np.all(table[:, col] == k):
            return None
        items = table[:, col + 1 : col + 1 + k].reshape(-1)
        out[p.name] = (items, np.full(el.count, k, dtype=np.int64))
    return out


def _ascii_per_line(
    lines: list[bytes], numbers: LineNumbers, flat: NDArray[np.float64], el: PlyElement
) -> ElementData:
    """General path: lists of varying length, one entry per line."""
    widths = np.fromiter((len(line.split()) for line in lines), dtype=np.int64, count=len(lines))
    line_start = np.concatenate([[0], np.cumsum(widths)[:-1]])
    cols: dict[str, list[NDArray[np.float64]]] = {}
    pos = line_start.copy()
    for p in el.properties:
        if np.any(pos >= line_start + widths):
            bad = int(np.flatnonzero(pos >= line_start + widths)[0])
            raise FormatError(
                f"line {numbers[bad]}: too few values for {el.name} property {p.name!r}",
                fmt="ply",
                line=numbers[bad],
            )
        head = flat[pos]
        if not p.is_list:
            cols[p.name] = [head]
            pos = pos + 1
            continue
        if np.any((head < 0) | (head != np.round(head))):
            bad = int(np.flatnonzero((head < 0) | (head != np.round(head)))[0])
            raise FormatError(
                f"line {numbers[bad]}: bad list length {float(flat[pos[bad]])!r} for {el.name}",
                fmt="ply",
                line=numbers[bad],
            )
        k = head.astype(np.int64)
        if np.any(pos + 1 + k > line_start + widths):
            bad = int(np.flatnonzero(pos + 1 + k > line_start + widths)[0])
            raise FormatError(
                f"line {numbers[bad]}: the list {p.name!r} announces {int(k[bad])} values but"
                f" the line is shorter",
                fmt="ply",
                line=numbers[bad],
            )
        items = _gather_values(flat, pos + 1, k)
        cols[p.name] = [items, k]
        pos = pos + 1 + k
    extra = pos != line_start + widths
    if np.any(extra):
        bad = int(np.flatnonzero(extra)[0])
        raise FormatError(
            f"line {numbers[bad]}: too many values for a {el.name} entry",
            fmt="ply",
            line=numbers[bad],
        )
    out: ElementData = {}
    for p in el.properties:
        col = cols[p.name]
        out[p.name] = (col[0], col[1].astype(np.int64)) if p.is_list else col[0]
    return out


def _gather_values(
    flat: NDArray[np.float64], starts: NDArray[np.int64], counts: NDArray[np.int64]
) -> NDArray[np.float64]:
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return flat[np.arange(total, dtype=np.int64) + np.repeat(starts - offsets, counts)]


def read_ascii_body(
    data: bytes, header: PlyHeader, notes: list[str], wanted: tuple[str, ...]
) -> dict[str, ElementData]:
    """Read the wanted elements of an ASCII body (one entry per line); note skipped ones."""
    raw = data[header.body_offset :]
    body = raw.split(b"\n")
    keep = np.flatnonzero(tokens_per_line(raw, len(body)) > 0)
    if keep.size == 0 or keep[-1] == keep.size - 1:  # no blank lines except at the end
        lines = body[: keep.size]
    else:
        lines = [body[i] for i in keep.tolist()]
    numbers = keep + (header.n_lines + 1)  # 1-based line numbers
    out: dict[str, ElementData] = {}
    row = 0
    for el in header.elements:
        if row + el.count > len(lines):
            raise FormatError(
                f"the header declares {el.count} {el.name} entries but the file ends after"
                f" {len(lines) - row} (element counts do not match the data)",
                fmt="ply",
            )
        if el.name in wanted and el.name not in out:
            out[el.name] = _ascii_element(
                lines[row : row + el.count], numbers[row : row + el.count], el
            )
        elif el.count:
            notes.append(f"skipped PLY element {el.name!r} ({el.count} entries)")
        row += el.count
    if row < len(lines):
        raise FormatError(
            f"line {numbers[row]}: {len(lines) - row} more lines than the header declares"
            " (element counts do not match the data)",
            fmt="ply",
            line=numbers[row],
        )
    return out
