"""Georeferenced coordinates (~5.6e6 m) survive every writer to the input's own precision.

One input per kind the registry lists, each at UTM magnitudes: ``points_agisoft.xyz`` (a real
photogrammetry cloud, 6 decimals) and synthetic double-precision inputs (a binary PLY mesh, an
OBJ polyline with 6 decimals); ``korita-zbevnica.gpx`` for the geographic formats. Each is
moved by ~1 cm (as smoothing does), written in every format that can hold it, read back by
the format's reference reader (:data:`tests.io.test_cross_format.READERS`), and compared with
what was written:

* text input (6 decimals): within half a unit of the 6th decimal, whatever the format;
* double binary input: bit for bit, except LAS/LAZ (scaled integers: half the scale the writer
  chose, 1e-7 of the extent or finer) and glTF (float32 about the centre: half a float32 step
  of the half-extent);
* float32-only formats (STL) are refused for such input, naming the formats that can hold it.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
import pytest

from service.io import FORMATS, GeometryDocument, read_geometry, write_geometry
from service.io.dispatch import OutputRefused, check_output
from service.io.holds import dropped_kinds
from tests.io.cross_readers import READERS, _ours
from tests.io.test_cross_format import _corners
from tests.shared_data import shared_data_dir

DATA = shared_data_dir()
UTM = np.array([665000.0, 5648000.0, 240.0])


def _agisoft() -> GeometryDocument:
    path = DATA / "points_agisoft.xyz"
    if not path.exists():
        pytest.skip("shared data not found")
    return read_geometry(path)


def _binary_mesh() -> GeometryDocument:
    rng = np.random.default_rng(5)
    n = 6
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n)), -1).reshape(-1, 2) * 3.7
    pts = np.column_stack([g, rng.random(n * n)]) + UTM + rng.random((n * n, 3)) * 1e-3
    faces = [
        (i * n + j, i * n + j + 1, (i + 1) * n + j + 1) for i in range(n - 1) for j in range(n - 1)
    ]
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n"
        "property double x\nproperty double y\nproperty double z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = pts.astype("<f8").tobytes() + b"".join(struct.pack("<Biii", 3, *f) for f in faces)
    return read_geometry(head + body, "ply")


def _polyline() -> GeometryDocument:
    t = np.linspace(0.0, 40.0, 30)
    pts = np.column_stack([t, 3 * np.sin(t / 5), 0.1 * t]) + UTM
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in pts)
    text += "l " + " ".join(str(i + 1) for i in range(len(pts))) + "\n"
    return read_geometry(text.encode(), "obj")


def _track() -> GeometryDocument:
    path = DATA / "korita-zbevnica.gpx"
    if not path.exists():
        pytest.skip("shared data not found")
    return read_geometry(path)


INPUTS = {"agisoft-cloud": _agisoft, "binary-mesh": _binary_mesh, "utm-polyline": _polyline}
WRITABLE = [name for name, f in FORMATS.items() if f.write is not None]


def _positions(fmt: str, data: bytes, faces: np.ndarray | None) -> np.ndarray:
    back = READERS.get(fmt, _ours(fmt))(data)
    if faces is not None:
        assert back.faces is not None
        return _corners(back.points, back.faces)
    return back.points


def _allowed(doc: GeometryDocument, fmt: str, moved: np.ndarray) -> float:
    spec = FORMATS[fmt]
    extent = float(np.max(np.ptp(moved, axis=0)))
    if spec.coordinates == "float32-offset":
        return float(np.spacing(np.float32(extent / 2))) * 0.5 * 1.01
    if doc.precision.text is not None:  # 6 decimals: half a unit of the last one (+ rounding)
        return 0.5e-6 * 1.02
    if fmt in ("las", "laz"):
        return 0.5 * 10.0 ** -np.ceil(-np.log10(1e-7 * extent)) * 1.01
    return 0.0


@pytest.mark.parametrize("fmt", WRITABLE)
@pytest.mark.parametrize("kind", list(INPUTS))
def test_georeferenced_precision(kind: str, fmt: str, record_property: object) -> None:
    doc = INPUTS[kind]()
    moved = doc.geometry.points + np.random.default_rng(2).normal(
        0, 0.01, doc.geometry.points.shape
    )
    try:
        check_output(doc, fmt, moved)
    except OutputRefused as exc:
        if FORMATS[fmt].coordinates == "float32" and "float32" in str(exc):
            assert "instead" in str(exc)
        return  # a kind the format cannot hold: covered by test_cross_format
    assert FORMATS[fmt].coordinates != "float32", f"{fmt} accepted double georeferenced input"
    faces = None if dropped_kinds(doc, FORMATS[fmt]) else doc.geometry.faces  # vertices only
    got = _positions(fmt, write_geometry(doc, fmt, moved), faces)
    want = _corners(moved, faces) if faces is not None else moved
    assert got.shape == want.shape
    err = float(np.max(np.abs(got - want)))
    assert err <= _allowed(doc, fmt, moved), f"{fmt}: {err:.3g}"


@pytest.mark.parametrize("fmt", ["gpx", "geojson"])
def test_geographic_precision(fmt: str) -> None:
    """GPX track -> GPX/GeoJSON: degrees to the input's decimals, elevations to theirs."""
    doc = _track()
    moved = doc.geometry.points + np.random.default_rng(4).normal(0, 0.5, doc.geometry.points.shape)
    back = READERS[fmt](write_geometry(doc, fmt, moved))
    lon, lat, ele = doc.layout.frame.back(moved)  # type: ignore[attr-defined]
    cd, ed = doc.layout.digits  # type: ignore[attr-defined]
    n = len(lon)
    assert back.points.shape[0] == n
    assert np.max(np.abs(back.points[:, 0] - lon)) <= 0.5 * 10.0**-cd * 1.01
    assert np.max(np.abs(back.points[:, 1] - lat)) <= 0.5 * 10.0**-cd * 1.01
    assert np.max(np.abs(back.points[:, 2] - ele)) <= 0.5 * 10.0**-ed * 1.01


def test_e57_from_utm_text_is_double() -> None:
    """The issue's case: ``points_agisoft.xyz -o x.e57`` moved points by up to 0.25 m."""
    doc = _agisoft()
    data = write_geometry(doc, "e57")
    got = READERS["e57"](data).points
    assert np.max(np.abs(got - doc.geometry.points)) == 0.0
    assert io.BytesIO(data).read(8) == b"ASTM-E57"


def test_e57_keeps_its_coordinates_precision(tmp_path: Path) -> None:
    """Issue 41 item 8: a float32 E57 is written back float32 (its size), a double one double."""
    import pye57
    from pye57 import libe57

    def precision(data: bytes) -> object:
        path = tmp_path / "p.e57"
        path.write_bytes(data)
        e57 = pye57.E57(str(path))  # alive while its nodes are read
        proto = libe57.StructureNode(e57.get_header(0).points.prototype())
        found = libe57.FloatNode(proto.get("cartesianX")).precision()
        e57.close()
        return found

    single = tmp_path / "single.e57"
    rng = np.random.default_rng(2)
    writer = pye57.E57(str(single), mode="w")  # pye57 writes E57_SINGLE coordinates
    writer.write_scan_raw({f"cartesian{a}": rng.random(500) for a in "XYZ"})
    writer.close()
    doc = read_geometry(single.read_bytes(), "e57")
    out = write_geometry(doc, "e57", doc.geometry.points + 0.01)
    assert precision(out) == libe57.E57_SINGLE and len(out) == single.stat().st_size
    double = write_geometry(read_geometry(b"500000.123 5000000.456 10.5\n" * 3 + b"1 2 3\n", "xyz"),
                            "e57")  # fmt: skip
    assert precision(double) == libe57.E57_DOUBLE
    again = read_geometry(double, "e57")
    assert precision(write_geometry(again, "e57", again.geometry.points)) == libe57.E57_DOUBLE
