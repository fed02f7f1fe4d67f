"""``import geosmooth``: smooth() on numpy, trimesh and Open3D objects, read() and write().

Each adapter is checked against the engine called directly on the same arrays (bit-identical
points), so the connectivity it hands over is the right one; the returned object is of the
input's kind, with the input's connectivity and other data, and the input is left unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

import geosmooth
from service.core import Geometry, SmoothingParams
from service.core import smooth as core_smooth

trimesh = pytest.importorskip("trimesh")


def _noisy_sphere(seed: int = 0) -> Any:
    mesh = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(seed)
    mesh.vertices = mesh.vertices + rng.normal(0, 0.01, mesh.vertices.shape)
    return mesh


def _direct(points: Any, **kw: Any) -> np.ndarray:
    params = {k: v for k, v in kw.items() if k not in ("faces", "edges")}
    geometry = Geometry(np.asarray(points, dtype=float), faces=kw.get("faces"),
                        edges=kw.get("edges"))  # fmt: skip
    return core_smooth(geometry, SmoothingParams(**params)).points


def test_arrays_in_arrays_out() -> None:
    rng = np.random.default_rng(1)
    cloud = rng.normal(size=(200, 3))
    out, result = geosmooth.smooth(cloud, rms=0.05, full_output=True)
    assert isinstance(out, np.ndarray) and out.shape == cloud.shape
    np.testing.assert_array_equal(out, _direct(cloud, rms=0.05))
    assert result.phi == pytest.approx(((out - cloud) ** 2).sum(), rel=1e-9)

    t = np.linspace(0, 4 * np.pi, 100)
    curve = np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, 0.01, (100, 2))
    edges = np.column_stack([np.arange(99), np.arange(1, 100)])
    out = geosmooth.smooth(curve, edges=edges, lam=0.5)
    np.testing.assert_array_equal(out, _direct(curve, edges=edges, lam=0.5))


def test_geometry_and_params_object() -> None:
    mesh = _noisy_sphere(2)
    g = Geometry(mesh.vertices, faces=mesh.faces)
    out = geosmooth.smooth(g, SmoothingParams(tau=0.01), laplacian="feature")
    assert isinstance(out, Geometry)
    np.testing.assert_array_equal(out.faces, g.faces)
    np.testing.assert_array_equal(
        out.points, _direct(mesh.vertices, faces=mesh.faces, tau=0.01, laplacian="feature")
    )


def test_trimesh_objects() -> None:
    mesh = _noisy_sphere(3)
    mesh.visual.vertex_colors = [200, 10, 10, 255]
    before = mesh.vertices.copy()
    out = geosmooth.smooth(mesh, tau=0.01)
    assert isinstance(out, trimesh.Trimesh) and out is not mesh
    np.testing.assert_array_equal(mesh.vertices, before)  # the input is untouched
    np.testing.assert_array_equal(out.faces, mesh.faces)
    np.testing.assert_array_equal(out.vertices, _direct(before, faces=mesh.faces, tau=0.01))
    np.testing.assert_array_equal(out.visual.vertex_colors, mesh.visual.vertex_colors)

    cloud = trimesh.PointCloud(before)
    out_cloud = geosmooth.smooth(cloud, rms=0.005, neighborhood="knn")
    assert isinstance(out_cloud, trimesh.PointCloud)
    np.testing.assert_array_equal(
        out_cloud.vertices, _direct(before, rms=0.005, neighborhood="knn")
    )

    line = trimesh.path.entities.Line(np.arange(40))
    path = trimesh.path.Path3D(entities=[line], vertices=before[:40], process=False)
    out_path = geosmooth.smooth(path, lam=1.0)
    edges = np.column_stack([np.arange(39), np.arange(1, 40)])
    assert type(out_path).__name__ == "Path3D"
    np.testing.assert_array_equal(out_path.vertices, _direct(path.vertices, edges=edges, lam=1.0))


def test_open3d_objects() -> None:
    o3d = pytest.importorskip("open3d")
    mesh = _noisy_sphere(4)
    o3_mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(mesh.vertices), o3d.utility.Vector3iVector(mesh.faces)
    )
    o3_mesh.compute_vertex_normals()
    out = geosmooth.smooth(o3_mesh, tau=0.01)
    assert isinstance(out, o3d.geometry.TriangleMesh)
    smoothed = _direct(mesh.vertices, faces=mesh.faces, tau=0.01)
    np.testing.assert_array_equal(np.asarray(out.vertices), smoothed)
    np.testing.assert_array_equal(np.asarray(out.triangles), mesh.faces)
    fresh = o3d.geometry.TriangleMesh(out.vertices, out.triangles)
    fresh.compute_vertex_normals()  # the normals belong to the smoothed surface
    np.testing.assert_allclose(np.asarray(out.vertex_normals), np.asarray(fresh.vertex_normals))

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(mesh.vertices))
    cloud.normals = o3d.utility.Vector3dVector(mesh.vertices / np.linalg.norm(mesh.vertices,
                                                                              axis=1)[:, None])
    out_cloud = geosmooth.smooth(cloud, rms=0.005)
    new_normals = np.asarray(out_cloud.normals)
    assert np.all(np.sum(new_normals * np.asarray(cloud.normals), axis=1) > 0)  # same side
    np.testing.assert_array_equal(np.asarray(out_cloud.points), _direct(mesh.vertices, rms=0.005))

    lines = o3d.geometry.LineSet(o3d.utility.Vector3dVector(mesh.vertices[:30]),
                                 o3d.utility.Vector2iVector(np.column_stack(
                                     [np.arange(29), np.arange(1, 30)])))  # fmt: skip
    out_lines = geosmooth.smooth(lines, lam=1.0)
    np.testing.assert_array_equal(np.asarray(out_lines.lines), np.asarray(lines.lines))
    np.testing.assert_array_equal(
        np.asarray(out_lines.points),
        _direct(mesh.vertices[:30], edges=np.asarray(lines.lines), lam=1.0),
    )


def test_read_smooth_write_round_trip(tmp_path: Path) -> None:
    mesh = _noisy_sphere(5)
    soup = mesh.vertices[mesh.faces.ravel()]  # STL-style: every face its own three vertices
    src, out = tmp_path / "soup.json", tmp_path / "soup-smooth.ply"
    geosmooth.write(Geometry(soup, faces=np.arange(len(soup)).reshape(-1, 3)), src)
    doc = geosmooth.read(src, weld=True)
    assert doc.geometry.n == len(mesh.vertices)
    geosmooth.write(geosmooth.smooth(doc, tau=0.01), out)
    back = geosmooth.read(out, weld=False).geometry  # as stored
    assert back.n == len(soup)  # the file's vertices, not the welded ones
    expected = _direct(doc.geometry.points, faces=doc.geometry.faces, tau=0.01)
    np.testing.assert_array_equal(back.points, expected[doc.weld.index])  # type: ignore[union-attr]


def test_invalid_input_raises_typed_errors() -> None:
    with pytest.raises(ValidationError):
        geosmooth.smooth(np.zeros((5, 3)), tau=-1)
    with pytest.raises(geosmooth.TauOutOfRange) as info:
        geosmooth.smooth(np.random.default_rng(6).normal(size=(50, 3)), tau=1e9)
    assert info.value.tau_max > 0
    with pytest.raises(TypeError, match="faces= and edges= go with arrays"):
        geosmooth.smooth(_noisy_sphere(), faces=[[0, 1, 2]], tau=0.1)
    with pytest.raises(geosmooth.GeometryError):
        geosmooth.smooth(np.array([[0.0, np.nan, 0.0]] * 4), tau=0.1)


def test_describe_takes_what_smooth_takes() -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(0, 4 * np.pi, 300)
    points = np.c_[np.cos(t), np.sin(t), 0.1 * t] + 0.01 * rng.standard_normal((300, 3))
    edges = np.c_[np.arange(299), np.arange(1, 300)]
    facts = geosmooth.describe(points, edges=edges, weights="uniform", ends="pulled")
    assert (facts["kind"], facts["n_points"], facts["n_edges"]) == ("curve", 300, 299)
    phi0 = float(((points - points.mean(axis=0)) ** 2).sum())  # eq. (14), D = I
    assert np.isclose(facts["phi0"], phi0, rtol=1e-9)  # the report's ends: the centroid
    facts = geosmooth.describe(points, edges=edges, weights="uniform")  # default: ends pinned
    s = np.linspace(0.0, 1.0, 300)[:, None]
    line = float(((points - (points[0] + s * (points[-1] - points[0]))) ** 2).sum())
    assert line * (1 - 1e-3) <= facts["phi0"] <= line  # the segment between the ends
    _, result = geosmooth.smooth(points, edges=edges, full_output=True)
    assert np.isclose(result.tau, facts["suggested_tau"], rtol=1e-9)  # the default budget
