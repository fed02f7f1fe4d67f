"""XYZ point lists: one point per line, numbers separated by whitespace or commas.

Reading
-------
* Every data line must have the same number of columns (at least 2); a line with another count
  is an error naming it (never shifted into the next point).
* Coordinates: with 2 columns the points are 2D; with 3 or more the first three are ``x y z``
  (``xyz_dims=d``: the first ``d``). The other columns are attributes, written back unchanged:
  named by a header line when there is one (``x,y,z,red,green,blue``), else three unit-vector
  columns are normals (``nx ny nz``, recomputed on write), three or four integer columns in
  ``0..255`` are ``red green blue [alpha]``, others ``col3``, ``col4``, ...
* Blank lines and ``#`` lines are skipped (leading ones are the comments). A first data line
  with no numbers is a header line.
* Read in bounded blocks; digits are measured per column (see :mod:`.numfmt`).

Writing
-------
The input's columns in the input's order, separator and digits (a header line too, if it had
one); other documents: coordinates, normals, then attributes. Connectivity cannot be stored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble, require_points
from service.io._shared.numfmt import Digits, default_spec, write_rows
from service.io._shared.plain import PlainDocument
from service.io._shared.text import LineBlock, line_blocks, table_rows
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.limits import check_points
from service.io.source import Source

__all__ = ["XyzLayout", "columns", "read_coordinates", "read_xyz", "write_xyz"]

_COMMENT = re.compile(rb"(?m)^[ \t]*#[^\n]*")
NORMALS = ("nx", "ny", "nz")


@dataclass(frozen=True, eq=False)
class XyzLayout:
    """Column names in file order, separator, header line."""

    names: tuple[str, ...]
    separator: str
    header: str | None


def _is_number(token: bytes) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _start(data: Any) -> tuple[int, list[str], list[bytes] | None, int, str | None]:
    """First data line's offset, leading comments, header words, line number, header text."""
    comments: list[str] = []
    pos = 0
    line_no = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl + 1
        line_no += 1
        text = data[pos:end].strip()
        if text.startswith(b"#"):
            comments.append(text[1:].strip().decode("utf-8", errors="replace"))
        elif text:
            words = text.replace(b",", b" ").split()
            if not any(_is_number(w) for w in words):
                return end, comments, words, line_no, text.decode("utf-8", errors="replace")
            return pos, comments, None, line_no, None
        pos = end
    return pos, comments, None, line_no, None


def _names(table: NDArray[np.float64], dims: int, header: list[bytes] | None) -> tuple[str, ...]:
    width = table.shape[1]
    if header is not None and len(header) == width:
        return tuple(w.decode("utf-8", errors="replace") for w in header)
    base = ("x", "y", "z")[:dims] if dims <= 3 else tuple(f"c{j}" for j in range(dims))
    extra = table[:, dims:]
    k = extra.shape[1]
    if dims == 3 and k == 3 and len(extra):
        norm = np.linalg.norm(extra, axis=1)
        if np.mean(np.abs(norm - 1) < 1e-3) >= 0.99:
            return (*base, *NORMALS)
    integral = len(extra) and np.all((extra == np.round(extra)) & (extra >= 0))
    if k in (3, 4) and integral and extra.max() <= 255:
        return (*base, *("red", "green", "blue", "alpha")[:k])
    return (*base, *(f"col{j}" for j in range(dims, width)))


def _table(
    data: Any, pos: int, width: int, digits: Digits | None, keep: int | None = None, held: int = 0
) -> NDArray[np.float64]:
    """The rows from ``pos`` (the first ``keep`` columns), checked against the reader limits
    first (``held``: bytes of the file held in memory besides the table)."""
    lines = data.count(b"\n", pos) + 1
    cols = width if keep is None else keep
    check_points(lines, (held + 16 * cols * lines) / lines, "xyz", "lines")
    out = np.empty((lines, cols))
    n = 0
    for block in line_blocks(data, pos):
        text = block.data
        if b"," in text:
            text = text.replace(b",", b" ")
        if b"#" in text:
            text = _COMMENT.sub(lambda m: b" " * len(m[0]), text)
        clean = LineBlock(text, block.offset, block.rows)
        rows = table_rows(clean, data, width, fmt="xyz", what="a point")
        out[n : n + len(rows)] = rows[:, :cols]
        n += len(rows)
        if digits is not None:
            digits.update(text, rows)
    return out[:n]


def _width(data: Any, pos: int, line_no: int) -> tuple[bytes, int]:
    """The first data line and its number of columns (at least 2)."""
    nl = data.find(b"\n", pos)
    first = bytes(data[pos : nl if nl >= 0 else len(data)])
    width = len(first.replace(b",", b" ").split())
    if width == 0:
        raise FormatError("the file holds no points", fmt="xyz")
    if width < 2:
        raise FormatError(
            f"line {line_no}: XYZ needs at least 2 columns per line, found {width}",
            fmt="xyz",
            line=line_no,
        )
    return first, width


def columns(data: Any) -> int:
    """Columns of the first data line of ``data`` (0: none found)."""
    pos, _, _, line_no, _ = _start(data)
    try:
        return _width(data, pos, line_no)[1]
    except FormatError:
        return 0


def read_coordinates(data: Any) -> NDArray[np.float64]:
    """The ``x y z`` columns of an XYZ file of 3 or more columns (``data``: bytes or a mapped
    file), checked exactly as :func:`read_xyz` checks it; the streamed reader's
    (:mod:`service.io.stream`)."""
    pos, _, _, line_no, _ = _start(data)
    _, width = _width(data, pos, line_no)
    if width < 3:
        raise FormatError(f"line {line_no}: expected 3 columns, found {width}", fmt="xyz")
    points = _table(data, pos, width, None, keep=3)
    require_points(points, "xyz")
    return points


def read_xyz(
    source: Source, *, weld: bool = False, xyz_dims: int | None = None
) -> GeometryDocument:
    """Read an XYZ point list.

    Raises
    ------
    FormatError
        Empty file, fewer than 2 columns, rows of different lengths, non-numeric tokens (with
        the line number), ``xyz_dims`` larger than the number of columns.
    """
    data = source.data()
    pos, comments, header, line_no, header_text = _start(data)
    notes = []
    if header is not None:
        notes.append(f"read header line {line_no}: {header_text!r}")
    first, width = _width(data, pos, line_no)
    digits = Digits(width)
    table = _table(data, pos, width, digits, held=len(data))
    dims = xyz_dims if xyz_dims is not None else (2 if width == 2 else 3)
    if not 1 <= dims <= width:
        raise FormatError(f"xyz_dims={dims} but the file has {width} columns per line", fmt="xyz")
    names = _names(table, dims, header)
    specs = digits.specs()
    normals = None
    attributes: dict[str, NDArray[Any]] = {}
    for j in range(dims, width):
        attributes[names[j]] = table[:, j]
    if names[dims : dims + 3] == NORMALS:
        normals = table[:, dims : dims + 3]
        for c in NORMALS:
            attributes.pop(c)
    if width > dims:
        notes.append(f"kept {width - dims} extra columns per line: {', '.join(names[dims:])}")
    sep = "," if b"," in first else " "
    layout = XyzLayout(names, sep, header_text)
    precision = Precision("float64", specs[:dims], {names[j]: specs[j] for j in range(dims, width)})
    doc = assemble(
        np.ascontiguousarray(table[:, :dims]), fmt="xyz", notes=notes, comments=comments, weld=weld
    )
    return doc.with_extras(
        attributes=attributes, normals=normals, precision=precision, layout=layout
    )


def write_xyz(plain: PlainDocument, out: BinaryIO) -> None:
    """Write the points (and their attributes) as XYZ text; connectivity is not representable."""
    if plain.dim < 2:
        raise FormatError(
            "XYZ needs at least 2 coordinates per point; write 1D points as JSON instead",
            fmt="xyz",
        )
    layout = plain.layout if isinstance(plain.layout, XyzLayout) else None
    specs = plain.coordinate_specs()
    cols: list[tuple[NDArray[Any], str]] = [
        (plain.points[:, j], specs[j]) for j in range(plain.dim)
    ]
    text = plain.source.precision.attribute_text
    normal_cols = []
    if plain.normals is not None:
        normal_cols = [
            (np.asarray(plain.normals[:, j]), text.get(c, default_spec(plain.normals.dtype)))
            for j, c in enumerate(NORMALS)
        ]
    attr_cols: dict[str, tuple[NDArray[Any], str]] = {}
    for name, values in plain.attributes.items():
        if values.ndim == 1:
            attr_cols[name] = (values, plain.attribute_spec(name))
        else:
            for j in range(values.shape[1]):
                attr_cols[f"{name}_{j}"] = (values[:, j], plain.attribute_spec(name))
    sep = " "
    if layout is not None and layout.names[: plain.dim] and len(layout.names) >= plain.dim:
        sep = layout.separator
        if layout.header is not None:
            out.write((layout.header + "\n").encode("utf-8"))
        for name in layout.names[plain.dim :]:
            if name in NORMALS:
                cols.extend(normal_cols[NORMALS.index(name) : NORMALS.index(name) + 1])
            elif name in attr_cols:
                cols.append(attr_cols.pop(name))
    else:
        cols.extend(normal_cols)
    cols.extend(attr_cols.values())
    write_rows(out, cols, sep=sep, n=plain.n)
