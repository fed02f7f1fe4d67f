"""PLY writing: the input's elements, properties and order, new coordinates and normals.

A document read from PLY is written back with its header's elements and properties in order
(faces with their per-face properties, ``range_grid``, any other element), every vertex
attribute unchanged, coordinates in the input's type (``precision``), normals recomputed or
dropped, and the input's encoding (``ply_ascii=None``; ``True``/``False`` force ASCII/binary
little-endian). ASCII values are written with the input's digits (see :mod:`.numfmt`).

Documents of other formats get ``x y z`` (2D points ``z = 0``), normals and attributes as vertex
properties (8-bit colours ``red green blue [alpha]`` as ``uchar``, the PLY convention, whatever
type the input stored them in, e.g. an XYZ file's 0..255 columns; glTF's ``uv`` as ``s t``, which
trimesh reads as texture coordinates), ``face`` (``list uchar int
vertex_indices``, plus an OBJ's texture coordinates as ``list uchar float texcoord``, the UVs of
each face's corners as MeshLab writes them) and an ``edge`` element holding the standalone and
polyline edges (PLY has no polylines).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from service.io._shared.coords import as_xyz
from service.io._shared.numfmt import (
    F32,
    ROWS_PER_CHUNK,
    default_spec,
    format_column,
    write_rows,
)
from service.io._shared.plain import PlainDocument
from service.io._shared.text import header_comments
from service.io._shared.texture import corner_uvs
from service.io.errors import FormatError
from service.io.formats.ply.read import PlyLayout

__all__ = ["write_ply"]

_TYPE_NAMES = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}


@dataclass
class _Prop:
    name: str
    type: str  # numpy code without byte order, e.g. "f4"
    values: NDArray[Any]  # scalar values, or the flat list items
    counts: NDArray[Any] | None = None  # list lengths (list properties only)
    count_type: str = "u1"
    spec: str = "%r"


@dataclass
class _Element:
    name: str
    count: int
    props: list[_Prop]


def _code(dtype: np.dtype[Any]) -> str:
    return dtype.kind + str(dtype.itemsize)


def _ply_type(values: NDArray[Any]) -> tuple[str, NDArray[Any]]:
    """A PLY type for an attribute column (64-bit integers as int/double, bools as uchar)."""
    dt = values.dtype
    if dt.kind == "b":
        return "u1", values.astype(np.uint8)
    if dt.kind in "iu" and dt.itemsize == 8:
        lo, hi = (int(values.min()), int(values.max())) if values.size else (0, 0)
        if lo >= -(2**31) and hi < 2**31:
            return "i4", values.astype(np.int32)
        return "f8", values.astype(np.float64)
    if dt.kind == "f" and dt.itemsize == 2:
        return "f4", values.astype(np.float32)
    code = _code(dt)
    if code not in _TYPE_NAMES:
        raise FormatError(f"PLY cannot store an attribute of type {dt}", fmt="ply")
    return code, values


_COLOURS = ("red", "green", "blue", "alpha")


def _bytes(values: NDArray[Any]) -> bool:
    """Whether a colour column holds 8-bit values (integers 0..255, in any dtype)."""
    if values.dtype.kind not in "iuf" or not values.size:
        return False
    if values.dtype.kind == "f" and float(np.max(values)) <= 1.0:  # fractions (OBJ), or unclear
        return False
    with np.errstate(invalid="ignore"):
        return bool(np.all((values >= 0) & (values <= 255) & (values == np.round(values))))


def _vertex_props(plain: PlainDocument, layout: PlyLayout | None) -> list[_Prop]:
    cdt = plain.coordinate_dtype()
    specs = plain.coordinate_specs()
    text = layout.text if layout is not None and plain.options.precision == "input" else {}
    if layout is not None:
        pts = plain.points
        coords = {c: i for i, c in enumerate(layout.coords)}
        normals = {c: i for i, c in enumerate(layout.normals or ())}
        vertex = layout.header.elements[layout.vertex]
        vdata = layout.elements[layout.vertex]
    else:
        pts = as_xyz(plain.points, "ply")
        specs = specs + specs[-1:] if len(specs) == 2 else specs
        coords = {"x": 0, "y": 1, "z": 2}
        normals = {"nx": 0, "ny": 1, "nz": 2}
        vertex = None
        vdata = {}
    out = [_Prop(c, _code(cdt), pts[:, i].astype(cdt), spec=specs[i]) for c, i in coords.items()]
    if plain.normals is not None:
        for c, i in normals.items():
            declared = vertex.find(c) if vertex is not None else None
            ntype = declared.type if declared is not None else "f4"
            values = np.asarray(plain.normals[:, i]).astype(ntype)
            out.append(_Prop(c, ntype, values, spec=text.get(c, default_spec(values.dtype))))
    attrs = {}
    for name, values in plain.attributes.items():
        cols = [values] if values.ndim == 1 else [values[:, j] for j in range(values.shape[1])]
        names = [name] if values.ndim == 1 else [f"{name}_{j}" for j in range(values.shape[1])]
        if vertex is None and name == "uv" and len(names) == 2:  # glTF's: PLY's ``s t``
            names = ["s", "t"]
        for nm, col in zip(names, cols, strict=True):
            code, col = _ply_type(np.asarray(col))
            spec = plain.attribute_spec(name)
            if vertex is None and nm in _COLOURS and _bytes(col):  # the PLY convention: uchar
                code, col, spec = "u1", col.astype(np.uint8), "%d"
            attrs[nm] = _Prop(nm, code, col, spec=spec)
    if vertex is None:
        return out + list(attrs.values())
    ordered: list[_Prop] = []
    by_name = {p.name: p for p in out}
    for p in vertex.properties:
        if p.name in by_name:
            ordered.append(by_name[p.name])
        elif p.name in attrs:
            ordered.append(attrs.pop(p.name))
        elif p.is_list:
            items, counts = vdata[p.name]  # type: ignore[misc]
            items = np.asarray(items).reshape(-1)
            ordered.append(_Prop(p.name, p.type, items, counts, str(p.count_type), "%d"))
    return ordered + list(attrs.values())


def _elements(plain: PlainDocument, layout: PlyLayout | None) -> list[_Element]:
    vertex = _Element("vertex", plain.n, _vertex_props(plain, layout))
    if layout is not None:
        out = []
        for i, el in enumerate(layout.header.elements):
            if i == layout.vertex:
                out.append(vertex)
                continue
            props = []
            for p in el.properties:
                value = layout.elements[i].get(p.name)
                if p.is_list:
                    items, counts = value if value is not None else (np.zeros(0), np.zeros(0))  # type: ignore[misc]
                    items = np.asarray(items).reshape(-1)
                    props.append(_Prop(p.name, p.type, items, counts, str(p.count_type)))
                else:
                    props.append(_Prop(p.name, p.type, np.asarray(value)))
            for prop in props:
                prop.spec = default_spec(np.dtype(prop.type))
            out.append(_Element(el.name, el.count, props))
        return out
    out = [vertex]
    if plain.faces is not None and len(plain.faces):
        f = plain.faces
        counts = np.full(len(f), 3, dtype=np.uint8)
        items = f.reshape(-1).astype(np.int32)
        props = [_Prop("vertex_indices", "i4", items, counts, "u1", "%d")]
        uvs = corner_uvs(plain, "ply")
        if uvs is not None:  # OBJ texture coordinates, per face corner (MeshLab's texcoord)
            flat = uvs[1][uvs[0]].reshape(-1).astype(np.float32)
            props.append(_Prop("texcoord", "f4", flat, np.full(len(f), 6, np.uint8), "u1", F32))
        out.append(_Element("face", len(f), props))
    edges = plain.edges()
    if edges is not None and len(edges):
        e = edges.astype(np.int32)
        out.append(
            _Element(
                "edge",
                len(e),
                [
                    _Prop("vertex1", "i4", e[:, 0], spec="%d"),
                    _Prop("vertex2", "i4", e[:, 1], spec="%d"),
                ],
            )
        )
    return out


def _header(plain: PlainDocument, encoding: str, elements: list[_Element]) -> bytes:
    head = ["ply", f"format {encoding} 1.0"]
    head += [f"comment {c}" for c in header_comments(plain.comments)]
    layout = plain.layout
    if isinstance(layout, PlyLayout):
        head += [f"obj_info {c}" for c in layout.header.obj_info]
    for el in elements:
        head.append(f"element {el.name} {el.count}")
        for p in el.props:
            if p.counts is not None:
                ct, it = _TYPE_NAMES[p.count_type], _TYPE_NAMES[p.type]
                head.append(f"property list {ct} {it} {p.name}")
            else:
                head.append(f"property {_TYPE_NAMES[p.type]} {p.name}")
    head.append("end_header")
    return ("\n".join(head) + "\n").encode("ascii", errors="replace")


def _offsets(counts: NDArray[Any]) -> NDArray[np.int64]:
    out = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=out[1:])
    return out


def _binary_blocks(el: _Element, endian: str) -> Iterator[bytes]:
    """The element's binary body, block by block."""
    offs = {p.name: _offsets(p.counts) for p in el.props if p.counts is not None}
    if not offs:
        dt = np.dtype([(p.name, endian + p.type) for p in el.props])
        for s in range(0, el.count, ROWS_PER_CHUNK):
            rec = np.empty(min(ROWS_PER_CHUNK, el.count - s), dtype=dt)
            for p in el.props:
                rec[p.name] = p.values[s : s + len(rec)]
            yield rec.tobytes()
        return
    for s in range(0, el.count, ROWS_PER_CHUNK):
        e = min(s + ROWS_PER_CHUNK, el.count)
        lens = {n: np.diff(o[s : e + 1]) for n, o in offs.items()}
        keys = np.stack(list(lens.values()), axis=1)
        groups, inverse = np.unique(keys, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        dts = []
        for g in groups:
            fields: list[Any] = []
            j = 0
            for p in el.props:
                if p.counts is None:
                    fields.append((p.name, endian + p.type))
                    continue
                k = int(g[j])
                j += 1
                fields.append((f"{p.name}#n", endian + p.count_type))
                if k:
                    fields.append((p.name, endian + p.type, (k,)))
            dts.append(np.dtype(fields))
        sizes = np.array([d.itemsize for d in dts], dtype=np.int64)[inverse]
        starts = _offsets(sizes)
        buf = np.empty(int(starts[-1]), dtype=np.uint8)
        for gi, dt in enumerate(dts):
            rows = np.flatnonzero(inverse == gi)
            rec = np.empty(rows.size, dtype=dt)
            for p in el.props:
                if p.counts is None:
                    rec[p.name] = p.values[s + rows]
                    continue
                k = int(lens[p.name][rows[0]])
                rec[f"{p.name}#n"] = k
                if k:
                    first = offs[p.name][s + rows]
                    rec[p.name] = p.values[first[:, None] + np.arange(k)]
            idx = starts[rows][:, None] + np.arange(dt.itemsize)
            buf[idx] = rec.view(np.uint8).reshape(rows.size, dt.itemsize)
        yield buf.tobytes()


def _ascii_blocks(el: _Element) -> Iterator[list[str]]:
    """The element's lines, block by block."""
    offs = {p.name: _offsets(p.counts) for p in el.props if p.counts is not None}
    for s in range(0, el.count, ROWS_PER_CHUNK):
        e = min(s + ROWS_PER_CHUNK, el.count)
        parts: list[list[str]] = [[] for _ in range(e - s)]
        for p in el.props:
            if p.counts is None:
                for i, text in enumerate(format_column(p.values[s:e], p.spec)):
                    parts[i].append(text)
                continue
            o = offs[p.name]
            lo, hi = int(o[s]), int(o[e])
            texts = format_column(p.values[lo:hi], p.spec)
            local = o[s : e + 1] - lo
            for i in range(e - s):
                a, b = int(local[i]), int(local[i + 1])
                parts[i].append(str(b - a))
                parts[i].extend(texts[a:b])
        yield [" ".join(row) for row in parts]


def write_ply(plain: PlainDocument, out: BinaryIO) -> None:
    """Write a plain document as PLY (see the module docstring)."""
    layout = plain.layout if isinstance(plain.layout, PlyLayout) else None
    mode = plain.options.ply_ascii
    if mode is None:
        encoding = layout.header.encoding if layout is not None else "binary_little_endian"
    else:
        encoding = "ascii" if mode else "binary_little_endian"
    elements = _elements(plain, layout)
    out.write(_header(plain, encoding, elements))
    for el in elements:
        if encoding == "ascii":
            if all(p.counts is None for p in el.props):
                write_rows(out, [(p.values, p.spec) for p in el.props], n=el.count)
                continue
            for lines in _ascii_blocks(el):
                out.write(("\n".join(lines) + "\n").encode("ascii"))
        else:
            endian = "<" if encoding == "binary_little_endian" else ">"
            for chunk in _binary_blocks(el, endian):
                out.write(chunk)
