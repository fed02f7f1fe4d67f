"""OFF (Object File Format): ``[ST][C][N]OFF``, counts, vertex lines, face lines.

Our own reader (trimesh's splits the whole text into Python lists, keeps no line numbers, drops
colours and normals, and takes a face line with the wrong number of indices silently):

* The keyword line says what each vertex line holds after ``x y z``: ``N`` normals, ``C`` a
  colour (3 or 4 values), ``ST`` texture coordinates. Normals become the document's normals
  (recomputed on write), colours and texture coordinates attributes. Every vertex line must have
  the same number of values; ``#`` comments and blank lines are skipped.
* Face lines ``k i1 ... ik [colour]`` are fan-triangulated for the engine; a line with fewer
  than ``k + 1`` values is an error naming it. The face lines are written back as they are.
* Read in bounded blocks; writing keeps the input's digits, header and face section.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.coords import as_xyz
from service.io._shared.numfmt import Digits, write_rows
from service.io._shared.plain import PlainDocument
from service.io._shared.text import LineBlock, flat_numbers, line_blocks, line_number, table_rows
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.source import Source

__all__ = ["OffLayout", "read_off", "write_off"]

_KEYWORD = re.compile(rb"\A(ST)?(C)?(N)?(4)?(n)?OFF\Z")
_COMMENT = re.compile(rb"#[^\n]*")


@dataclass(frozen=True, eq=False)
class OffLayout:
    """The file around its vertex lines: bytes before and after, the vertex column names."""

    before: bytes
    after: bytes
    columns: tuple[str, ...]


def _clean(block: LineBlock) -> LineBlock:
    if b"#" not in block.data:
        return block
    text = _COMMENT.sub(lambda m: b" " * len(m[0]), block.data)
    return LineBlock(text, block.offset, block.rows)


def _next_words(data: bytes, pos: int) -> tuple[list[bytes], int]:
    """Words of the next line that has any (comments removed), and the offset after it."""
    while pos < len(data):
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl + 1
        words = _COMMENT.sub(b"", data[pos:end]).split()
        pos = end
        if words:
            return words, pos
    return [], pos


def _header(data: bytes) -> tuple[bytes, list[int], int]:
    """Keyword, the counts and the offset after the counts line."""
    words, pos = _next_words(data, 0)
    keyword = words[0] if words else b""
    m = _KEYWORD.match(keyword)
    if m is None or m.group(4) or m.group(5):
        raise FormatError(
            f"not an OFF file: the first word is {keyword[:20].decode(errors='replace')!r}"
            " (expected OFF, COFF, NOFF, STOFF, ...; 4OFF and nOFF are not supported)",
            fmt="off",
        )
    tokens = words[1:]
    if not tokens:
        tokens, pos = _next_words(data, pos)
    try:
        counts = [int(t) for t in tokens]
    except ValueError:
        counts = []
    if len(counts) not in (2, 3) or min(counts) < 0:
        raise FormatError("OFF counts line must be 'nvertices nfaces nedges'", fmt="off")
    return keyword, counts, pos


def _columns(keyword: bytes, width: int) -> tuple[str, ...]:
    m = _KEYWORD.match(keyword)
    assert m is not None
    names = ["x", "y", "z"]
    tail = []
    if m.group(3):
        names += ["nx", "ny", "nz"]
    if m.group(1):
        tail = ["u", "v"]
    colour = width - len(names) - len(tail)
    if m.group(2):
        if colour not in (3, 4):
            raise FormatError(
                f"COFF vertex lines need a colour of 3 or 4 values, found {colour}", fmt="off"
            )
        names += ["red", "green", "blue", "alpha"][:colour]
    elif colour:
        names += [f"col{j}" for j in range(len(names), len(names) + colour)]
    return (*names, *tail)


def _vertices(data: bytes, pos: int, n: int) -> tuple[NDArray[np.float64], Digits, int]:
    rows: list[NDArray[np.float64]] = []
    width = digits = None
    got = 0
    for raw in line_blocks(data, pos, n):
        block = _clean(raw)
        if width is None:
            first = block.data.split(b"\n", 1)[0].split() or block.data.split()[:3]
            width = len(first)
            digits = Digits(width)
        rows.append(table_rows(block, data, width, fmt="off", what="a vertex"))
        assert digits is not None
        digits.update(block.data, rows[-1])
        got += len(rows[-1])
        pos = raw.offset + len(raw.data)
    if got < n or digits is None:
        raise FormatError(f"the header declares {n} vertices but the file has {got}", fmt="off")
    return np.concatenate(rows), digits, pos


def _faces(data: bytes, pos: int, m: int, n: int) -> tuple[Any, int]:
    flats, counts_all = [], []
    got = 0
    for raw in line_blocks(data, pos, m):
        block = _clean(raw)
        flat, widths = flat_numbers(block, data, fmt="off", what="a face")
        starts = np.concatenate([[0], np.cumsum(widths)[:-1]])
        k = flat[starts]
        bad = (k != np.round(k)) | (k < 0) | (k + 1 > widths)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            lines = [ln for ln in block.data.split(b"\n")]
            nonblank = [j for j, ln in enumerate(lines) if ln.strip()]
            offset = raw.offset + sum(len(x) + 1 for x in lines[: nonblank[i]])
            line = line_number(data, offset)
            raise FormatError(
                f"line {line}: a face of {int(k[i]) if k[i] >= 0 else k[i]} vertices needs"
                f" {int(max(k[i], 0)) + 1} values or more, found {int(widths[i])}",
                fmt="off",
                line=line,
            )
        k = k.astype(np.int64)
        offs = np.concatenate([[0], np.cumsum(k)[:-1]])
        idx = np.arange(int(k.sum())) + np.repeat(starts + 1 - offs, k)
        flats.append(flat[idx])
        counts_all.append(k)
        got += len(k)
        pos = raw.offset + len(raw.data)
    if got < m:
        raise FormatError(f"the header declares {m} faces but the file has {got}", fmt="off")
    if not flats:
        return None, pos
    flat = np.concatenate(flats)
    if flat.size and (np.any(flat != np.round(flat)) or flat.min() < 0 or flat.max() >= n):
        bad = float(flat[(flat != np.round(flat)) | (flat < 0) | (flat >= n)][0])
        raise FormatError(f"a face refers to vertex {bad:g} but the file has {n}", fmt="off")
    return (flat.astype(np.int64), np.concatenate(counts_all)), pos


def read_off(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read an OFF file (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="off")
    keyword, counts, pos = _header(data)
    n, m = counts[0], counts[1]
    if n == 0:
        raise FormatError("the file holds no points (0 vertices)", fmt="off")
    if 2 * n + 2 * m > len(data):
        raise FormatError(f"OFF counts {n} {m} do not fit a file of {len(data)} bytes", fmt="off")
    table, digits, vend = _vertices(data, pos, n)
    polygons, fend = _faces(data, vend, m, n)
    if data[fend:].strip() and _COMMENT.sub(b"", data[fend:]).strip():
        raise FormatError(
            f"line {line_number(data, fend)}: more lines than the header declares", fmt="off"
        )
    columns = _columns(keyword, table.shape[1])
    specs = digits.specs()
    normals = table[:, 3:6] if columns[3:6] == ("nx", "ny", "nz") else None
    attributes = {c: table[:, j] for j, c in enumerate(columns) if j >= 3 and c[0] != "n"}
    layout = OffLayout(data[:pos], data[vend:], columns)
    precision = Precision("float64", specs[:3], dict(zip(columns, specs, strict=True)))
    doc = assemble(np.ascontiguousarray(table[:, :3]), fmt="off", polygons=polygons, weld=weld)
    return doc.with_extras(
        attributes=attributes, normals=normals, precision=precision, layout=layout
    )


def write_off(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as OFF: the input's header and faces, new vertex lines."""
    pts = as_xyz(plain.points, "off")
    specs = plain.coordinate_specs()
    specs = specs + specs[-1:] if len(specs) == 2 else specs
    cols: list[tuple[NDArray[Any], str]] = [(pts[:, j], specs[j]) for j in range(3)]
    layout = plain.layout if isinstance(plain.layout, OffLayout) else None
    text = plain.source.precision.attribute_text
    normals = plain.normals
    if layout is not None:
        keep_n = normals is not None and "nx" in layout.columns
        head = (
            layout.before
            if keep_n or "nx" not in layout.columns
            else re.sub(rb"\A(\s*(?:#[^\n]*\n\s*)*(?:ST)?C?)N", rb"\1", layout.before)
        )
        out.write(head)
        for j, c in enumerate(layout.columns[3:], start=3):
            if c in ("nx", "ny", "nz"):
                if keep_n:
                    assert normals is not None
                    cols.append((np.asarray(normals[:, j - 3]), text.get(c, "%.6g")))
            else:
                cols.append((plain.attributes[c], plain.attribute_spec(c)))
        write_rows(out, cols, n=plain.n)
        out.write(layout.after)
        return
    faces = plain.faces if plain.faces is not None else np.zeros((0, 3), dtype=np.int64)
    out.write(f"OFF\n{plain.n} {len(faces)} 0\n".encode())
    write_rows(out, cols, n=plain.n)
    if len(faces):
        write_rows(out, [(np.full(len(faces), 3), "%d")] + [(faces[:, j], "%d") for j in range(3)])
