"""XYZ point lists: one point per line, numbers separated by whitespace or commas.

Reading
-------
* Every data line must have the same number of columns, at least 2.
* Coordinates: with 2 columns the points are 2D (``x y``); with 3 or more columns the first three
  are ``x y z`` and the remaining columns (colours, normals, intensity, ...) are **ignored on
  read and not written back**. ``read_geometry(..., xyz_dims=d)`` takes the first ``d`` columns
  instead (e.g. to smooth 5-dimensional data stored as XYZ).
* Blank lines and lines starting with ``#`` are skipped (leading ones are kept as comments). A
  first data line with no numbers at all (e.g. ``x,y,z``) is taken as a column header, skipped
  and noted; any other non-numeric token is an error naming the line.
* XYZ holds no connectivity: the result is a point cloud.

Writing
-------
One line per point, all ``s`` coordinates separated by single spaces, every float64 in shortest
round-trip form (``repr``), no header or comments. Faces, edges and polylines cannot be stored
in XYZ and are not written. 1D points cannot be written (XYZ needs at least 2 columns).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.io.assemble import assemble
from service.io.document import GeometryDocument
from service.io.errors import FormatError
from service.io.text import format_rows, numeric_block, tokens_per_line

__all__ = ["read_xyz", "write_xyz"]


def _is_number(token: bytes) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _lines_with_comments(raw: list[bytes], comments: list[str]) -> tuple[list[bytes], list[int]]:
    """Data lines and their numbers; ``#`` lines before the first data line go to comments."""
    lines: list[bytes] = []
    numbers: list[int] = []
    for number, line in enumerate(raw, start=1):
        s = line.strip()
        if not s:
            continue
        if s[:1] == b"#":
            if not lines:
                comments.append(s[1:].strip().decode("utf-8", errors="replace"))
            continue
        lines.append(line)
        numbers.append(number)
    return lines, numbers


def read_xyz(data: bytes, *, weld: bool = False, xyz_dims: int | None = None) -> GeometryDocument:
    """Read an XYZ point list from bytes.

    Parameters
    ----------
    data : bytes
        File content.
    weld : bool
        Merge exactly coincident points (see :mod:`service.io.weld`).
    xyz_dims : int, optional
        Number of leading columns that are coordinates (default: 2 for 2 columns, else 3).

    Raises
    ------
    FormatError
        Empty file, fewer than 2 columns, rows of different lengths, non-numeric tokens (with
        the line number), ``xyz_dims`` larger than the number of columns.
    """
    text = data.replace(b",", b" ")
    raw = text.split(b"\n")
    comments: list[str] = []
    notes: list[str] = []
    if b"#" in text:
        lines, numbers = _lines_with_comments(raw, comments)
    else:
        keep = np.flatnonzero(tokens_per_line(text, len(raw)) > 0)
        if keep.size == 0 or keep[-1] == keep.size - 1:  # no blank lines except at the end
            lines = raw[: keep.size]
        else:
            lines = [raw[i] for i in keep.tolist()]
        numbers = (keep + 1).tolist()
    if not lines:
        raise FormatError("the file holds no points", fmt="xyz")
    first = lines[0].split()
    if not any(_is_number(t) for t in first):
        notes.append(
            f"skipped header line {numbers[0]}: {b' '.join(first).decode(errors='replace')!r}"
        )
        lines, numbers = lines[1:], numbers[1:]
        if not lines:
            raise FormatError("the file holds no points (only a header line)", fmt="xyz")
        first = lines[0].split()
    width = len(first)
    if width < 2:
        raise FormatError(
            f"line {numbers[0]}: XYZ needs at least 2 columns per line, found {width}",
            fmt="xyz",
            line=numbers[0],
        )
    table = numeric_block(lines, numbers, width, fmt="xyz", what="a point")
    dims = xyz_dims if xyz_dims is not None else (2 if width == 2 else 3)
    if not 1 <= dims <= width:
        raise FormatError(f"xyz_dims={dims} but the file has {width} columns per line", fmt="xyz")
    if dims < width:
        notes.append(f"ignored {width - dims} extra columns per line (coordinates: first {dims})")
    points = np.ascontiguousarray(table[:, :dims])
    return assemble(points, fmt="xyz", notes=notes, comments=comments, weld=weld)


def write_xyz(doc: GeometryDocument, points: NDArray[np.float64] | None = None) -> bytes:
    """Write the document's points as XYZ text (connectivity is not representable)."""
    pts = doc.output_points(points)
    if pts.shape[1] < 2:
        raise FormatError(
            "XYZ needs at least 2 coordinates per point; write 1D points as JSON instead",
            fmt="xyz",
        )
    return format_rows(pts).encode("ascii")
