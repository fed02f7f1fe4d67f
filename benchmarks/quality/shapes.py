"""Clean shapes with ground truth: positions, normals (or tangents) and a distance function.

Synthetic shapes (spheres, tori at several resolutions, a subdivided box, point clouds sampled
from surfaces; curves and curve networks are in :mod:`benchmarks.quality.curves`) have exact
distance functions; the shared real meshes (``fandisk.obj``, ``spot.obj``, ``bun_zipper.ply``,
``horse.ply``) are their own ground truth (distance to the clean triangle mesh). Every generator
is deterministic.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from benchmarks import metrics
from benchmarks.shapes import box_mesh, load_mesh, mean_edge_length, torus_grid

__all__ = [
    "Shape",
    "box",
    "frame_from_normal",
    "mesh_cloud",
    "real_mesh",
    "sphere",
    "sphere_cloud",
    "torus",
    "torus_cloud",
    "vertex_normals",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass
class Shape:
    """A clean shape.

    Attributes
    ----------
    name : str
    points : ndarray, shape (n, s)
        Clean positions (the ground truth of every vertex).
    faces, edges : ndarray or None
        Connectivity; both ``None`` for a point cloud.
    frame : ndarray, shape (n, s, s)
        Orthonormal frame per point: the first ``codim`` columns span the normal space, the
        others the tangent space.
    codim : int
        1 for surfaces in 3-D and curves in 2-D, 2 for curves in 3-D.
    distance : callable
        ``distance(X)``: unsigned distance of each row of ``X`` to the true surface or curve.
    h : float
        Mean spacing (mean edge length; mean nearest-neighbour distance for clouds).
    closed : bool
        Closed mesh in 3-D or closed polygons in 2-D (volume/area change is meaningful).
    sharp : ndarray of bool, shape (n,), optional
        Points near creases and corners (fandisk, box), for the L(f) study.
    """

    name: str
    points: FloatArray
    faces: IntArray | None
    edges: IntArray | None
    frame: FloatArray
    codim: int
    distance: Callable[[FloatArray], FloatArray]
    h: float
    closed: bool = False
    sharp: NDArray[np.bool_] | None = None
    source: str = ""
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    @property
    def kind(self) -> str:
        if self.faces is not None:
            return "mesh"
        return "curve" if self.edges is not None else "cloud"

    @property
    def normals(self) -> FloatArray:
        """Unit normal (surfaces) or first normal (curves) per point."""
        return self.frame[:, :, 0]


def vertex_normals(points: FloatArray, faces: IntArray) -> FloatArray:
    """Area-weighted vertex normals of a triangle mesh (zero for unreferenced vertices)."""
    a, b, c = (points[faces[:, i]] for i in range(3))
    fn = np.cross(b - a, c - a)
    vn = np.zeros_like(points)
    for i in range(3):
        np.add.at(vn, faces[:, i], fn)
    nrm = np.linalg.norm(vn, axis=1, keepdims=True)
    return np.divide(vn, nrm, out=np.zeros_like(vn), where=nrm > 0)


def frame_from_normal(nrm: FloatArray) -> FloatArray:
    """Frames (n, 3, 3): column 0 the normal, columns 1-2 a tangent basis (vectorised)."""
    helper = np.where(np.abs(nrm[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(nrm, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    return np.stack([nrm, t1, t2], axis=2)


# --- surfaces ----------------------------------------------------------------------------------


def sphere(subdivisions: int) -> Shape:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    P = np.asarray(s.vertices, dtype=np.float64)
    F = np.asarray(s.faces, dtype=np.int64)
    return Shape(
        f"sphere {_k(len(P))}",
        P,
        F,
        None,
        frame_from_normal(P.copy()),
        1,
        metrics.sphere_distance,
        mean_edge_length(P, F),
        closed=True,
        source=f"unit icosphere({subdivisions})",
    )


def torus(nu: int, nv: int) -> Shape:
    R, r = 1.0, 0.4
    P, F = torus_grid(nu, nv, R, r)
    ring = P.copy()
    ring[:, 2] = 0.0
    ring *= (R / np.linalg.norm(ring, axis=1))[:, None]
    nrm = (P - ring) / r
    return Shape(
        f"torus {_k(len(P))}",
        P,
        F,
        None,
        frame_from_normal(nrm),
        1,
        lambda X: metrics.torus_distance(X, R, r),
        mean_edge_length(P, F),
        closed=True,
        source=f"torus {nu}x{nv} (R=1, r=0.4)",
    )


def box() -> Shape:
    c = box_mesh(subdivisions=4, sigma=0.0)
    P, F = c.points, c.faces
    assert F is not None
    q = np.abs(P)
    nrm = np.where(q >= q.max(axis=1, keepdims=True) - 1e-12, np.sign(P), 0.0)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    h = mean_edge_length(P, F)
    sharp = np.sort(q, axis=1)[:, 1] > 1.0 - 2.5 * h  # within 2.5 h of an edge
    return Shape(
        "box",
        P,
        F,
        None,
        frame_from_normal(nrm),
        1,
        lambda X: metrics.box_distance(X, 1.0),
        h,
        closed=True,
        sharp=sharp,
        source="box 2x2x2 subdivided 4x (sharp edges)",
    )


def real_mesh(file: str, label: str, weld: bool = False) -> Shape:
    P, F = load_mesh(file, weld=weld)
    nrm = vertex_normals(P, F)
    import trimesh

    closed = bool(trimesh.Trimesh(P, F, process=False).is_watertight)
    shape = Shape(
        label,
        P,
        F,
        None,
        frame_from_normal(nrm),
        1,
        metrics.SurfaceDistance(P, F),
        mean_edge_length(P, F),
        closed=closed,
        source=f"{file} (clean, its own ground truth)",
    )
    if file == "fandisk.obj":
        shape.sharp = _crease_vertices(P, F, shape.h)
    return shape


def _crease_vertices(
    P: FloatArray, F: IntArray, h: float, angle: float = 30.0
) -> NDArray[np.bool_]:
    """Vertices within 2 h of an edge whose dihedral angle exceeds ``angle`` degrees."""
    import trimesh

    m = trimesh.Trimesh(P, F, process=False)
    sharp_edges = m.face_adjacency_edges[m.face_adjacency_angles > np.radians(angle)]
    on = np.zeros(len(P), dtype=bool)
    on[sharp_edges.ravel()] = True
    d, _ = cKDTree(P[on]).query(P)
    return d <= 2.0 * h


# --- point clouds -----------------------------------------------------------------------------


def _cloud(
    name: str,
    P: FloatArray,
    nrm: FloatArray,
    dist: Callable[[FloatArray], FloatArray],
    source: str,
    sharp: NDArray[np.bool_] | None = None,
) -> Shape:
    d, _ = cKDTree(P).query(P, k=2)
    return Shape(
        name,
        P,
        None,
        None,
        frame_from_normal(nrm),
        1,
        dist,
        float(d[:, 1].mean()),
        sharp=sharp,
        source=source,
    )


def sphere_cloud(n: int = 5000) -> Shape:
    P = np.random.default_rng(5).normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    return _cloud(
        f"sphere cloud {_k(n)}",
        P,
        P.copy(),
        metrics.sphere_distance,
        f"{n} uniform random points on the unit sphere",
    )


def mesh_cloud(shape: Shape, n: int, label: str) -> Shape:
    """Uniform random samples of a clean mesh's surface (area-weighted faces, uniform
    barycentric coordinates), with the normals of their faces."""
    assert shape.faces is not None
    tri = shape.points[shape.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(fn, axis=1)
    rng = np.random.default_rng(7)
    fi = rng.choice(len(tri), n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.uniform(size=n)), rng.uniform(size=n)
    t = tri[fi]
    P = (
        (1 - r1)[:, None] * t[:, 0]
        + (r1 * (1 - r2))[:, None] * t[:, 1]
        + (r1 * r2)[:, None] * t[:, 2]
    )
    nrm = fn[fi] / area[fi, None]
    sharp = None
    if shape.sharp is not None:
        sharp = shape.sharp[cKDTree(shape.points).query(P)[1]]
    return _cloud(label, P, nrm, shape.distance, f"{n} uniform samples of {shape.source}", sharp)


def torus_cloud(n: int) -> Shape:
    """Uniform random samples of the analytic torus (R = 1, r = 0.4), by rejection."""
    R, r = 1.0, 0.4
    rng = np.random.default_rng(8)
    u = rng.uniform(0, 2 * np.pi, 4 * n)
    v = rng.uniform(0, 2 * np.pi, 4 * n)
    keep = rng.uniform(0, R + r, 4 * n) < R + r * np.cos(v)  # area element (R + r cos v)
    u, v = u[keep][:n], v[keep][:n]
    nrm = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], -1)
    P = np.stack([R * np.cos(u), R * np.sin(u), np.zeros_like(u)], -1) + r * nrm
    return _cloud(
        f"torus cloud {_k(n)}",
        P,
        nrm,
        lambda X: metrics.torus_distance(X, R, r),
        f"{n} uniform random points on the torus (R=1, r=0.4)",
    )


def _k(n: int) -> str:
    return f"{n / 1000:.1f}K".replace(".0K", "K") if n < 10000 else f"{round(n / 1000)}K"
