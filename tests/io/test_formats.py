"""The formats of issue 11, on files made by peer libraries: read, write back, attribute by
attribute, bit-identical where the format allows it."""

from __future__ import annotations

import io

import numpy as np
import pytest

from service.io import FormatError, read_geometry, sniff_format, write_geometry
from tests.io.io_format_files import (
    dxf_bytes,
    e57_bytes,
    glb_bytes,
    las_bytes,
    mesh,
    off_bytes,
    pcd_bytes,
    stl_bytes,
)


@pytest.mark.parametrize("point_format", [0, 1, 2, 3, 6, 7, 8])
@pytest.mark.parametrize("fmt", ["las", "laz"])
def test_las_every_dimension_kept(point_format: int, fmt: str) -> None:
    laspy = pytest.importorskip("laspy")
    data = las_bytes(point_format, compress=fmt == "laz")
    assert sniff_format(data) == fmt
    doc = read_geometry(data, fmt)
    src = laspy.read(io.BytesIO(data))
    assert doc.geometry.n == len(src.points)
    assert np.array_equal(doc.geometry.points[:, 0], np.asarray(src.x))
    names = [d for d in src.point_format.dimension_names if d not in ("X", "Y", "Z")]
    assert list(doc.attributes) == names
    for name in names:
        assert np.array_equal(doc.attributes[name], np.asarray(src[name])), name
    # unchanged points: every record bit for bit
    same = laspy.read(io.BytesIO(write_geometry(doc, fmt)))
    assert np.array_equal(same.points.array, src.points.array)
    # moved points: X Y Z with the file's scale and offset, every other dimension as it was
    moved = doc.geometry.points + np.array([0.5004, -0.25, 1.0])
    out = laspy.read(io.BytesIO(write_geometry(doc, fmt, moved)))
    assert out.header.point_format.id == point_format
    assert np.array_equal(out.header.scales, src.header.scales)
    assert np.array_equal(out.header.offsets, src.header.offsets)
    assert np.array_equal(out.X, np.round((moved[:, 0] - 650000.0) / 0.001).astype(np.int32))
    for name in names:
        assert np.array_equal(np.asarray(out[name]), np.asarray(src[name])), name
    assert np.isclose(out.header.maxs[2], moved[:, 2].max(), atol=0.005)


def test_las_coordinates_that_no_longer_fit() -> None:
    doc = read_geometry(las_bytes(0, n=100), "las")
    far = doc.geometry.points + np.array([3e6, 0.0, 0.0])  # 3e9 steps of 1 mm > int32
    with pytest.raises(FormatError, match=r"no longer fits the file.s scale 0\.001 and offset"):
        write_geometry(doc, "las", far)


def test_las_from_another_format_gets_a_header(data_dir) -> None:  # type: ignore[no-untyped-def]
    laspy = pytest.importorskip("laspy")
    doc = read_geometry(data_dir / "points_agisoft.xyz")
    out = laspy.read(io.BytesIO(write_geometry(doc, "laz")))
    assert out.header.point_format.id == 2  # red green blue
    assert np.allclose(out.x, doc.geometry.points[:, 0], atol=5e-7)  # 6 decimals kept
    assert np.array_equal(out.red, doc.attributes["red"].astype(np.uint16) * 257)  # 16-bit


@pytest.mark.parametrize("ascii_stl", [False, True])
def test_stl_welded_and_written_per_face(ascii_stl: bool) -> None:
    data = stl_bytes(ascii_stl)
    assert sniff_format(data) == "stl"
    doc = read_geometry(data, "stl")
    m = mesh()
    assert doc.geometry.n == len(m.vertices) and len(doc.geometry.faces) == len(m.faces)
    assert doc.weld is not None and doc.weld.n_original == 3 * len(m.faces)
    if not ascii_stl:
        assert write_geometry(doc, "stl") == data  # header, normals, attribute words
    moved = doc.geometry.points * 2.0
    out = write_geometry(doc, "stl", moved)
    back = read_geometry(out, "stl")
    assert np.allclose(back.geometry.points, moved, atol=1e-5)
    assert np.array_equal(back.geometry.faces, doc.geometry.faces)
    if not ascii_stl:
        assert out[:80] == data[:80] and len(out) == len(data)
        rec = np.frombuffer(out, dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")],
                            offset=84)  # fmt: skip
        assert np.array_equal(rec["a"], np.arange(len(rec)) % 65536)
        cross = np.cross(rec["v"][:, 1] - rec["v"][:, 0], rec["v"][:, 2] - rec["v"][:, 0])
        assert np.allclose(rec["n"], cross / np.linalg.norm(cross, axis=1)[:, None], atol=1e-6)
    unwelded = read_geometry(out, "stl", weld=False)
    assert unwelded.geometry.n == 3 * len(m.faces)


@pytest.mark.parametrize("kind", ["OFF", "COFF", "NOFF"])
def test_off_round_trip(kind: str) -> None:
    data = off_bytes(kind)
    doc = read_geometry(data)
    assert doc.source_format == "off"
    assert write_geometry(doc, "off") == data
    moved = doc.geometry.points + 0.125
    back = read_geometry(write_geometry(doc, "off", moved), "off")
    assert np.allclose(back.geometry.points, moved, atol=5e-7)
    assert np.array_equal(back.geometry.faces, doc.geometry.faces)
    if kind == "COFF":
        assert list(back.attributes) == ["red", "green", "blue", "alpha"]
        for c in back.attributes:
            assert np.array_equal(back.attributes[c], doc.attributes[c])
    if kind == "NOFF":
        assert np.allclose(np.linalg.norm(back.normals, axis=1), 1, atol=1e-5)


def test_glb_keeps_uvs() -> None:
    trimesh = pytest.importorskip("trimesh")
    data = glb_bytes()
    doc = read_geometry(data)
    assert doc.source_format == "glb" and "uv" in doc.attributes
    moved = doc.geometry.points * 3.0
    out = write_geometry(doc, "glb", moved)
    before = trimesh.load(io.BytesIO(data), file_type="glb", process=False, force="scene")
    after = trimesh.load(io.BytesIO(out), file_type="glb", process=False, force="scene")
    g0, g1 = (next(iter(s.geometry.values())) for s in (before, after))
    assert np.array_equal(g0.visual.uv, g1.visual.uv)
    assert np.array_equal(g0.faces, g1.faces)
    assert np.allclose(g1.vertices, np.asarray(g0.vertices) * 3.0, atol=1e-5)


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip(encoding: str) -> None:
    pypcd4 = pytest.importorskip("pypcd4")
    data = pcd_bytes(encoding, with_nan=True)
    assert sniff_format(data) == "pcd"
    doc = read_geometry(data, "pcd")
    assert doc.geometry.n == 500 - 72  # NaN points left out of the geometry
    assert write_geometry(doc, "pcd") == data
    moved = doc.geometry.points * 1.5
    out = write_geometry(doc, "pcd", moved)
    theirs = pypcd4.PointCloud.from_fileobj(io.BytesIO(out))
    ours = pypcd4.PointCloud.from_fileobj(io.BytesIO(data))
    assert len(theirs.pc_data) == 500
    for field in ("rgb", "label"):  # bit for bit, packed colours included
        assert theirs.pc_data[field].tobytes() == ours.pc_data[field].tobytes()
    valid = ~np.isnan(ours.pc_data["x"])
    assert np.all(np.isnan(theirs.pc_data["x"][~valid]))
    assert np.allclose(theirs.pc_data["x"][valid], moved[:, 0], atol=1e-6)


def test_e57_round_trip() -> None:
    data = e57_bytes()
    doc = read_geometry(data)
    assert doc.source_format == "e57" and doc.geometry.n == 780
    assert sorted(doc.attributes) == ["colorBlue", "colorGreen", "colorRed", "intensity"]
    moved = doc.geometry.points + np.array([1.0, -2.0, 0.5])
    back = read_geometry(write_geometry(doc, "e57", moved), "e57")
    assert np.allclose(back.geometry.points, moved, atol=1e-4)  # pye57 writes float32
    for name, values in doc.attributes.items():
        assert np.array_equal(back.attributes[name], values)


def test_dxf_chains_and_replaces() -> None:
    ezdxf = pytest.importorskip("ezdxf")
    data = dxf_bytes()
    doc = read_geometry(data)
    assert doc.source_format == "dxf"
    shapes = sorted((len(p), p.closed) for p in doc.polylines)
    assert shapes[0] == (3, True) and (4, False) in shapes and len(shapes) == 3
    assert write_geometry(doc, "dxf") == data
    moved = doc.geometry.points + 0.25
    out = write_geometry(doc, "dxf", moved)
    drawing = ezdxf.read(io.StringIO(out.decode()))
    kinds = sorted(e.dxftype() for e in drawing.modelspace())
    assert kinds == ["LWPOLYLINE", "LWPOLYLINE", "POLYLINE", "TEXT"]
    chain = [e for e in drawing.modelspace() if e.dxf.layer == "B"]
    assert len(chain) == 1  # two lines and an arc became one polyline on their layer
    back = read_geometry(out, "dxf")
    assert sorted((len(p), p.closed) for p in back.polylines) == shapes
