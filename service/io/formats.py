"""Format dispatch: :func:`detect_format`, :func:`read_geometry`, :func:`write_geometry`.

Supported formats are :data:`FORMATS`. Formats people commonly try (GPX, GeoJSON, DXF, STL,
...) are refused with an :class:`~service.io.errors.UnsupportedFormat` that says what to
convert the data to.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from service.io.document import GeometryDocument
from service.io.errors import FormatError, UnsupportedFormat
from service.io.registry import FORMATS, format_for_name, get_format, supported_text

__all__ = ["FORMATS", "detect_format", "read_geometry", "sniff_format", "write_geometry"]

_TO_POLYLINE = "as OBJ polylines ('v' + 'l' lines) or geosmooth JSON {points, polylines}"
_REFUSED: dict[str, str] = {
    "gpx": "GPX is not supported: convert each track segment to a polyline and save it "
    + _TO_POLYLINE,
    "geojson": "GeoJSON is not supported: convert each LineString to a polyline and save it "
    + _TO_POLYLINE,
    "dxf": "DXF is not supported: discretise the outline (lines and arcs) to polylines and save "
    "them " + _TO_POLYLINE,
    "svg": "SVG is not supported: discretise the paths to polylines and save them " + _TO_POLYLINE,
    "kml": "KML is not supported: convert the tracks to polylines and save them " + _TO_POLYLINE,
    "stl": "STL is not supported: convert the mesh to PLY or OBJ (e.g. with trimesh or MeshLab)",
    "off": "OFF is not supported: convert the mesh to PLY or OBJ (e.g. with trimesh or MeshLab)",
    "gltf": "glTF is not supported: export the mesh as PLY or OBJ",
    "glb": "glTF is not supported: export the mesh as PLY or OBJ",
    "fbx": "FBX is not supported: export the mesh as PLY or OBJ",
    "3ds": "3DS is not supported: export the mesh as PLY or OBJ",
    "vtk": "VTK is not supported: convert the data to PLY (e.g. with pyvista's save('x.ply'))",
    "vtp": "VTK is not supported: convert the data to PLY (e.g. with pyvista's save('x.ply'))",
    "pcd": "PCD is not supported: convert the point cloud to PLY or XYZ (e.g. with Open3D)",
    "las": "LAS/LAZ is not supported: convert the point cloud to PLY or XYZ (e.g. with PDAL)",
    "laz": "LAS/LAZ is not supported: convert the point cloud to PLY or XYZ (e.g. with PDAL)",
}


def _check_fmt(fmt: str) -> str:
    key = fmt.lower().lstrip(".")
    if key in _REFUSED and key not in FORMATS:
        raise UnsupportedFormat(_REFUSED[key], fmt=key)
    return get_format(key).name


def detect_format(filename: str) -> str:
    """The format of a file from its name's extension (case-insensitive).

    Raises
    ------
    UnsupportedFormat
        For GPX, GeoJSON, DXF and other known formats (the message says what to convert to),
        unknown extensions, and names without an extension.
    """
    name = Path(str(filename)).name
    suffix = Path(name).suffix.lower().lstrip(".")
    if not suffix:
        raise UnsupportedFormat(
            f"cannot tell the format of {name!r} (no file extension): {supported_text()};"
            " pass the format explicitly"
        )
    known = format_for_name(name)
    if known is not None:
        return known.name
    if suffix in _REFUSED:
        raise UnsupportedFormat(_REFUSED[suffix], fmt=suffix)
    raise UnsupportedFormat(
        f"unsupported file extension '.{suffix}' ({name!r}): {supported_text()}", fmt=suffix
    )


def sniff_format(data: bytes) -> str | None:
    """Guess the format from the content: ``"ply"``, ``"json"``, ``"obj"``, ``"xyz"`` or None."""
    head = data[:4096].lstrip()
    if head.startswith(b"ply"):
        return "ply"
    if head[:1] in (b"{", b"["):
        return "json"
    if head.startswith(b"<"):
        return None
    for line in head.split(b"\n")[:-1] or head.split(b"\n"):
        words = line.replace(b",", b" ").split()
        if not words or words[0].startswith(b"#"):
            continue
        if words[0] in (b"v", b"vn", b"vt", b"f", b"l", b"o", b"g", b"mtllib", b"usemtl", b"s"):
            return "obj"
        try:
            [float(w) for w in words]
        except ValueError:
            continue
        return "xyz"
    return None


def _load(
    source: bytes | bytearray | memoryview | str | os.PathLike[str],
) -> tuple[bytes, str | None]:
    if isinstance(source, bytes | bytearray | memoryview):
        return bytes(source), None
    if isinstance(source, str | os.PathLike):
        path = Path(source)
        return path.read_bytes(), path.name
    raise TypeError(f"source must be bytes or a path, got {type(source).__name__}")


def read_geometry(
    source: bytes | str | os.PathLike[str],
    fmt: str | None = None,
    *,
    filename: str | None = None,
    weld: bool = False,
    xyz_dims: int | None = None,
) -> GeometryDocument:
    """Read a geometry file.

    Parameters
    ----------
    source : bytes or str or path-like
        File content (e.g. an upload) or a path to read.
    fmt : str, optional
        One of :data:`FORMATS`. Default: from the extension of ``filename`` (or the path's
        name); without one, from the content (PLY magic, a JSON object, OBJ keywords, numbers).
    filename : str, optional
        Name used to detect the format of bytes.
    weld : bool
        Merge exactly coincident vertices (see :mod:`service.io.weld`); the document remembers
        the map, and :func:`write_geometry` writes the original vertex count and order.
    xyz_dims : int, optional
        XYZ only: number of leading columns that are coordinates (see :mod:`service.io.xyz`).

    Returns
    -------
    GeometryDocument

    Raises
    ------
    UnsupportedFormat
        A format geosmooth does not read (GPX, GeoJSON, DXF, unknown).
    FormatError
        A malformed file (one-line message; the line number for text formats).
    GeometryError
        Content with no meaning as smoothing input (e.g. non-finite coordinates).
    """
    data, path_name = _load(source)
    name = str(filename or path_name or "")
    if fmt is not None:
        kind = _check_fmt(fmt)
    elif Path(name).suffix:
        kind = detect_format(name)
    else:  # no name, or a name without an extension: look at the content
        sniffed = sniff_format(data)
        if sniffed is None:
            if not data.strip():
                raise FormatError("the file is empty")
            raise UnsupportedFormat(f"cannot tell the format of the data: {supported_text()}")
        kind = sniffed
    if kind != "xyz" and xyz_dims is not None:
        raise ValueError("xyz_dims applies to XYZ files only")
    options = {"xyz_dims": xyz_dims} if xyz_dims is not None else {}
    return FORMATS[kind].read(data, weld=weld, **options)


def write_geometry(
    doc: GeometryDocument,
    fmt: str,
    points: ArrayLike | None = None,
    *,
    ply_ascii: bool = False,
) -> bytes:
    """Write a document (optionally with new points) in one of :data:`FORMATS`.

    Parameters
    ----------
    doc : GeometryDocument
        From :func:`read_geometry` (or built from a geometry).
    fmt : str
        Output format.
    points : array_like, optional
        The smoothed points: same shape as ``doc.geometry.points``. Default: the doc's own.
        For a welded document, each original vertex is written with its welded vertex's point,
        so the output keeps the input's vertex count, order and connectivity.
    ply_ascii : bool
        Write ASCII PLY instead of binary little-endian.

    Raises
    ------
    FormatError
        The format cannot hold the points (PLY and OBJ: 2 or 3 coordinates; XYZ: at least 2).
    UnsupportedFormat
        ``fmt`` is not one of :data:`FORMATS`.
    ValueError
        ``points`` has the wrong shape.
    """
    spec = FORMATS[_check_fmt(fmt)]
    if spec.write is None:
        raise UnsupportedFormat(f"{spec.title} can be read but not written", fmt=spec.name)
    pts: Any = None if points is None else np.asarray(points, dtype=np.float64)
    if pts is not None and pts.shape != doc.geometry.points.shape:
        raise ValueError(
            f"points must have the shape of the document's points {doc.geometry.points.shape},"
            f" got {pts.shape}"
        )
    return spec.write(doc, pts, ascii=ply_ascii)
