"""STL, binary and ASCII: a triangle soup, welded on read by default, written back per face.

Reading
-------
* Binary: the 80-byte header, the triangle count (which must match the file size), then 50-byte
  records (normal, three float32 vertices, a uint16 attribute), read as one numpy view. Our own
  reader: it keeps the header and the attribute bytes (trimesh keeps the latter too, but not the
  header verbatim) and needs no copy; the benchmark compares it with trimesh's.
* ASCII: ``solid NAME`` / ``facet normal`` / ``outer loop`` / three ``vertex x y z`` /
  ``endloop`` / ``endfacet`` / ``endsolid``, several solids allowed; a facet with another number
  of vertices, or a line out of place, is an error naming the line. Read in bounded blocks
  (trimesh's ASCII reader lower-cases and splits the whole text, keeps no line numbers and takes
  polygons silently).
* Every facet gives three vertices (the soup); ``weld`` (default on) merges coincident ones.

Writing
-------
Per face, in the input's encoding (binary for other inputs), the input's header, solid names
and attribute bytes; coordinates in float32 (binary; ``precision`` as usual for ASCII); facet
normals recomputed from the written triangle (``normals="drop"``: zero normals, which STL
readers accept). Geometry without triangles cannot be written as STL.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble
from service.io._shared.coords import as_xyz
from service.io._shared.normals import unit_rows
from service.io._shared.numfmt import Digits, format_column
from service.io._shared.plain import PlainDocument
from service.io._shared.text import WRITTEN_BY, line_blocks
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.limits import check_points
from service.io.source import Source

__all__ = ["StlLayout", "read_stl", "write_stl"]

RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


@dataclass(frozen=True, eq=False)
class StlLayout:
    """What an STL file has besides its triangles.

    Attributes
    ----------
    ascii : bool
        Encoding of the input.
    header : bytes
        Binary: the 80-byte header.
    attributes : ndarray of uint16 or None
        Binary: the attribute word of each facet.
    normals : ndarray, shape (m, 3)
        The facet normals as read.
    solids : list of (str, int)
        ASCII: each solid's name and number of facets.
    """

    ascii: bool
    header: bytes
    attributes: NDArray[np.uint16] | None
    normals: NDArray[Any]
    solids: list[tuple[str, int]]


def _binary(data: bytes) -> tuple[NDArray[np.float64], StlLayout, Precision]:
    if len(data) < 84:
        raise FormatError("binary STL shorter than its 84-byte header", fmt="stl")
    count = int.from_bytes(data[80:84], "little")
    if 84 + 50 * count != len(data):
        raise FormatError(
            f"binary STL declares {count} triangles ({84 + 50 * count} bytes) but the file has"
            f" {len(data)} bytes",
            fmt="stl",
        )
    if count == 0:
        raise FormatError("the file holds no triangles", fmt="stl")
    check_points(3 * count, 24 + 24, "stl", "triangle corners")  # + welding's sort keys
    rec = np.frombuffer(data, dtype=RECORD, count=count, offset=84)
    points = rec["v"].reshape(-1, 3).astype(np.float64)
    layout = StlLayout(False, data[:80], rec["attr"], rec["normal"], [])
    return points, layout, Precision("float32")


def _ascii(data: bytes) -> tuple[NDArray[np.float64], StlLayout, Precision]:
    vertex_text: list[bytes] = []
    normal_text: list[bytes] = []
    solids: list[tuple[str, int]] = []
    state = "solid"
    in_facet = 0
    line = 1
    for block in line_blocks(data, 0):
        for raw in block.data.split(b"\n"):
            words = raw.split()
            if words:
                key = words[0].lower()
                state, in_facet = _step(key, words, raw, state, in_facet, line, solids)
                if key == b"vertex":
                    vertex_text.append(raw.lstrip()[6:])
                elif key == b"facet":
                    normal_text.append(b" ".join(words[2:5]))
            line += 1
        line -= 1  # the block's last split piece is the start of the next line
    if state != "solid" or not solids:
        raise FormatError("ASCII STL ends inside a solid (no 'endsolid')", fmt="stl")
    if not vertex_text:
        raise FormatError("the file holds no triangles", fmt="stl")
    joined = b"\n".join(vertex_text)
    try:
        points = np.array(joined.split(), dtype=np.float64).reshape(-1, 3)
        normals = np.array(b" ".join(normal_text).split(), dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise FormatError("ASCII STL: a vertex or normal is not three numbers", fmt="stl") from None
    digits = Digits(3)
    digits.update(joined, points)
    layout = StlLayout(True, b"", None, normals, solids)
    return points, layout, Precision("float64", digits.specs())


def _step(
    key: bytes,
    words: list[bytes],
    raw: bytes,
    state: str,
    in_facet: int,
    line: int,
    solids: list[tuple[str, int]],
) -> tuple[str, int]:
    """One line of the ASCII grammar; raises FormatError naming the line when out of place."""
    expected = {
        "solid": (b"solid",),
        "facet": (b"facet", b"endsolid"),
        "loop": (b"outer",),
        "vertex": (b"vertex", b"endloop"),
        "endfacet": (b"endfacet",),
    }[state]
    if key not in expected:
        raise FormatError(
            f"line {line}: expected {' or '.join(e.decode() for e in expected)}, found"
            f" {words[0][:20].decode(errors='replace')!r}",
            fmt="stl",
            line=line,
        )
    if key == b"solid":
        solids.append((raw.strip()[5:].strip().decode("utf-8", errors="replace"), 0))
        return "facet", 0
    if key == b"endsolid":
        return "solid", 0
    if key == b"facet":
        if len(words) != 5 or words[1].lower() != b"normal":
            raise FormatError(
                f"line {line}: expected 'facet normal nx ny nz'", fmt="stl", line=line
            )
        return "loop", 0
    if key == b"outer":
        return "vertex", 0
    if key == b"vertex":
        if len(words) != 4:
            raise FormatError(f"line {line}: a vertex needs 3 coordinates", fmt="stl", line=line)
        return "vertex", in_facet + 1
    if key == b"endloop":
        if in_facet != 3:
            raise FormatError(
                f"line {line}: a facet has {in_facet} vertices; STL facets are triangles",
                fmt="stl",
                line=line,
            )
        name, k = solids[-1]
        solids[-1] = (name, k + 1)
        return "endfacet", 0
    return "facet", 0  # endfacet


def read_stl(source: Source, *, weld: bool = True) -> GeometryDocument:
    """Read a binary or ASCII STL file (see the module docstring)."""
    data = source.data()
    if not data.strip():
        raise FormatError("the file is empty", fmt="stl")
    binary = len(data) >= 84 and 84 + 50 * int.from_bytes(data[80:84], "little") == len(data)
    if not binary and data.lstrip()[:5].lower() != b"solid":
        return _binary_or_fail(data)
    points, layout, precision = _binary(data) if binary else _ascii(data)
    m = len(points) // 3
    faces = np.arange(3 * m, dtype=np.int64).reshape(m, 3)
    comments = [] if layout.ascii else [layout.header.rstrip(b"\x00 ").decode("ascii", "replace")]
    doc = assemble(
        points,
        fmt="stl",
        polygons=(faces.reshape(-1), np.full(m, 3)),
        weld=weld,
        comments=[c for c in comments if c],
    )
    return doc.with_extras(precision=precision, layout=layout)


def _binary_or_fail(data: bytes) -> GeometryDocument:
    _binary(data)  # raises the size mismatch
    raise AssertionError("unreachable")  # pragma: no cover


def _face_normals(plain: PlainDocument, tris: NDArray[np.float64], layout: StlLayout | None) -> Any:
    if plain.options.normals == "drop":
        return np.zeros((len(tris), 3))
    if not plain.moved and layout is not None and len(layout.normals) == len(tris):
        return layout.normals
    return unit_rows(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]))[0]


def write_stl(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as STL (see the module docstring)."""
    if plain.faces is None or not len(plain.faces):
        raise FormatError("STL holds triangles; this geometry has none", fmt="stl")
    layout = plain.layout if isinstance(plain.layout, StlLayout) else None
    tris = as_xyz(plain.points, "stl")[plain.faces]
    normals = _face_normals(plain, tris, layout)
    if layout is not None and layout.ascii:
        _write_ascii(plain, tris, normals, layout, out)
        return
    rec = np.zeros(len(tris), dtype=RECORD)
    rec["v"] = tris
    rec["normal"] = normals
    if layout is not None and layout.attributes is not None and len(layout.attributes) == len(rec):
        rec["attr"] = layout.attributes
        header = layout.header
    else:
        header = WRITTEN_BY.encode().ljust(80, b" ")
    out.write(header[:80].ljust(80, b"\0") + np.uint32(len(rec)).tobytes())
    out.write(rec.tobytes())


def _write_ascii(
    plain: PlainDocument,
    tris: NDArray[np.float64],
    normals: Any,
    layout: StlLayout,
    out: BinaryIO,
) -> None:
    specs = plain.coordinate_specs()
    solids = layout.solids if sum(k for _, k in layout.solids) == len(tris) else [("", len(tris))]
    at = 0
    for name, k in solids:
        out.write(f"solid {name}\n".encode())
        part = tris[at : at + k]
        cols = [format_column(part[:, :, j].reshape(-1), specs[j]) for j in range(3)]
        ncols = [format_column(np.asarray(normals[at : at + k, j]), "%.6g") for j in range(3)]
        lines = []
        for f in range(k):
            lines.append(f"facet normal {ncols[0][f]} {ncols[1][f]} {ncols[2][f]}\n outer loop")
            for c in range(3 * f, 3 * f + 3):
                lines.append(f"  vertex {cols[0][c]} {cols[1][c]} {cols[2][c]}")
            lines.append(" endloop\nendfacet")
        out.write(("\n".join(lines) + f"\nendsolid {name}\n").encode())
        at += k
