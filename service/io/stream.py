"""Streamed point files for tiled runs (issue 23): coordinates in, coordinates out, in chunks.

A tiled run needs only the coordinates of the input (24 bytes a point) and gives back new
coordinates; every other attribute can stay in the file. :func:`read_coordinates` reads
``x, y, z`` chunk by chunk (LAS/LAZ with laspy's chunk iterator, binary PLY through a memory
map of its vertex block, XYZ text in blocks of lines) and, for binary PLY meshes, the
triangles; :func:`rewrite` streams the input again and writes it with the new coordinates, every
other dimension, property, column and byte left as it was (LAS/LAZ: scaled to the file's own
scale and offset; PLY: cast to the vertex properties' types; XYZ: printed with the input's
decimals). So the process holds the coordinates twice and one chunk of records, never the
input's attribute table. Running the engine between the two is the use case's
(:func:`service.workflows.smooth_file.smooth_streamed`); this module only turns bytes into
coordinates and back.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from service.io.dispatch import check_not_empty
from service.io.errors import FormatError
from service.io.formats import xyz
from service.io.formats.ply import read as ply_read
from service.io.formats.ply.header import PlyHeader, parse_header
from service.io.limits import ReadLimits, reading
from service.io.source import UTF8_BOM, Source, mapped

__all__ = [
    "CHUNK",
    "STREAMED",
    "read_coordinates",
    "rewrite",
    "streamable",
    "streamed_format",
]

CHUNK = 1 << 20
#: Formats read and written in chunks here.
STREAMED = ("las", "laz", "ply", "xyz")
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
Array = NDArray[np.float64]


def _code(ply_type: str) -> str:
    """numpy code of a PLY scalar type (the header parser may have normalised it already)."""
    return _PLY_TYPES.get(ply_type, ply_type)


def _ply_header(path: Path) -> PlyHeader:
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    return parse_header(head)


def _vertex_dtype(header: PlyHeader) -> np.dtype | None:
    """The structured dtype of a binary PLY's leading vertex element (scalars only)."""
    if header.encoding == "ascii" or not header.elements:
        return None
    vertex = header.elements[0]
    if vertex.name != "vertex" or any(p.is_list for p in vertex.properties):
        return None
    if not {"x", "y", "z"} <= {p.name for p in vertex.properties}:
        return None
    end = "<" if header.encoding == "binary_little_endian" else ">"
    return np.dtype([(p.name, end + _code(p.type)) for p in vertex.properties])


def streamable(path: Path, fmt: str) -> bool:
    """Whether :func:`read_coordinates` / :func:`rewrite` handle this file: LAS/LAZ; XYZ of
    three or more columns; binary PLY whose first element is the vertex (scalar ``x y z``),
    followed by at most a ``face`` element. Files with a byte order mark take the ordinary
    path (which drops it)."""
    if fmt in ("las", "laz"):
        return True
    if fmt not in ("ply", "xyz"):
        return False
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if head.startswith(UTF8_BOM):
        return False
    if fmt == "xyz":
        return xyz.columns(head) >= 3
    try:
        header = parse_header(head)
    except FormatError:
        return False
    if _vertex_dtype(header) is None:
        return False
    rest = header.elements[1:]
    return all(e.name == "face" for e in rest) and len(rest) <= 1


def read_coordinates(
    path: Path, fmt: str, *, limits: ReadLimits | None = None
) -> tuple[Array, NDArray[np.int64] | None]:
    """``(points (n, 3) float64, triangles (m, 3) or None)`` of a streamable file.

    The checks are the ordinary readers' own code (:func:`service.io.formats.las.open_points`,
    :func:`service.io.formats.ply.read.read_coordinates`,
    :func:`service.io.formats.xyz.read_coordinates`), so a file one path refuses the other
    refuses with the same message;
    ``limits`` (default: those in force, :mod:`service.io.limits`) bound the declared counts
    before anything is allocated.

    Raises
    ------
    FormatError
        Whatever the ordinary reader raises for this file
        (:class:`~service.io.limits.InputTooLarge` past the limits).
    GeometryError
        Non-finite coordinates (as the ordinary readers).
    """
    path = Path(path)
    with reading(limits):
        return _coordinates(path, fmt)


def _coordinates(path: Path, fmt: str) -> tuple[Array, NDArray[np.int64] | None]:
    source = Source.of(path)
    check_not_empty(source, fmt)
    if fmt in ("las", "laz"):
        return _las_points(source, fmt), None
    with mapped(path) as data:
        if fmt == "xyz":
            return xyz.read_coordinates(data), None
        end = data.find(b"end_header")
        header = parse_header(data[: end + 4096] if end >= 0 else data[: 1 << 16])
        return ply_read.read_coordinates(data.map, header)


def _las_points(source: Source, fmt: str) -> Array:
    from service.io.formats.las import open_points

    with open_points(source, fmt, attributes=False) as stream:
        P = np.empty((stream.n, 3))
        at = 0
        for chunk in stream.chunks:
            k = len(chunk)
            P[at : at + k] = np.c_[chunk.x, chunk.y, chunk.z]
            at += k
    return P


def _numeric(token: bytes) -> bool:
    try:
        float(token.replace(b",", b""))
    except ValueError:
        return False
    return True


def rewrite(src: Path, dst: Path, fmt: str, points: Array) -> None:
    """Write ``src`` to ``dst`` with ``points`` as its coordinates, chunk by chunk (module
    docstring).

    Raises
    ------
    FormatError
        A coordinate that the LAS file's scale and offset cannot hold.
    """
    src, dst = Path(src), Path(dst)
    if fmt in ("las", "laz"):
        _las_rewrite(src, dst, points, fmt == "laz")
    elif fmt == "xyz":
        _xyz_rewrite(src, dst, points)
    else:
        _ply_rewrite(src, dst, points)


def _las_rewrite(src: Path, dst: Path, points: Array, compress: bool) -> None:
    import laspy

    from service.io.formats.las import _scaled

    with laspy.open(src) as reader, laspy.open(dst, mode="w", header=reader.header,
                                               do_compress=compress) as writer:  # fmt: skip
        header = reader.header
        at = 0
        for chunk in reader.chunk_iterator(CHUNK):
            k = len(chunk)
            for j, name in enumerate(("X", "Y", "Z")):
                scale, offset = float(header.scales[j]), float(header.offsets[j])
                chunk[name] = _scaled(points[at : at + k, j], scale, offset, "xyz"[j])
            writer.write_points(chunk)
            at += k
        if header.evlrs:
            writer.write_evlrs(header.evlrs)


def _ply_rewrite(src: Path, dst: Path, points: Array) -> None:
    header = _ply_header(src)
    vdt = _vertex_dtype(header)
    assert vdt is not None
    n = header.elements[0].count
    vertices = np.memmap(src, dtype=vdt, mode="r", offset=header.body_offset, shape=(n,))
    with open(src, "rb") as fin, open(dst, "wb") as out:
        out.write(fin.read(header.body_offset))
        for at in range(0, n, CHUNK):
            block = np.array(vertices[at : at + CHUNK])
            for j, name in enumerate("xyz"):
                block[name] = points[at : at + CHUNK, j].astype(vdt[name])
            out.write(block.tobytes())
        fin.seek(header.body_offset + n * vdt.itemsize)
        shutil.copyfileobj(fin, out, 1 << 22)


def _decimals(token: bytes) -> int:
    text = token.decode()
    return len(text.split(".", 1)[1]) if "." in text and "e" not in text.lower() else 6


def _xyz_rewrite(src: Path, dst: Path, points: Array) -> None:
    at = 0
    with open(src, "rb") as fin, open(dst, "wb") as out:
        digits: list[int] | None = None
        for raw in fin:
            s = raw.strip()
            if not s or s.startswith(b"#") or not _numeric(s.split(None, 1)[0]):
                out.write(raw)
                continue
            sep = b"," if b"," in s else b" "  # the reader's separators: commas or blanks
            tokens = s.replace(b",", b" ").split()
            if digits is None:
                digits = [_decimals(t) for t in tokens[:3]]
            new = [f"{points[at, j]:.{digits[j]}f}".encode() for j in range(3)]
            out.write(sep.join(new + tokens[3:]) + b"\n")
            at += 1


def streamed_format(
    src: Path, given: str | None, out_fmt: str | None, weld: bool | None, xyz_dims: int | None
) -> str | None:
    """The format to stream ``src`` in, or ``None`` when the file is not for this path: the
    output in the same format, no welding, three coordinates, a :func:`streamable` file."""
    from service.io import detect_format

    fmt = given or (detect_format(src.name) if src.suffix else None)
    if fmt not in STREAMED or (out_fmt not in (None, fmt)) or weld or xyz_dims not in (None, 3):
        return None
    return fmt if src.is_file() and streamable(src, fmt) else None
