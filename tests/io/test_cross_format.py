"""Every (input kind x output format) pair: round-trips through the output format's reference
reader, or is refused before smoothing with a one-line error naming the formats that can hold it.

The pairs come from the registry (:data:`service.io.FORMATS`), so a new format is covered as
soon as it is registered: it is read back with its reference reader from :data:`READERS` (the
library people use for it), or with geosmooth's own reader when it has none listed there.
Inputs are small (<= 50 points) and their coordinates have 6 decimals, so text writers (which keep
the input's digits) are exact to 5e-7; float32-only formats are checked to half a float32 step.
"""

from __future__ import annotations

import io
import itertools
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from service.io import FORMATS, GeometryDocument, read_geometry, write_geometry
from service.io.dispatch import OutputRefused, check_output, input_kinds, is_geographic

# ----------------------------------------------------------------------------- inputs


def _mesh() -> GeometryDocument:
    n = 5
    xs = np.linspace(0.0, 2.0, n)
    X, Y = np.meshgrid(xs, xs)
    v = np.column_stack([X.ravel(), Y.ravel(), 0.1 * np.sin(3 * X.ravel())])
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            faces += [(a, a + 1, a + n + 1), (a, a + n + 1, a + n)]
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    return read_geometry(text.encode(), "obj")


def _polyline() -> GeometryDocument:
    t = np.linspace(0.0, 3.0, 20)
    v = np.column_stack([t, np.sin(t), 0.1 * t])
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
    text += "l " + " ".join(str(i + 1) for i in range(12)) + "\n"
    text += "l " + " ".join(str(i + 1) for i in range(12, 20)) + "\n"
    return read_geometry(text.encode(), "obj")


def _cloud(offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> GeometryDocument:
    rng = np.random.default_rng(7)
    v = rng.random((40, 3)) * 10 + np.asarray(offset)
    c = rng.integers(0, 256, (40, 3))
    rows = zip(v.tolist(), c.tolist(), strict=True)
    text = "x y z red green blue\n" + "".join(
        f"{a:.6f} {b:.6f} {d:.6f} {r} {g} {bl}\n" for (a, b, d), (r, g, bl) in rows
    )
    return read_geometry(text.encode(), "xyz")


def _track() -> GeometryDocument:
    rng = np.random.default_rng(3)
    segs = []
    for s in range(2):
        pts = "".join(
            f'<trkpt lat="{45.38 + 1e-4 * i + 1e-6 * rng.random():.7f}" '
            f'lon="{14.14 + 2e-4 * i + s * 1e-3:.7f}"><ele>{700 + i * 0.5:.1f}</ele></trkpt>'
            for i in range(10)
        )
        segs.append(f"<trkseg>{pts}</trkseg>")
    text = (
        '<?xml version="1.0" encoding="UTF-8"?><gpx version="1.1" creator="test" '
        f'xmlns="http://www.topografix.com/GPX/1/1"><trk>{"".join(segs)}</trk></gpx>'
    )
    return read_geometry(text.encode(), "gpx")


INPUTS: dict[str, Callable[[], GeometryDocument]] = {
    "mesh": _mesh,
    "polyline": _polyline,
    "cloud": _cloud,
    "georeferenced-cloud": lambda: _cloud((665000.0, 5648000.0, 240.0)),
    "gpx-track": _track,
}

WRITABLE = [name for name, f in FORMATS.items() if f.write is not None]


# ----------------------------------------------------------------------------- reference readers


@dataclass
class Back:
    """What a reference reader saw: positions, faces, lines (index lists) and colours."""

    points: NDArray[np.float64]
    faces: NDArray[np.int64] | None = None
    lines: list[list[int]] = field(default_factory=list)
    colours: NDArray[np.float64] | None = None
    lonlat: bool = False


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
    return Back(pts, colours=cols)


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


# ----------------------------------------------------------------------------- checks


def _moved(doc: GeometryDocument) -> NDArray[np.float64]:
    pts = doc.geometry.points
    extent = float(np.max(np.ptp(pts, axis=0)))
    rng = np.random.default_rng(11)
    return pts + rng.normal(0.0, 1e-3 * extent, pts.shape)


def _tolerance(fmt: str, expected: NDArray[np.float64]) -> float:
    spec = FORMATS[fmt]
    if spec.coordinates == "float64":
        return 5.1e-7  # inputs have 6 decimals: text writers keep them, binary ones are exact
    centre = (expected.min(axis=0) + expected.max(axis=0)) / 2
    stored = expected - centre if spec.coordinates == "float32-offset" else expected
    return float(np.spacing(np.float32(np.max(np.abs(stored))))) * 1.01 + 1e-12


def _corners(points: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Face corner positions, each face rotated to start at its smallest corner (sorted rows)."""
    tri = points[faces]
    keys = np.lexsort(tri.reshape(len(tri), -1).T[::-1])
    return tri[keys]


def _edge_set(lines: list[list[int]]) -> set[tuple[int, int]]:
    return {(min(a, b), max(a, b)) for ln in lines for a, b in itertools.pairwise(ln)}


def _expected(doc: GeometryDocument, moved: NDArray[np.float64], lonlat: bool) -> Any:
    if not lonlat:
        return moved
    lon, lat, ele = doc.layout.frame.back(moved)  # type: ignore[attr-defined]
    return np.column_stack([lon, lat, ele])


def _check_round_trip(doc: GeometryDocument, fmt: str, back: Back, moved: NDArray[Any]) -> None:
    kinds = input_kinds(doc)
    expected = _expected(doc, moved, back.lonlat)
    if back.lonlat:  # GPX / GeoJSON: the input's 7 decimals of degrees, 1 of elevation
        assert back.points.shape == expected.shape
        np.testing.assert_allclose(back.points[:, :2], expected[:, :2], rtol=0, atol=5.1e-8)
        np.testing.assert_allclose(back.points[:, 2], expected[:, 2], rtol=0, atol=0.051)
        assert [len(ln) for ln in back.lines] == [len(p) for p in doc.polylines]
        return
    tol = _tolerance(fmt, expected)
    if "mesh" in kinds:
        assert back.faces is not None and len(back.faces) == len(doc.geometry.faces), fmt
        got = _corners(back.points, back.faces)
        want = _corners(expected, np.asarray(doc.geometry.faces))
        np.testing.assert_allclose(got, want, rtol=0, atol=tol, err_msg=fmt)
        return
    assert back.points.shape == expected.shape, fmt
    np.testing.assert_allclose(back.points, expected, rtol=0, atol=tol, err_msg=fmt)
    if "polyline" in kinds:  # the same edges (PLY stores lines as an edge element)
        assert _edge_set(back.lines) == _edge_set([p.indices.tolist() for p in doc.polylines]), fmt
    if "red" in doc.attributes and FORMATS[fmt].keeps("red"):
        colours = np.column_stack([doc.attributes[c] for c in ("red", "green", "blue")])
        assert back.colours is not None, f"{fmt} lost the colours"
        got = back.colours * (255.0 if back.colours.max() <= 1.0 else 1.0)  # OBJ: fractions
        np.testing.assert_allclose(got, colours.astype(np.float64), rtol=0, atol=1e-3)


@pytest.mark.parametrize("fmt", WRITABLE)
@pytest.mark.parametrize("kind", list(INPUTS))
def test_pair_round_trips_or_is_refused(kind: str, fmt: str) -> None:
    doc = INPUTS[kind]()
    moved = _moved(doc)
    try:
        check_output(doc, fmt)
    except OutputRefused as exc:
        text = str(exc)
        assert "\n" not in text and exc.field == "format" and exc.status == 422
        assert text.startswith(f"cannot write {fmt}:") and "instead" in text
        named = text.rsplit("write ", 1)[1].removesuffix(" instead").split(", ")
        assert named and fmt not in named and set(named) <= set(FORMATS)
        for other in named:  # every format named can hold it
            check_output(doc, other)
        spec = FORMATS[fmt]
        assert not input_kinds(doc) <= spec.kinds or (
            spec.geographic_only and not is_geographic(doc)
        ), f"{fmt} refused {kind} for no registered reason: {text}"
        with pytest.raises(OutputRefused):  # every write checks too
            write_geometry(doc, fmt, moved)
        return
    data = write_geometry(doc, fmt, moved)
    back = READERS.get(fmt, _ours(fmt))(data)
    _check_round_trip(doc, fmt, back, moved)


def test_every_writable_format_has_a_reader() -> None:
    """A new format round-trips at least through geosmooth's own reader."""
    for fmt in WRITABLE:
        assert fmt in READERS or FORMATS[fmt].read is not None


def test_output_notes_stay_true() -> None:
    """Notes about kept columns only where true; geographic input written planar says so."""
    from service.io.dispatch import output_notes

    cloud = _cloud()
    assert any(n.startswith("kept 3 extra columns") for n in output_notes(cloud, "ply"))
    notes = output_notes(cloud, "off")
    assert not any(n.startswith("kept") for n in notes)
    assert "OFF keeps no red, green, blue: not written" in notes
    track = _track()
    assert not any("not longitude/latitude" in n for n in output_notes(track, "geojson"))
    assert any("not longitude/latitude" in n for n in output_notes(track, "ply"))
