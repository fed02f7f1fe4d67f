"""PLY reading (ascii, binary_little_endian, binary_big_endian); writing is in :mod:`.ply.write`.

Reading
-------
* ``vertex``: points from ``x``, ``y``, ``z`` (only ``x``, ``y``: 2D points), as float64 taking
  the declared type first (PLY semantics: a ``float`` written as text ``0.1`` reads as
  ``float64(float32(0.1))``, exactly as from a binary file). Normals (``nx ny nz`` or
  ``normal_x ...``) become the document's normals; every other scalar vertex property
  (confidence, intensity, colours, alpha, quality, labels, ...) is an attribute, in its own dtype.
* ``face``: the list ``vertex_indices`` (or ``vertex_index``); polygons are fan-triangulated for
  the engine; faces repeating a vertex are dropped there and counted in the notes.
* ``edge``: ``vertex1``, ``vertex2`` become standalone edges.
* Every element (faces with their other properties, ``range_grid``, ...) is kept in the
  :class:`PlyLayout`, so a PLY written back has the input's elements, properties and order.
* Bodies are read by :mod:`.ply.binary` (numpy structured dtypes, views of the input) and
  :mod:`.ply.ascii` (bounded blocks, one entry per line).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io._shared.assemble import assemble, triangles
from service.io._shared.elements import as_indices, check_indices
from service.io._shared.numfmt import Digits
from service.io.document import GeometryDocument, Precision
from service.io.errors import FormatError
from service.io.formats.ply.ascii import read_ascii_body
from service.io.formats.ply.binary import read_binary_body
from service.io.formats.ply.header import PlyElement, PlyHeader, parse_header
from service.io.formats.ply.model import ElementData
from service.io.limits import check_points
from service.io.source import Source

__all__ = ["NORMAL_NAMES", "PlyLayout", "checked_body", "read_coordinates", "read_ply"]

Array = NDArray[np.float64]

_FACE_LISTS = ("vertex_indices", "vertex_index")
NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))


@dataclass(frozen=True, eq=False)
class PlyLayout:
    """A PLY file's structure: header, every element's data, where coordinates and normals are.

    Attributes
    ----------
    header : PlyHeader
        As parsed (encoding, elements and properties in order, comments, obj_info).
    elements : list of ElementData
        Data of every element, in header order (the vertex element's too).
    vertex : int
        Index of the ``vertex`` element.
    coords : tuple of str
        Coordinate property names.
    normals : tuple of str or None
        Normal property names.
    text : dict of str to str
        ASCII input: printf spec of each vertex property (the input's digits).
    """

    header: PlyHeader
    elements: list[ElementData]
    vertex: int
    coords: tuple[str, ...]
    normals: tuple[str, str, str] | None
    text: dict[str, str]


def _check_counts(header: PlyHeader, size: int) -> None:
    """Declared counts must fit the body (no allocation from an absurd header count)."""
    room = size - header.body_offset
    for el in header.elements:
        if header.encoding == "ascii":
            least = 2 if el.count else 0
        else:
            least = sum(
                np.dtype(p.count_type if p.is_list else p.type).itemsize  # type: ignore[arg-type]
                for p in el.properties
            )
        if el.count * least > room:
            if header.encoding != "ascii":
                raise FormatError(
                    f"binary PLY is truncated: element {el.name!r} ({el.count} entries) needs"
                    f" {el.count * least} more bytes but only {max(room, 0)} remain (or the"
                    " element counts do not match the data)",
                    fmt="ply",
                )
            raise FormatError(
                f"the header declares {el.count} {el.name} entries but the body has only {room}"
                " bytes (element counts do not match the data)",
                fmt="ply",
            )
        room -= el.count * least


def _vertex_checks(header: PlyHeader) -> tuple[int, PlyElement]:
    index = next((i for i, el in enumerate(header.elements) if el.name == "vertex"), None)
    if index is None:
        raise FormatError("PLY file has no 'vertex' element", fmt="ply")
    vertex = header.elements[index]
    if vertex.find("x") is None or vertex.find("y") is None:
        raise FormatError("PLY 'vertex' element has no 'x' and 'y' properties", fmt="ply")
    for name in ("x", "y", "z"):
        prop = vertex.find(name)
        if prop is not None and prop.is_list:
            raise FormatError(f"PLY vertex property {name!r} is a list", fmt="ply")
    if vertex.count == 0:
        raise FormatError("the file holds no points (element vertex 0)", fmt="ply")
    return index, vertex


def _normal_names(vertex: PlyElement) -> tuple[str, str, str] | None:
    for names in NORMAL_NAMES:
        props = [vertex.find(n) for n in names]
        if all(p is not None and not p.is_list for p in props):
            return names
    return None


def _faces(
    header: PlyHeader, elements: list[ElementData], n: int
) -> tuple[NDArray[np.int64], NDArray[Any]] | None:
    index = next((i for i, el in enumerate(header.elements) if el.name == "face"), None)
    if index is None or not header.elements[index].count:
        return None
    face = header.elements[index]
    prop = face.find(*_FACE_LISTS) or next((p for p in face.properties if p.is_list), None)
    if prop is None or not prop.is_list:
        raise FormatError("PLY 'face' element has no 'vertex_indices' list", fmt="ply")
    items, counts = elements[index][prop.name]  # type: ignore[misc]
    flat = as_indices(np.asarray(items), what="face", fmt="ply")
    check_indices(flat, n, what="face", fmt="ply", counts=counts)
    return flat, counts


def _edges(header: PlyHeader, elements: list[ElementData], n: int) -> NDArray[np.int64] | None:
    index = next((i for i, el in enumerate(header.elements) if el.name == "edge"), None)
    if index is None or not header.elements[index].count:
        return None
    edge = header.elements[index]
    if edge.find("vertex1") is None or edge.find("vertex2") is None:
        raise FormatError("PLY 'edge' element needs 'vertex1' and 'vertex2'", fmt="ply")
    data = elements[index]
    edges = np.column_stack(
        [as_indices(np.asarray(data[c]), what="edge", fmt="ply") for c in ("vertex1", "vertex2")]
    )
    check_indices(edges.reshape(-1), n, what="edge", fmt="ply", counts=np.full(len(edges), 2))
    return edges


def _face_count(header: PlyHeader) -> int:
    return sum(el.count for el in header.elements if el.name == "face")


def checked_body(
    data: Any, header: PlyHeader, *, held: int = 0
) -> tuple[int, PlyElement, list[ElementData], Digits | None]:
    """The body of a PLY file after every check of the ordinary reader, shared with the
    streamed reader (:func:`read_coordinates`): counts that fit the file, a vertex element with
    coordinates, the reader limits (``held``: bytes of the file held in memory besides the
    arrays), then the elements (truncation, list lengths, trailing bytes)."""
    _check_counts(header, len(data))
    vi, vertex = _vertex_checks(header)
    n, m = vertex.count, _face_count(header)
    check_points(n, (held + 24 * n + 48 * m) / n, "ply")
    digits = Digits(len(vertex.properties)) if header.encoding == "ascii" else None
    if header.encoding == "ascii":
        elements = read_ascii_body(data, header, digits)
    else:
        elements = read_binary_body(data, header)
    return vi, vertex, elements, digits


def _points(vertex: PlyElement, vdata: ElementData, coords: tuple[str, ...]) -> Array:
    points = np.empty((vertex.count, len(coords)))
    for j, c in enumerate(coords):  # column by column: no float64 temporaries
        points[:, j] = vdata[c]
    return points


def read_coordinates(data: Any, header: PlyHeader) -> tuple[Array, NDArray[np.int64] | None]:
    """``(points, triangles or None)`` of a PLY file (``data``: bytes or a memory map), checked
    exactly as :func:`read_ply` checks it; the streamed reader's (:mod:`service.io.stream`)."""
    vi, vertex, elements, _ = checked_body(data, header)
    coords = ("x", "y", "z") if vertex.find("z") is not None else ("x", "y")
    points = _points(vertex, elements[vi], coords)
    _edges(header, elements, len(points))
    polygons = _faces(header, elements, len(points))
    faces = None if polygons is None else np.array(triangles(polygons)[0], dtype=np.int64)
    return points, faces


def read_ply(source: Source, *, weld: bool = False) -> GeometryDocument:
    """Read a PLY file.

    Raises
    ------
    FormatError
        Malformed header or body, counts that do not match the data, indices out of range.
    """
    data = source.data()
    header = parse_header(data)
    vi, vertex, elements, digits = checked_body(data, header, held=len(data))
    vdata = elements[vi]
    coords = ("x", "y", "z") if vertex.find("z") is not None else ("x", "y")
    points = _points(vertex, vdata, coords)
    normal_names = _normal_names(vertex)
    normals = None
    if normal_names is not None:
        normals = np.column_stack([np.asarray(vdata[c]) for c in normal_names])
    skip = set(coords) | set(normal_names or ())
    attributes = {
        p.name: np.asarray(vdata[p.name])
        for p in vertex.properties
        if not p.is_list and p.name not in skip
    }
    specs = (
        dict(zip([p.name for p in vertex.properties], digits.specs(), strict=True))
        if digits
        else {}
    )
    xtype = np.dtype(vertex.find("x").type)  # type: ignore[union-attr]
    precision = Precision(
        dtype="float32" if xtype == np.float32 else "float64",
        text=tuple(specs[c] for c in coords) if specs else None,
        attribute_text={k: v for k, v in specs.items() if k in attributes},
    )
    notes = []
    for el in header.elements:
        if el.name not in ("vertex", "face", "edge") and el.count:
            notes.append(f"kept PLY element {el.name!r} ({el.count} entries) as it is")
    layout = PlyLayout(header, elements, vi, coords, normal_names, specs)
    doc = assemble(
        points,
        fmt="ply",
        polygons=_faces(header, elements, len(points)),
        edges=_edges(header, elements, len(points)),
        notes=notes,
        comments=header.comments,
        weld=weld,
    )
    return doc.with_extras(
        attributes=attributes, normals=normals, precision=precision, layout=layout
    )
