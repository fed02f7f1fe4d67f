"""PLY reading and writing (ascii, binary_little_endian, binary_big_endian).

Reading
-------
* ``vertex``: points from ``x``, ``y``, ``z`` (only ``x``, ``y``: 2D points), as float64.
  Values take the declared property type, as PLY specifies: a ``float`` property written as
  text ``0.1`` reads as ``float64(float32(0.1))``, exactly as from a binary file. Other vertex
  properties (confidence, intensity, normals, colours, ...) are read past and ignored.
* ``face``: the list property ``vertex_indices`` (or ``vertex_index``); polygons are
  fan-triangulated; faces repeating a vertex are dropped and counted in the notes.
* ``edge``: ``vertex1``, ``vertex2`` become standalone edges.
* Any other element (e.g. ``range_grid`` in Stanford range scans) is skipped and noted.
* Bodies are read by :mod:`.ply_binary` (numpy structured dtypes) and :mod:`.ply_ascii`
  (one element entry per line, as every PLY writer does).

Writing
-------
``binary_little_endian`` by default (``ascii=True`` for text), vertices as ``double x y z``
(2D points get ``z = 0``), faces as ``list uchar int vertex_indices``, all edges (standalone
and polyline edges) as an ``edge`` element. PLY has no polylines, so they are written as edges.
Points with 1 or more than 3 coordinates cannot be written as PLY.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.io.assemble import assemble
from service.io.coords import as_xyz
from service.io.document import GeometryDocument
from service.io.elements import as_indices, check_indices
from service.io.errors import FormatError
from service.io.ply_ascii import read_ascii_body
from service.io.ply_binary import read_binary_body
from service.io.ply_header import PlyElement, PlyHeader, parse_header
from service.io.text import format_rows, header_comments

__all__ = ["read_ply", "write_ply"]

_WANTED = ("vertex", "face", "edge")
_FACE_LISTS = ("vertex_indices", "vertex_index")


def _element(header: PlyHeader, name: str) -> PlyElement | None:
    for el in header.elements:
        if el.name == name:
            return el
    return None


def read_ply(data: bytes, *, weld: bool = False) -> GeometryDocument:
    """Read a PLY file from bytes.

    Raises
    ------
    FormatError
        Malformed header or body, counts that do not match the data, indices out of range.
    """
    header = parse_header(data)
    notes: list[str] = []
    vertex = _element(header, "vertex")
    if vertex is None:
        raise FormatError("PLY file has no 'vertex' element", fmt="ply")
    if vertex.find("x") is None or vertex.find("y") is None:
        raise FormatError("PLY 'vertex' element has no 'x' and 'y' properties", fmt="ply")
    for name in ("x", "y", "z"):
        prop = vertex.find(name)
        if prop is not None and prop.is_list:
            raise FormatError(f"PLY vertex property {name!r} is a list", fmt="ply")
    if header.encoding == "ascii":
        body = read_ascii_body(data, header, notes, _WANTED)
    else:
        body = read_binary_body(data, header, notes, _WANTED)
    names = ["x", "y", "z"] if vertex.find("z") is not None else ["x", "y"]
    vdata = body.get("vertex", {})
    if vertex.count == 0:
        raise FormatError("the file holds no points (element vertex 0)", fmt="ply")
    # ASCII values arrive as float64: round them to the declared type first (PLY semantics)
    declared = {p.name: p.type for p in vertex.properties}
    with np.errstate(over="ignore", invalid="ignore"):
        points = np.column_stack(
            [np.asarray(vdata[c]).astype(declared[c]).astype(np.float64) for c in names]
        )
    n = points.shape[0]
    polygons = None
    face = _element(header, "face")
    if face is not None and face.count:
        prop = face.find(*_FACE_LISTS) or next((p for p in face.properties if p.is_list), None)
        if prop is None or not prop.is_list:
            raise FormatError("PLY 'face' element has no 'vertex_indices' list", fmt="ply")
        items, counts = body["face"][prop.name]  # type: ignore[misc]
        flat = as_indices(np.asarray(items), what="face", fmt="ply")
        check_indices(flat, n, what="face", fmt="ply", counts=counts)
        polygons = (flat, counts)
    edges = None
    edge = _element(header, "edge")
    if edge is not None and edge.count:
        if edge.find("vertex1") is None or edge.find("vertex2") is None:
            raise FormatError("PLY 'edge' element needs 'vertex1' and 'vertex2'", fmt="ply")
        edata = body["edge"]
        edges = np.column_stack(
            [
                as_indices(np.asarray(edata[c]), what="edge", fmt="ply")
                for c in ("vertex1", "vertex2")
            ]
        )
        check_indices(edges.reshape(-1), n, what="edge", fmt="ply", counts=np.full(len(edges), 2))
    return assemble(
        points,
        fmt="ply",
        polygons=polygons,
        edges=edges,
        notes=notes,
        comments=header.comments,
        weld=weld,
    )


# --------------------------------------------------------------------------- writing


def write_ply(
    doc: GeometryDocument, points: NDArray[np.float64] | None = None, *, ascii: bool = False
) -> bytes:
    """Write a document as PLY (binary little-endian unless ``ascii``)."""
    pts = as_xyz(doc.output_points(points), "ply")
    faces = doc.output_faces()
    edges = doc.output_edges()
    head = ["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0"]
    head += [f"comment {c}" for c in header_comments(doc.comments)]
    head += [f"element vertex {len(pts)}"]
    head += [f"property double {c}" for c in "xyz"]
    if faces is not None and len(faces):
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    if edges is not None and len(edges):
        head += [f"element edge {len(edges)}", "property int vertex1", "property int vertex2"]
    head.append("end_header")
    chunks = ["\n".join(head).encode("ascii", errors="replace") + b"\n"]
    if ascii:
        chunks.append(format_rows(pts).encode())
        if faces is not None and len(faces):
            chunks.append(format_rows(faces.astype(np.int64), prefix="3 ").encode())
        if edges is not None and len(edges):
            chunks.append(format_rows(edges.astype(np.int64)).encode())
        return b"".join(chunks)
    chunks.append(np.ascontiguousarray(pts, dtype="<f8").tobytes())
    if faces is not None and len(faces):
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        rec["n"] = 3
        rec["v"] = faces
        chunks.append(rec.tobytes())
    if edges is not None and len(edges):
        chunks.append(np.ascontiguousarray(edges, dtype="<i4").tobytes())
    return b"".join(chunks)
