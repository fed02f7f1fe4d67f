"""Objects of other libraries as geosmooth geometry, and back to the same kind of object.

:func:`adapt` turns what a caller hands to :func:`geosmooth.smooth` into a
:class:`~service.io.GeometryDocument` plus a function that builds the caller's kind of object
from smoothed points: numpy arrays (points, with ``faces`` / ``edges``), geosmooth's own
``Geometry`` and ``GeometryDocument``, ``trimesh.Trimesh`` / ``PointCloud`` / ``Path2D`` /
``Path3D``, and Open3D's ``TriangleMesh``, ``PointCloud`` and ``LineSet``. trimesh and Open3D are
recognised by their module names, so neither is imported unless the caller passes one of its
objects. The input object is never modified: a copy with the new points is returned, with its
other data (colours, UVs, metadata) kept; normals are recomputed, as ``service.io`` does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from service.core.geometry import Geometry
from service.io import GeometryDocument

__all__ = ["Rebuild", "adapt"]

Rebuild = Callable[[NDArray[np.float64]], Any]


def _library(obj: Any) -> str:
    return type(obj).__module__.split(".")[0]


def adapt(
    obj: Any, *, faces: ArrayLike | None = None, edges: ArrayLike | None = None
) -> tuple[GeometryDocument, Rebuild]:
    """The document to smooth and the function that rebuilds ``obj``'s kind from points.

    Raises
    ------
    TypeError
        For an object of no supported kind (``faces``/``edges`` only go with arrays).
    """
    if isinstance(obj, GeometryDocument):
        _no_connectivity(faces, edges, "a GeometryDocument")
        return obj, obj.with_points
    if isinstance(obj, Geometry):
        _no_connectivity(faces, edges, "a Geometry")
        return GeometryDocument.from_geometry(obj), lambda p: replace(obj, points=p)
    library = _library(obj)
    if library in ("trimesh", "open3d"):
        _no_connectivity(faces, edges, f"a {type(obj).__name__}")
        adapter = _TRIMESH if library == "trimesh" else _OPEN3D
        convert = adapter.get(type(obj).__name__)
        if convert is None:
            raise TypeError(f"geosmooth cannot smooth a {library} {type(obj).__name__}")
        return convert(obj)
    points = np.asarray(obj, dtype=np.float64)
    geometry = Geometry(points, faces=_array(faces), edges=_array(edges))
    return GeometryDocument.from_geometry(geometry), lambda p: np.asarray(p)


def _array(values: ArrayLike | None) -> Any:
    return None if values is None else np.asarray(values)


def _no_connectivity(faces: Any, edges: Any, what: str) -> None:
    if faces is not None or edges is not None:
        raise TypeError(f"faces= and edges= go with arrays of points, not with {what}")


# --------------------------------------------------------------------------- trimesh


def _trimesh_mesh(mesh: Any) -> tuple[GeometryDocument, Rebuild]:
    geometry = Geometry(np.asarray(mesh.vertices, dtype=np.float64), faces=mesh.faces)

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = mesh.copy()
        out.vertices = points  # trimesh drops its cached normals with the old vertices
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


def _trimesh_points(cloud: Any) -> tuple[GeometryDocument, Rebuild]:
    geometry = Geometry(np.asarray(cloud.vertices, dtype=np.float64))

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = cloud.copy()
        out.vertices = points
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


def _trimesh_path(path: Any) -> tuple[GeometryDocument, Rebuild]:
    """Paths of line entities: each entity's consecutive vertices form the edges."""
    segments = [
        np.column_stack([e.points[:-1], e.points[1:]])
        for e in path.entities
        if type(e).__name__ == "Line" and len(e.points) > 1
    ]
    if len(segments) != len(path.entities):
        raise TypeError("geosmooth smooths paths made of line entities only (not arcs, curves)")
    edges = np.concatenate(segments) if segments else None
    geometry = Geometry(np.asarray(path.vertices, dtype=np.float64), edges=edges)

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = path.copy()
        out.vertices = points
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


_TRIMESH = {
    "Trimesh": _trimesh_mesh,
    "PointCloud": _trimesh_points,
    "Path2D": _trimesh_path,
    "Path3D": _trimesh_path,
}


# --------------------------------------------------------------------------- Open3D


def _open3d_mesh(mesh: Any) -> tuple[GeometryDocument, Rebuild]:
    import open3d as o3d

    geometry = Geometry(np.asarray(mesh.vertices), faces=np.asarray(mesh.triangles))

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = o3d.geometry.TriangleMesh(mesh)
        out.vertices = o3d.utility.Vector3dVector(points)
        if mesh.has_vertex_normals():
            out.compute_vertex_normals()
        if mesh.has_triangle_normals():
            out.compute_triangle_normals()
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


def _open3d_points(cloud: Any) -> tuple[GeometryDocument, Rebuild]:
    import open3d as o3d

    geometry = Geometry(np.asarray(cloud.points))

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = o3d.geometry.PointCloud(cloud)
        out.points = o3d.utility.Vector3dVector(points)
        if cloud.has_normals():  # re-estimated, each oriented like the point's old normal
            old = np.asarray(cloud.normals).copy()
            out.estimate_normals()
            new = np.asarray(out.normals)
            flip = np.sum(new * old, axis=1) < 0
            new[flip] *= -1
            out.normals = o3d.utility.Vector3dVector(new)
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


def _open3d_lines(lines: Any) -> tuple[GeometryDocument, Rebuild]:
    import open3d as o3d

    geometry = Geometry(np.asarray(lines.points), edges=np.asarray(lines.lines))

    def rebuild(points: NDArray[np.float64]) -> Any:
        out = o3d.geometry.LineSet(lines)
        out.points = o3d.utility.Vector3dVector(points)
        return out

    return GeometryDocument.from_geometry(geometry), rebuild


_OPEN3D = {
    "TriangleMesh": _open3d_mesh,
    "PointCloud": _open3d_points,
    "LineSet": _open3d_lines,
}
