"""Reference readers of the cross-format matrix (tests/io/test_cross_format.py).

Each reader takes a file's bytes and returns what the library people use for that format saw
(:class:`Back`): :data:`READERS` the format's own library (plyfile or ours for PLY, trimesh,
laspy, pypcd4, pye57, gpxpy, ``json``, ezdxf, numpy for XYZ), :data:`OPEN3D` Open3D 0.20's
``read_point_cloud`` / ``read_triangle_mesh`` for the formats it reads (PLY, OBJ, XYZ, STL, OFF,
glTF, PCD).
"""

from __future__ import annotations

import io
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from service.io import read_geometry

# ----------------------------------------------------------------------------- reference readers


@dataclass
class Back:
    """What a reference reader saw: positions, faces, lines (index lists) and colours."""

    points: NDArray[np.float64]
    faces: NDArray[np.int64] | None = None
    lines: list[list[int]] = field(default_factory=list)
    colours: NDArray[np.float64] | None = None
    lonlat: bool = False
    resolution: float = 0.0  # the file's own coordinate step (LAS scale), if coarser than 1e-6
    reads_colours: bool = True  # False: the reader never reads colours (Open3D's XYZ)
    reads_lines: bool = True  # False: the reader reads points only (Open3D's read_point_cloud)


def _ours(name: str) -> Callable[[bytes], Back]:
    def read(data: bytes) -> Back:
        doc = read_geometry(data, name)
        g = doc.geometry
        lines = [pl.indices.tolist() for pl in doc.polylines]
        if doc.standalone_edges is not None:
            lines += [list(e) for e in doc.standalone_edges.tolist()]
        cols = None
        if all(c in doc.attributes for c in ("red", "green", "blue")):
            cols = np.column_stack([doc.attributes[c] for c in ("red", "green", "blue")])
        return Back(g.points, g.faces, lines, cols)

    return read


def _trimesh(kind: str) -> Callable[[bytes], Back]:
    def read(data: bytes) -> Back:
        import trimesh

        loaded = trimesh.load(io.BytesIO(data), file_type=kind, process=False, force="scene")
        geoms = [g for g in loaded.dump(concatenate=False)] if loaded.geometry else []
        assert len(geoms) == 1, f"{kind}: expected one geometry, got {len(geoms)}"
        g = geoms[0]
        faces = np.asarray(g.faces) if hasattr(g, "faces") and len(g.faces) else None
        cols = None
        if kind == "glb":
            vc = getattr(g, "colors", None)
            if vc is None or not len(vc):
                vc = g.visual.vertex_colors if hasattr(g, "visual") else None
            if vc is not None and len(vc) == len(g.vertices):
                cols = np.asarray(vc)[:, :3].astype(np.float64)
        return Back(np.asarray(g.vertices, dtype=np.float64), faces, [], cols)

    return read


def _xyz(data: bytes) -> Back:
    text = data.decode()
    first = text.split(None, 1)[0]
    header = not first.lstrip("+-").replace(".", "", 1).isdigit()  # a header line of names
    table = np.loadtxt(io.StringIO(text), ndmin=2, skiprows=int(header))
    return Back(table[:, :3], colours=table[:, 3:6] if table.shape[1] >= 6 else None)


def _las(data: bytes) -> Back:
    import laspy

    las = laspy.read(io.BytesIO(data))
    pts = np.column_stack([las.x, las.y, las.z]).astype(np.float64)
    names = set(las.point_format.dimension_names)
    cols = None
    if {"red", "green", "blue"} <= names:
        cols = np.column_stack([las.red, las.green, las.blue]).astype(np.float64)
        if cols.max() > 255:  # LAS colours are 16-bit: 8-bit ones are written x 257
            assert np.all(cols % 257 == 0), "16-bit colours that are not 8-bit ones x 257"
            cols = cols / 257
    return Back(pts, colours=cols, resolution=float(np.max(las.header.scales)) / 2)


def _pcd(data: bytes) -> Back:
    import pypcd4

    with tempfile.NamedTemporaryFile(suffix=".pcd") as fh:
        fh.write(data)
        fh.flush()
        pc = pypcd4.PointCloud.from_path(fh.name)
    pts = pc.numpy(("x", "y", "z")).astype(np.float64)
    cols = None
    if "rgb" in pc.fields:
        cols = pypcd4.PointCloud.decode_rgb(pc.numpy(("rgb",))[:, 0]).astype(np.float64)
    return Back(pts, colours=cols)


def _e57(data: bytes) -> Back:
    import pye57

    with tempfile.NamedTemporaryFile(suffix=".e57") as fh:
        fh.write(data)
        fh.flush()
        e57 = pye57.E57(fh.name)
        raw = e57.read_scan(0, ignore_missing_fields=True, colors=True, transform=True)
        e57.close()
    pts = np.column_stack([raw[c] for c in ("cartesianX", "cartesianY", "cartesianZ")])
    cols = None
    if "colorRed" in raw:
        cols = np.column_stack([raw[c] for c in ("colorRed", "colorGreen", "colorBlue")])
    return Back(pts.astype(np.float64), colours=None if cols is None else cols.astype(float))


def _gpx(data: bytes) -> Back:
    import gpxpy

    gpx = gpxpy.parse(data.decode())
    rows, lines = [], []
    for trk in gpx.tracks:
        for seg in trk.segments:
            lines.append(list(range(len(rows), len(rows) + len(seg.points))))
            rows += [(p.longitude, p.latitude, p.elevation) for p in seg.points]
    return Back(np.asarray(rows, dtype=np.float64), lines=lines, lonlat=True)


def _geojson(data: bytes) -> Back:
    obj = json.loads(data)
    rows: list[list[float]] = []
    lines = []
    for feature in obj["features"]:
        coords = feature["geometry"]["coordinates"]
        assert feature["geometry"]["type"] == "LineString"
        lines.append(list(range(len(rows), len(rows) + len(coords))))
        rows += coords
    return Back(np.asarray(rows, dtype=np.float64), lines=lines, lonlat=True)


def _dxf(data: bytes) -> Back:
    import ezdxf

    doc = ezdxf.read(io.StringIO(data.decode()))
    rows: list[Any] = []
    faces = None
    lines = []
    for e in doc.modelspace():
        kind = e.dxftype()
        if kind == "MESH":
            faces = np.asarray([list(f) for f in e.faces], dtype=np.int64) + len(rows)
            rows += [tuple(v) for v in e.vertices]
        elif kind == "POINT":
            rows.append(tuple(e.dxf.location))
        elif kind in ("LWPOLYLINE", "POLYLINE"):
            pts = (
                [(x, y, e.dxf.elevation) for x, y in e.get_points("xy")]
                if kind == "LWPOLYLINE"
                else [tuple(v.dxf.location) for v in e.vertices]
            )
            lines.append(list(range(len(rows), len(rows) + len(pts))))
            rows += pts
        else:
            raise AssertionError(f"unexpected DXF entity {kind}")
    return Back(np.asarray(rows, dtype=np.float64), faces, lines)


def _ply(data: bytes) -> Back:
    try:
        import plyfile
    except ImportError:
        return _ours("ply")(data)
    ply = plyfile.PlyData.read(io.BytesIO(data))
    v = ply["vertex"]
    pts = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    faces = None
    if "face" in ply and len(ply["face"].data):
        faces = np.vstack(ply["face"].data["vertex_indices"]).astype(np.int64)
    names = set(v.data.dtype.names or ())
    cols = None
    if {"red", "green", "blue"} <= names:
        cols = np.column_stack([v["red"], v["green"], v["blue"]]).astype(np.float64)
    lines = []
    if "edge" in ply:
        ends = zip(ply["edge"]["vertex1"], ply["edge"]["vertex2"], strict=True)
        lines = [[int(a), int(b)] for a, b in ends]
    return Back(pts, faces, lines, cols)


def _obj(data: bytes) -> Back:
    ours = _ours("obj")(data)
    if ours.faces is None:  # trimesh drops OBJ 'l' lines and keeps no lone vertices
        return ours
    ref = _trimesh("obj")(data)
    return Back(ref.points, ref.faces, ours.lines)


#: The library people use to read each format (geosmooth's reader where none is listed).
READERS: dict[str, Callable[[bytes], Back]] = {
    "ply": _ply,
    "obj": _obj,
    "xyz": _xyz,
    "stl": _trimesh("stl"),
    "off": _trimesh("off"),
    "glb": _trimesh("glb"),
    "las": _las,
    "laz": _las,
    "pcd": _pcd,
    "e57": _e57,
    "gpx": _gpx,
    "geojson": _geojson,
    "dxf": _dxf,
}


def _o3d_file(data: bytes, suffix: str, read: Callable[[str], Any]) -> Any:
    with tempfile.NamedTemporaryFile(suffix=suffix) as fh:
        fh.write(data)
        fh.flush()
        return read(fh.name)


def _o3d_cloud(suffix: str) -> Callable[[bytes], Back]:
    def read(data: bytes) -> Back:
        import open3d as o3d

        pc = _o3d_file(data, suffix, o3d.io.read_point_cloud)
        cols = np.asarray(pc.colors) * 255.0 if pc.has_colors() else None
        pts = np.asarray(pc.points, dtype=np.float64)
        return Back(pts, colours=cols, reads_colours=suffix != ".xyz", reads_lines=False)

    return read


def _o3d_mesh(suffix: str) -> Callable[[bytes], Back]:
    def read(data: bytes) -> Back:
        import open3d as o3d

        mesh = _o3d_file(data, suffix, o3d.io.read_triangle_mesh)
        faces = np.asarray(mesh.triangles, dtype=np.int64)
        cols = np.asarray(mesh.vertex_colors) * 255.0 if mesh.has_vertex_colors() else None
        pts = np.asarray(mesh.vertices, dtype=np.float64)
        return Back(pts, faces if len(faces) else None, colours=cols)

    return read


#: Open3D's reader of each format it reads, for meshes and for points (lines: their vertices).
OPEN3D: dict[str, dict[str, Callable[[bytes], Back]]] = {
    "ply": {"mesh": _o3d_mesh(".ply"), "points": _o3d_cloud(".ply")},
    "obj": {"mesh": _o3d_mesh(".obj")},
    "stl": {"mesh": _o3d_mesh(".stl")},
    "off": {"mesh": _o3d_mesh(".off")},
    "glb": {"mesh": _o3d_mesh(".glb")},
    "xyz": {"points": _o3d_cloud(".xyz")},
    "pcd": {"points": _o3d_cloud(".pcd")},
}
