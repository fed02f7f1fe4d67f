"""Issue 21's new surfaces and clouds, each with exact ground truth (deterministic seeds).

* ``terrain``: a regular grid triangulation (60 x 60) of a smooth random height field
  ``z = f(x, y)`` on the unit square (six sinusoids);
* ``dem``: a DEM-like grid (80 x 80, alternating diagonals) of a rougher, multi-scale terrain
  (twelve sinusoids with amplitudes falling as ``|k|^-1.5``);
* ``hemisphere``: the upper half of an icosphere (open, one boundary circle);
* ``saddle``: ``z = (x^2 - y^2) / 2`` on ``[-1, 1]^2`` sampled on a jittered grid and
  Delaunay-triangulated in the plane (open, irregular triangles);
* ``sphere-irr``: Fibonacci points on the unit sphere jittered along it, triangulated by their
  convex hull (an irregular closed triangulation);
* clouds with a 10:1 density change: the unit sphere (density 10x on ``x > 0``) and the terrain
  (density 10x on ``x > 0.5``), both with a smooth transition of width 0.1.

Height fields' distances are exact: the closest point of the graph is found by projected Newton
iterations on ``(u, v)`` (the domain is the patch, so points beyond its boundary measure to it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, Delaunay, cKDTree

from benchmarks import metrics
from benchmarks.quality.shapes import Shape, _cloud, frame_from_normal, vertex_normals
from benchmarks.shapes import mean_edge_length

__all__ = [
    "HeightField",
    "Helicoid",
    "dem",
    "dense_cloud_sphere",
    "dense_cloud_terrain",
    "helicoid",
    "hemisphere",
    "saddle",
    "sphere_irregular",
    "terrain",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
DENSITY_RATIO = 10.0


class HeightField:
    """``z = f(x, y)`` as a sum of sinusoids ``a sin(k . (x, y) + phase)`` (or a quadric)."""

    def __init__(self, k: FloatArray, a: FloatArray, phase: FloatArray,
                 quad: tuple[float, float] = (0.0, 0.0),
                 box: tuple[float, float] = (0.0, 1.0)) -> None:
        self.k, self.a, self.phase, self.quad, self.box = k, a, phase, quad, box

    def derivatives(self, u: FloatArray, v: FloatArray) -> tuple[FloatArray, ...]:
        """f, fx, fy, fxx, fxy, fyy at the points (u, v)."""
        arg = np.outer(u, self.k[:, 0]) + np.outer(v, self.k[:, 1]) + self.phase
        s, c = np.sin(arg) * self.a, np.cos(arg) * self.a
        kx, ky = self.k[:, 0], self.k[:, 1]
        qx, qy = self.quad
        return (s.sum(1) + 0.5 * (qx * u**2 + qy * v**2), c @ kx + qx * u, c @ ky + qy * v,
                -(s @ kx**2) + qx, -(s @ (kx * ky)), -(s @ ky**2) + qy)

    def normals(self, u: FloatArray, v: FloatArray) -> FloatArray:
        _, fx, fy, *_ = self.derivatives(u, v)
        nrm = np.stack([-fx, -fy, np.ones_like(u)], axis=1)
        return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)

    def __call__(self, X: FloatArray, steps: int = 30) -> FloatArray:
        """Distance of the rows of ``X`` to the graph over the box (projected Newton)."""
        lo, hi = self.box
        u, v = np.clip(X[:, 0], lo, hi), np.clip(X[:, 1], lo, hi)
        for _ in range(steps):
            f, fx, fy, fxx, fxy, fyy = self.derivatives(u, v)
            r = f - X[:, 2]
            gu, gv = (u - X[:, 0]) + r * fx, (v - X[:, 1]) + r * fy
            a, b, d = 1 + fx**2 + r * fxx, fx * fy + r * fxy, 1 + fy**2 + r * fyy
            det = a * d - b * b
            ok = det > 1e-12  # else a gradient step
            du = np.where(ok, (d * gu - b * gv) / np.where(ok, det, 1.0), gu)
            dv = np.where(ok, (a * gv - b * gu) / np.where(ok, det, 1.0), gv)
            # a coordinate the step pushes out of the box stays on its bound; the other one
            # then takes the 1-D Newton step along that edge
            hold_u = ((u <= lo) & (du > 0)) | ((u >= hi) & (du < 0))
            hold_v = ((v <= lo) & (dv > 0)) | ((v >= hi) & (dv < 0))
            du = np.where(hold_v, gu / np.maximum(a, 1e-12), du)
            dv = np.where(hold_u, gv / np.maximum(d, 1e-12), dv)
            du[hold_u], dv[hold_v] = 0.0, 0.0
            u, v = np.clip(u - du, lo, hi), np.clip(v - dv, lo, hi)
        f = self.derivatives(u, v)[0]
        return np.sqrt((u - X[:, 0]) ** 2 + (v - X[:, 1]) ** 2 + (f - X[:, 2]) ** 2)


def _random_field(seed: int, count: int, kmin: float, kmax: float, amp: float,
                  power: float) -> HeightField:
    rng = np.random.default_rng(seed)
    mag = 2 * np.pi * rng.uniform(kmin, kmax, count)
    ang = rng.uniform(0, 2 * np.pi, count)
    k = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=1)
    a = amp * (mag / (2 * np.pi)) ** -power * rng.uniform(0.5, 1.0, count)
    return HeightField(k, a, rng.uniform(0, 2 * np.pi, count))


def _grid_faces(m: int, alternate: bool) -> IntArray:
    i, j = np.meshgrid(np.arange(m - 1), np.arange(m - 1), indexing="ij")
    a = (i * m + j).ravel()
    b, c, d = a + m, a + 1, a + m + 1
    flip = ((i + j) % 2 == 1).ravel() if alternate else np.zeros(a.size, dtype=bool)
    t1 = np.where(flip[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(flip[:, None], np.stack([c, b, d], 1), np.stack([a, d, c], 1))
    return np.vstack([t1, t2]).astype(np.int64)


def _height_shape(name: str, field: HeightField, u: FloatArray, v: FloatArray, F: IntArray,
                  source: str, grid: bool) -> Shape:
    P = np.stack([u, v, field.derivatives(u, v)[0]], axis=1)
    return Shape(name, P, F, None, frame_from_normal(field.normals(u, v)), 1, field,
                 mean_edge_length(P, F), source=source, extra={"grid": grid})


def _grid_uv(m: int) -> tuple[FloatArray, FloatArray]:
    g = np.linspace(0.0, 1.0, m)
    U, V = np.meshgrid(g, g, indexing="ij")
    return U.ravel(), V.ravel()


def terrain(m: int = 60) -> Shape:
    field = _random_field(21, 6, 1.0, 3.0, 0.06, 1.0)
    u, v = _grid_uv(m)
    return _height_shape(f"terrain {m}x{m}", field, u, v, _grid_faces(m, False),
                         f"smooth random height field (6 sinusoids), regular {m}x{m} grid", True)


def dem(m: int = 80) -> Shape:
    field = _random_field(22, 12, 1.0, 6.0, 0.08, 1.5)
    u, v = _grid_uv(m)
    return _height_shape(f"DEM {m}x{m}", field, u, v, _grid_faces(m, True),
                         f"multi-scale terrain (12 sinusoids), DEM grid {m}x{m}", True)


def saddle(m: int = 55, jitter: float = 0.35) -> Shape:
    field = HeightField(np.zeros((0, 2)), np.zeros(0), np.zeros(0), quad=(1.0, -1.0),
                        box=(-1.0, 1.0))
    g = np.linspace(-1.0, 1.0, m)
    U, V = np.meshgrid(g, g, indexing="ij")
    inner = (np.abs(U) < 1) & (np.abs(V) < 1)
    d = jitter * (g[1] - g[0]) * np.random.default_rng(23).uniform(-1, 1, (2, *U.shape))
    u, v = (U + d[0] * inner).ravel(), (V + d[1] * inner).ravel()
    F = Delaunay(np.stack([u, v], 1)).simplices.astype(np.int64)
    return _height_shape("saddle (irregular)", field, u, v, F,
                         f"z = (x^2 - y^2)/2, jittered {m}x{m} grid, Delaunay", False)


def _fibonacci(n: int) -> FloatArray:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    t = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(t), r * np.sin(t), z], axis=1)


def sphere_irregular(n: int = 3000, jitter: float = 0.35) -> Shape:
    P = _fibonacci(n)
    h0 = np.sqrt(4 * np.pi / n)
    P = P + jitter * h0 * np.random.default_rng(24).uniform(-1, 1, P.shape)
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    F = ConvexHull(P).simplices.astype(np.int64)
    fn = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    inward = np.einsum("ij,ij->i", fn, P[F].mean(axis=1)) < 0
    F[inward] = F[inward][:, ::-1]
    return Shape(f"sphere irregular {n / 1000:g}K", P, F, None, frame_from_normal(P.copy()), 1,
                 metrics.sphere_distance, mean_edge_length(P, F), closed=True,
                 source=f"{n} jittered Fibonacci points on the unit sphere, convex hull")


def _cap_distance(z0: float) -> Callable[[FloatArray], FloatArray]:
    rim = np.sqrt(1 - z0**2)

    def dist(X: FloatArray) -> FloatArray:
        r = np.linalg.norm(X, axis=1)
        on_cap = X[:, 2] >= z0 * r
        rho = np.hypot(X[:, 0], X[:, 1])
        to_rim = np.hypot(rho - rim, X[:, 2] - z0)
        return np.where(on_cap, np.abs(r - 1.0), to_rim)

    return dist


def hemisphere(subdivisions: int = 4) -> Shape:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    P0 = np.asarray(s.vertices, dtype=np.float64)
    F0 = np.asarray(s.faces, dtype=np.int64)
    keep = F0[P0[F0].mean(axis=1)[:, 2] > 0]
    used = np.unique(keep)
    remap = np.full(len(P0), -1)
    remap[used] = np.arange(used.size)
    P, F = P0[used], remap[keep]
    return Shape(f"hemisphere {used.size / 1000:.1f}K", P, F, None, frame_from_normal(P.copy()),
                 1, _cap_distance(float(P[:, 2].min())), mean_edge_length(P, F),
                 source=f"upper half of icosphere({subdivisions}) (open, one boundary)")


def _density_weights(t: FloatArray, width: float = 0.1) -> FloatArray:
    """1 on one side, DENSITY_RATIO on the other, smooth over ``width``."""
    return 1.0 + (DENSITY_RATIO - 1.0) / (1.0 + np.exp(-t / width))


def dense_cloud_sphere(n: int = 6000) -> Shape:
    rng = np.random.default_rng(25)
    Q = rng.normal(size=(20 * n, 3))
    Q /= np.linalg.norm(Q, axis=1, keepdims=True)
    w = _density_weights(Q[:, 0])
    Q = Q[rng.uniform(0, DENSITY_RATIO, len(Q)) < w][:n]
    return _cloud(f"sphere cloud 10:1 {n / 1000:g}K", Q, Q.copy(), metrics.sphere_distance,
                  f"{n} points on the unit sphere, density 10x on x > 0")


def dense_cloud_terrain(n: int = 6000) -> Shape:
    field = _random_field(21, 6, 1.0, 3.0, 0.06, 1.0)
    rng = np.random.default_rng(26)
    uv = rng.uniform(0, 1, (20 * n, 2))
    uv = uv[rng.uniform(0, DENSITY_RATIO, len(uv)) < _density_weights(uv[:, 0] - 0.5)][:n]
    u, v = uv[:, 0], uv[:, 1]
    P = np.stack([u, v, field.derivatives(u, v)[0]], axis=1)
    return _cloud(f"terrain cloud 10:1 {n / 1000:g}K", P, field.normals(u, v), field,
                  f"{n} points on the terrain height field, density 10x on x > 0.5")


def mesh_normals_check(shape: Shape) -> float:
    """Largest angle (degrees) between the shape's frame normals and its mesh's vertex normals."""
    assert shape.faces is not None
    c = np.abs(np.einsum("ij,ij->i", vertex_normals(shape.points, shape.faces), shape.normals))
    return float(np.degrees(np.arccos(np.clip(c.min(), 0, 1))))


class Helicoid:
    """Distance to the helicoid patch ``(u cos v, u sin v, c v)``, ``u`` in ``[u0, u1]``, ``v``
    in ``[0, v1]``: the nearest of a dense parameter sample, then projected Newton on
    ``(u, v)`` (points beyond the patch measure to its boundary)."""

    def __init__(self, u0: float, u1: float, v1: float, c: float) -> None:
        self.u0, self.u1, self.v1, self.c = u0, u1, v1, c
        uu, vv = np.meshgrid(np.linspace(u0, u1, 80), np.linspace(0, v1, 1200), indexing="ij")
        self._uv = np.stack([uu.ravel(), vv.ravel()], 1)
        self._tree = cKDTree(self.point(self._uv[:, 0], self._uv[:, 1]))

    def point(self, u: FloatArray, v: FloatArray) -> FloatArray:
        return np.stack([u * np.cos(v), u * np.sin(v), self.c * v], axis=1)

    def normals(self, u: FloatArray, v: FloatArray) -> FloatArray:
        Su = np.stack([np.cos(v), np.sin(v), np.zeros_like(v)], 1)
        Sv = np.stack([-u * np.sin(v), u * np.cos(v), np.full_like(v, self.c)], 1)
        n = np.cross(Su, Sv)
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def __call__(self, X: FloatArray, steps: int = 30) -> FloatArray:
        u, v = self._uv[self._tree.query(X)[1]].T
        lo, hi = np.array([self.u0, 0.0]), np.array([self.u1, self.v1])
        for _ in range(steps):
            cv, sv = np.cos(v), np.sin(v)
            r = self.point(u, v) - X
            Su = np.stack([cv, sv, np.zeros_like(v)], 1)
            Sv = np.stack([-u * sv, u * cv, np.full_like(v, self.c)], 1)
            Suv = np.stack([-sv, cv, np.zeros_like(v)], 1)
            Svv = np.stack([-u * cv, -u * sv, np.zeros_like(v)], 1)
            gu, gv = np.sum(Su * r, 1), np.sum(Sv * r, 1)
            a = np.sum(Su * Su, 1)
            b = np.sum(Su * Sv, 1) + np.sum(r * Suv, 1)
            d = np.sum(Sv * Sv, 1) + np.sum(r * Svv, 1)
            det = a * d - b * b
            ok = (det > 1e-12) & (a > 0) & (d > 0)
            du = np.where(ok, (d * gu - b * gv) / np.where(ok, det, 1.0), gu / np.maximum(a, 1e-12))
            dv = np.where(ok, (a * gv - b * gu) / np.where(ok, det, 1.0),
                          gv / np.maximum(np.sum(Sv * Sv, 1), 1e-12))
            # a coordinate pushed out of the patch stays on its bound; the other one then takes
            # the 1-D Newton step along that boundary
            hold_u = ((u <= lo[0]) & (du > 0)) | ((u >= hi[0]) & (du < 0))
            hold_v = ((v <= lo[1]) & (dv > 0)) | ((v >= hi[1]) & (dv < 0))
            du = np.where(hold_v, gu / np.maximum(a, 1e-12), du)
            dv = np.where(hold_u, gv / np.maximum(d, 1e-12), dv)
            du[hold_u], dv[hold_v] = 0.0, 0.0
            uv = np.clip(np.stack([u - du, v - dv], 1), lo, hi)
            u, v = uv[:, 0], uv[:, 1]
        return np.linalg.norm(self.point(u, v) - X, axis=1)


def helicoid(mu: int = 25, turns: float = 1.25, u0: float = 0.3, c: float = 0.15) -> Shape:
    """A regular ``(u, v)`` grid on the helicoid patch (spacing along ``v`` matched to the mean
    radius), triangulated with one diagonal: open, two straight and two helical boundaries."""
    v1 = 2 * np.pi * turns
    du = (1.0 - u0) / (mu - 1)
    mv = round(v1 * 0.5 * (1.0 + u0) / du) + 1
    field = Helicoid(u0, 1.0, v1, c)
    U, V = np.meshgrid(np.linspace(u0, 1.0, mu), np.linspace(0.0, v1, mv), indexing="ij")
    u, v = U.ravel(), V.ravel()
    P = field.point(u, v)
    i, j = np.meshgrid(np.arange(mu - 1), np.arange(mv - 1), indexing="ij")
    a = (i * mv + j).ravel()
    F = np.vstack([np.stack([a, a + mv, a + mv + 1], 1), np.stack([a, a + mv + 1, a + 1], 1)])
    F = F.astype(np.int64)
    return Shape(f"helicoid {len(P) / 1000:.1f}K", P, F, None,
                 frame_from_normal(field.normals(u, v)), 1, field, mean_edge_length(P, F),
                 source=f"helicoid (u cos v, u sin v, {c} v), u in [{u0}, 1], {turns} turns, "
                 f"{mu}x{mv} grid")
