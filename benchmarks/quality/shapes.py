"""Clean shapes with ground truth: positions, normals (or tangents) and a distance function.

Synthetic shapes (spheres, tori at several resolutions, a subdivided box, non-uniformly sampled
curves and curve networks in 2-D and 3-D, point clouds sampled from surfaces) have exact
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

__all__ = ["SHAPES", "PolylineDistance", "Shape", "make_shape", "vertex_normals"]

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


def _frame_from_normal(nrm: FloatArray) -> FloatArray:
    """Frames (n, 3, 3): column 0 the normal, columns 1-2 a tangent basis (vectorised)."""
    helper = np.where(np.abs(nrm[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(nrm, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    return np.stack([nrm, t1, t2], axis=2)


def _curve_frame(tangent: FloatArray) -> FloatArray:
    """Frames whose last column is the tangent, the first ``s - 1`` columns the normal space."""
    t = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    s = t.shape[1]
    if s == 2:
        nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
        return np.stack([nrm, t], axis=2)
    f = _frame_from_normal(t)  # column 0 = tangent
    return np.stack([f[:, :, 1], f[:, :, 2], t], axis=2)


class PolylineDistance:
    """Exact distance to a union of polylines (the true curves, densely sampled)."""

    def __init__(self, segments: FloatArray, k: int = 8) -> None:
        self.a = segments[:, 0]
        self.b = segments[:, 1]
        self.tree = cKDTree(0.5 * (self.a + self.b))
        self.k = min(k, len(self.a))

    def __call__(self, X: FloatArray) -> FloatArray:
        _, idx = self.tree.query(X, k=self.k)
        a, b = self.a[idx], self.b[idx]
        ab = b - a
        t = np.einsum("nks,nks->nk", X[:, None] - a, ab) / np.maximum(
            np.einsum("nks,nks->nk", ab, ab), 1e-300
        )
        cp = a + np.clip(t, 0.0, 1.0)[..., None] * ab
        return np.linalg.norm(cp - X[:, None], axis=2).min(axis=1)


def _segments(
    curve: Callable[[FloatArray], FloatArray], t0: float, t1: float, m: int
) -> FloatArray:
    pts = curve(np.linspace(t0, t1, m + 1))
    return np.stack([pts[:-1], pts[1:]], axis=1)


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
        _frame_from_normal(P.copy()),
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
        _frame_from_normal(nrm),
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
        _frame_from_normal(nrm),
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
        _frame_from_normal(nrm),
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


# --- curves ------------------------------------------------------------------------------------


def _nonuniform(n: int, closed: bool, strength: float = 0.8) -> FloatArray:
    u = np.arange(n) / n if closed else np.linspace(0.0, 1.0, n)
    return u + strength / (2 * np.pi) * np.sin(2 * np.pi * u)


def _curve_shape(
    name: str,
    pts: FloatArray,
    tang: FloatArray,
    edges: IntArray,
    dist: Callable[[FloatArray], FloatArray],
    closed: bool,
    source: str,
) -> Shape:
    h = float(np.linalg.norm(pts[edges[:, 0]] - pts[edges[:, 1]], axis=1).mean())
    s = pts.shape[1]
    return Shape(
        name, pts, None, edges, _curve_frame(tang), s - 1, dist, h, closed=closed, source=source
    )


def circle2d(n: int = 400) -> Shape:
    t = 2 * np.pi * _nonuniform(n, True)
    P = np.stack([np.cos(t), np.sin(t)], -1)
    T = np.stack([-np.sin(t), np.cos(t)], -1)
    i = np.arange(n)
    return _curve_shape(
        "circle 2-D",
        P,
        T,
        np.stack([i, (i + 1) % n], -1),
        metrics.sphere_distance,
        True,
        f"unit circle, {n} points, spacing ratio ~9",
    )


def _chain(start: int, count: int, closed: bool = False) -> IntArray:
    i = np.arange(start, start + count)
    e = np.stack([i[:-1], i[1:]], -1)
    return np.vstack([e, [[i[-1], i[0]]]]) if closed else e


def network2d() -> Shape:
    """A circle with two crossing diameters: junctions of degree 3 (rim) and 4 (centre)."""
    n = 320
    t = 2 * np.pi * _nonuniform(n, True)
    angles = np.pi / 4 + np.pi / 2 * np.arange(4)  # where the diameters meet the rim
    junction = [int(np.argmin(np.abs(np.angle(np.exp(1j * (t - a)))))) for a in angles]
    t[junction] = angles
    rim = np.stack([np.cos(t), np.sin(t)], -1)
    rim_t = np.stack([-np.sin(t), np.cos(t)], -1)
    pts, tang, edges = [rim], [rim_t], [_chain(0, n, True)]
    centre = n
    pts.append(np.zeros((1, 2)))
    tang.append(np.array([[1.0, 0.0]]))
    m = 40
    for j in junction:
        d = rim[j]
        u = _nonuniform(m + 1, False, 0.6)[1:-1]
        seg = u[:, None] * d[None]
        start = sum(len(p) for p in pts)
        pts.append(seg)
        tang.append(np.repeat(d[None], len(seg), 0))
        e = _chain(start, len(seg))
        edges += [e, [[centre, start]], [[start + len(seg) - 1, j]]]
    P = np.vstack(pts)
    E = np.vstack(edges).astype(np.int64)
    dense = [_segments(lambda s: np.stack([np.cos(s), np.sin(s)], -1), 0, 2 * np.pi, 20000)]
    for a in np.pi / 4 + np.pi / 2 * np.arange(2):
        d = np.array([np.cos(a), np.sin(a)])
        u = np.linspace(-1.0, 1.0, 2001)[:, None] * d
        dense.append(np.stack([u[:-1], u[1:]], axis=1))
    return _curve_shape(
        "network 2-D",
        P,
        np.vstack(tang),
        E,
        PolylineDistance(np.vstack(dense)),
        False,
        "circle + 2 diameters (junctions of degree 3 and 4), non-uniform",
    )


def trefoil3d(n: int = 600) -> Shape:
    def f(s: FloatArray) -> FloatArray:
        return np.stack(
            [np.sin(s) + 2 * np.sin(2 * s), np.cos(s) - 2 * np.cos(2 * s), -np.sin(3 * s)], -1
        )

    def df(s: FloatArray) -> FloatArray:
        return np.stack(
            [np.cos(s) + 4 * np.cos(2 * s), -np.sin(s) + 4 * np.sin(2 * s), -3 * np.cos(3 * s)], -1
        )

    t = 2 * np.pi * _nonuniform(n, True)
    return _curve_shape(
        "trefoil 3-D",
        f(t),
        df(t),
        _chain(0, n, True),
        PolylineDistance(_segments(f, 0, 2 * np.pi, 60000)),
        False,
        f"trefoil knot, {n} points, non-uniform",
    )


def network3d() -> Shape:
    """Wire-frame cube (report fig. 11): 12 edges, 8 corners of degree 3, non-uniform."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    pairs = [
        (a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(corners[a] != corners[b]) == 1
    ]
    pts, tang, edges = [corners], [np.zeros((8, 3))], []
    m = 40
    for a, b in pairs:
        u = _nonuniform(m + 1, False, 0.7)[1:-1]
        seg = corners[a] + u[:, None] * (corners[b] - corners[a])
        start = sum(len(p) for p in pts)
        pts.append(seg)
        tang.append(np.repeat((corners[b] - corners[a])[None] / 2, len(seg), 0))
        edges += [[[a, start]], _chain(start, len(seg)), [[start + len(seg) - 1, b]]]
    T = np.vstack(tang)
    T[:8] = [1.0, 1.0, 1.0]  # corners: any direction (noise there is isotropic in effect)
    u = np.linspace(0.0, 1.0, 2001)[:, None, None]
    A, B = corners[[a for a, _ in pairs]], corners[[b for _, b in pairs]]
    line = A[None] + u * (B - A)[None]  # (2001, 12, 3)
    dense = np.stack([line[:-1], line[1:]], axis=2).reshape(-1, 2, 3)
    return _curve_shape(
        "cube wire-frame 3-D",
        np.vstack(pts),
        T,
        np.vstack(edges).astype(np.int64),
        PolylineDistance(dense),
        False,
        "12 cube edges, corners of degree 3",
    )


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
        _frame_from_normal(nrm),
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


SHAPES: dict[str, Callable[[], Shape]] = {
    "sphere-642": lambda: sphere(3),
    "sphere-2.5K": lambda: sphere(4),
    "sphere-10K": lambda: sphere(5),
    "sphere-41K": lambda: sphere(6),
    "torus-1.4K": lambda: torus(60, 24),
    "torus-5.8K": lambda: torus(120, 48),
    "torus-40K": lambda: torus(320, 125),
    "box": box,
    "fandisk": lambda: real_mesh("fandisk.obj", "fandisk"),
    "spot": lambda: real_mesh("spot.obj", "spot", weld=True),
    "bunny": lambda: real_mesh("bun_zipper.ply", "bun_zipper"),
    "horse": lambda: real_mesh("horse.ply", "horse"),
    "circle-2d": circle2d,
    "network-2d": network2d,
    "trefoil-3d": trefoil3d,
    "network-3d": network3d,
    "cloud-sphere": sphere_cloud,
    "cloud-torus": lambda: torus_cloud(10000),
    "cloud-fandisk": lambda: mesh_cloud(
        real_mesh("fandisk.obj", "fandisk"), 10000, "fandisk cloud 10K"
    ),
    "cloud-bunny": lambda: mesh_cloud(
        real_mesh("bun_zipper.ply", "bunny"), 20000, "bunny cloud 20K"
    ),
}

_CACHE: dict[str, Shape] = {}


def make_shape(key: str) -> Shape:
    """The clean shape ``key`` of :data:`SHAPES` (built once per process)."""
    if key not in _CACHE:
        _CACHE[key] = SHAPES[key]()
    return _CACHE[key]
