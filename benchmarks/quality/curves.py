"""Curves and curve networks with ground truth, sampled non-uniformly (2-D and 3-D)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from benchmarks import metrics
from benchmarks.quality.shapes import Shape, frame_from_normal

__all__ = ["PolylineDistance", "circle2d", "network2d", "network3d", "trefoil3d"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _curve_frame(tangent: FloatArray) -> FloatArray:
    """Frames whose last column is the tangent, the first ``s - 1`` columns the normal space."""
    t = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    s = t.shape[1]
    if s == 2:
        nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
        return np.stack([nrm, t], axis=2)
    f = frame_from_normal(t)  # column 0 = tangent
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
