"""Issue 32 items 1 and 3 on the shared real data: what Open3D and each format's own library read.

* XYZ -> PCD opened in Open3D as all zeros (binary ``F 8``): georeferenced text is now ASCII
  doubles (Open3D, pypcd4: exact), the mug scene float32 binary (float32 keeps its 6 decimals).
* XYZ colour columns -> PLY ``uchar`` (trimesh showed white for ``double`` colours), LAS 16-bit.
* spot.obj -> glTF and PLY keep its 3,225 texture coordinates (trimesh, Open3D), the other
  formats say they drop them.
* A mesh -> LAS writes the vertices with a note (as PDAL and CloudCompare do).
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from service.io import GeometryDocument, read_geometry, write_geometry
from service.io.dispatch import output_notes

RGB = ("red", "green", "blue")


def _doc(data_dir: Path, name: str) -> GeometryDocument:
    return read_geometry(data_dir / name)


def _colours(doc: GeometryDocument) -> NDArray[np.float64]:
    return np.column_stack([doc.attributes[c] for c in RGB]).astype(np.float64)


def _open3d_cloud(data: bytes, suffix: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    o3d = pytest.importorskip("open3d")
    with tempfile.NamedTemporaryFile(suffix=suffix) as fh:
        fh.write(data)
        fh.flush()
        pc = o3d.io.read_point_cloud(fh.name)
    return np.asarray(pc.points), np.asarray(pc.colors) * 255.0


def _pypcd4(data: bytes) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    import pypcd4

    with tempfile.NamedTemporaryFile(suffix=".pcd") as fh:
        fh.write(data)
        fh.flush()
        pc = pypcd4.PointCloud.from_path(fh.name)
    cols = None
    if "rgb" in pc.fields:
        cols = pypcd4.PointCloud.decode_rgb(pc.numpy(("rgb",))[:, 0]).astype(np.float64)
    return pc.numpy(("x", "y", "z")).astype(np.float64), cols


def test_georeferenced_xyz_to_pcd_opens_in_open3d_and_pypcd4(data_dir: Path) -> None:
    doc = _doc(data_dir, "points_agisoft.xyz")  # 6.65e5 / 5.65e6 m, 6 decimals, colours
    data = write_geometry(doc, "pcd")
    assert b"\nSIZE 8 8 8 4\nTYPE F F F U\n" in data and b"\nDATA ascii\n" in data
    pts, cols = _open3d_cloud(data, ".pcd")
    assert np.array_equal(pts, doc.geometry.points)  # was (0, 0, 0) for every point
    np.testing.assert_allclose(cols, _colours(doc), rtol=0, atol=1e-9)
    pts4, cols4 = _pypcd4(data)
    assert np.array_equal(pts4, doc.geometry.points) and cols4 is not None
    assert np.array_equal(cols4, _colours(doc))
    back = read_geometry(data, "pcd")  # and geosmooth's own reader
    assert np.array_equal(back.geometry.points, doc.geometry.points)


def test_mug_scene_to_pcd_is_float32_binary_open3d_reads(data_dir: Path) -> None:
    doc = _doc(data_dir, "table_scene_mug_stereo_textured.xyz")  # 209,280 points, 6 decimals
    data = write_geometry(doc, "pcd")
    assert b"\nSIZE 4 4 4\nTYPE F F F\n" in data and b"\nDATA binary\n" in data
    pts, _ = _open3d_cloud(data, ".pcd")
    assert pts.shape == doc.geometry.points.shape
    err = float(np.max(np.abs(pts - doc.geometry.points)))
    assert err <= 1.2e-7 < 0.25e-6  # float32 at |x| < 2.5: a quarter of the last decimal
    rounded = np.round(pts, 6)  # to the input's decimals: the input's values again
    np.testing.assert_allclose(rounded, doc.geometry.points, rtol=0, atol=1e-12)


def test_xyz_colours_become_ply_uchar(data_dir: Path) -> None:
    import trimesh

    doc = _doc(data_dir, "points_agisoft.xyz")
    data = write_geometry(doc, "ply")
    head = data[: data.index(b"end_header")].decode()
    assert all(f"property uchar {c}" in head for c in RGB)
    cloud = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    assert np.array_equal(np.asarray(cloud.colors)[:, :3], _colours(doc))  # was white
    pts, cols = _open3d_cloud(data, ".ply")
    assert np.array_equal(pts, doc.geometry.points)
    np.testing.assert_allclose(cols, _colours(doc), rtol=0, atol=1e-9)


def _same_textured_vertices(got: NDArray[np.float64], want: NDArray[np.float64]) -> None:
    """The same (position, uv) rows one to one, whatever the order (positions: float32)."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(want).query(got, k=1)
    assert float(np.max(dist)) < 1e-5
    assert len(np.unique(idx)) == len(want) == len(got)


def test_obj_uvs_survive_in_gltf(data_dir: Path) -> None:
    import trimesh

    doc = _doc(data_dir, "spot.obj")
    data = write_geometry(doc, "glb")
    assert not any("texture" in n for n in output_notes(doc, "glb"))  # kept, nothing to say
    ref = trimesh.load(data_dir / "spot.obj", process=False)  # splits at UV seams: 3225
    scene = trimesh.load(io.BytesIO(data), file_type="glb", process=False, force="scene")
    (mesh,) = scene.dump(concatenate=False)
    assert len(mesh.vertices) == len(ref.vertices) == 3225
    _same_textured_vertices(
        np.column_stack([mesh.vertices, mesh.visual.uv]),
        np.column_stack([ref.vertices, ref.visual.uv]),
    )
    o3d = pytest.importorskip("open3d")
    with tempfile.NamedTemporaryFile(suffix=".glb") as fh:
        fh.write(data)
        fh.flush()
        o3mesh = o3d.io.read_triangle_mesh(fh.name)
    assert o3mesh.has_triangle_uvs() and len(o3mesh.triangles) == len(doc.geometry.faces)


@pytest.mark.parametrize("ascii_", [False, True])
def test_obj_uvs_survive_in_ply(data_dir: Path, ascii_: bool) -> None:
    """PLY keeps the 2930 vertices; each face holds its corners' UVs (MeshLab's texcoord)."""
    import trimesh

    doc = _doc(data_dir, "spot.obj")
    data = write_geometry(doc, "ply", ply_ascii=ascii_)
    assert b"property list uchar float texcoord" in data[:1000]
    assert not any("texture" in n for n in output_notes(doc, "ply"))
    ref = trimesh.load(data_dir / "spot.obj", process=False)
    mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    _same_textured_vertices(
        np.column_stack([mesh.vertices, mesh.visual.uv]),
        np.column_stack([ref.vertices, ref.visual.uv]),
    )
    back = read_geometry(data, "ply")
    assert back.geometry.n == 2930 and write_geometry(back, "ply", ply_ascii=ascii_) == data


def test_formats_without_uvs_say_so(data_dir: Path) -> None:
    doc = _doc(data_dir, "spot.obj")
    for fmt in ("stl", "off", "json", "dxf", "las"):
        assert any("3225 UVs not written" in n for n in output_notes(doc, fmt)), fmt


def test_mesh_to_las_writes_the_vertices(data_dir: Path) -> None:
    import laspy

    doc = _doc(data_dir, "spot.obj")
    las = laspy.read(io.BytesIO(write_geometry(doc, "las")))
    pts = np.column_stack([las.x, las.y, las.z])
    half = 0.51 * float(np.max(las.header.scales))
    np.testing.assert_allclose(pts, doc.geometry.points, rtol=0, atol=half)
    assert "LAS keeps no faces: wrote the 2930 vertices as points" in output_notes(doc, "las")


def test_gltf_uvs_survive_in_obj_and_ply(data_dir: Path) -> None:
    """The other way: glTF's per-vertex UVs as OBJ ``vt`` (``f a/a``) and PLY ``s t``."""
    import trimesh

    gltf = read_geometry(write_geometry(_doc(data_dir, "spot.obj"), "glb"), "glb")
    want = np.column_stack([gltf.geometry.points[gltf.weld.index], gltf.attributes["uv"]])  # type: ignore[union-attr]
    for fmt in ("obj", "ply"):
        assert not any("uv" in n for n in output_notes(gltf, fmt)), fmt
        mesh = trimesh.load(io.BytesIO(write_geometry(gltf, fmt)), file_type=fmt, process=False)
        _same_textured_vertices(np.column_stack([mesh.vertices, mesh.visual.uv]), want)


def test_xyz_colours_become_16_bit_las(data_dir: Path) -> None:
    """LAS RGB is 16-bit (the specification): 8-bit colours are written x 257 (255 -> 65535)."""
    import laspy

    doc = _doc(data_dir, "points_agisoft.xyz")
    las = laspy.read(io.BytesIO(write_geometry(doc, "las")))
    cols = np.column_stack([las.red, las.green, las.blue]).astype(np.float64)
    assert np.array_equal(cols, _colours(doc) * 257)
    back = read_geometry(write_geometry(doc, "las"), "las")  # and to PCD: 8-bit again
    pcd = read_geometry(write_geometry(back, "pcd"), "pcd")
    rgb = pcd.attributes["rgb"].view(np.uint32)
    got = np.column_stack([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255]).astype(np.float64)
    assert np.array_equal(got, _colours(doc))
