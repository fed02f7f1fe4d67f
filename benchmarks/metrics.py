"""Error measures: distance to ground truth, deviation from the input, volume change."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from service.core.finish.volume import enclosed_measure

__all__ = [
    "SurfaceDistance",
    "box_distance",
    "measure_change",
    "rms",
    "rms_deviation",
    "sphere_distance",
    "torus_distance",
]

FloatArray = NDArray[np.float64]


def rms(values: FloatArray) -> float:
    """Root mean square of ``values``."""
    return float(np.sqrt(np.mean(np.square(values))))


def rms_deviation(X: FloatArray, P: FloatArray) -> float:
    """RMS of ``||x_i - p_i||``."""
    return float(np.sqrt(np.mean(np.sum((X - P) ** 2, axis=1))))


def sphere_distance(X: FloatArray) -> FloatArray:
    """Distance to the unit sphere (or unit circle in 2D)."""
    return np.abs(np.linalg.norm(X, axis=1) - 1.0)


def torus_distance(X: FloatArray, R: float, r: float) -> FloatArray:
    """Distance to the torus with radii ``R`` (centre circle in the xy-plane) and ``r``."""
    q = np.hypot(np.hypot(X[:, 0], X[:, 1]) - R, X[:, 2])
    return np.abs(q - r)


def box_distance(X: FloatArray, half: float) -> FloatArray:
    """Distance to the surface of the axis-aligned cube ``[-half, half]^3``."""
    q = np.abs(X) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    return np.abs(outside + inside)


class SurfaceDistance:
    """Distance of points to a reference triangle mesh.

    Candidate triangles are the ``k`` whose centroids are nearest (KD-tree); the exact
    point-triangle distance is taken over those. With triangles of similar size (as in the
    reference scans) this equals the true closest-point distance except in rare corner cases.

    Parameters
    ----------
    vertices : ndarray, shape (m, 3)
    faces : ndarray, shape (f, 3)
    k : int
        Candidate triangles per query point.
    """

    def __init__(self, vertices: FloatArray, faces: NDArray[np.int64], k: int = 12) -> None:
        self.triangles = np.asarray(vertices, dtype=np.float64)[faces]
        centroids = self.triangles.mean(axis=1)
        self.tree = cKDTree(centroids)
        self.sizes = np.maximum(
            np.linalg.norm(self.triangles - centroids[:, None], axis=2).max(axis=1), 1e-300
        )
        self.k = k

    def __call__(self, X: FloatArray, chunk: int = 20000) -> FloatArray:
        from trimesh.triangles import closest_point

        out = np.empty(X.shape[0])
        for start in range(0, X.shape[0], chunk):
            Q = X[start : start + chunk]
            _, idx = self.tree.query(Q, k=self.k)
            pts = np.repeat(Q, self.k, axis=0)
            # trimesh's tolerances are absolute: work in coordinates relative to the query
            # point, in units of the triangle's size (small triangles of a mesh in metres
            # were misclassified, giving distances up to 0.2 edge lengths for points inside)
            scale = self.sizes[idx.ravel()][:, None, None]
            tri = (self.triangles[idx.ravel()] - pts[:, None, :]) / scale
            cp = closest_point(tri, np.zeros_like(pts)) * scale[:, :, 0]
            d = np.linalg.norm(cp, axis=1).reshape(-1, self.k)
            out[start : start + chunk] = d.min(axis=1)
        return out


def measure_change(
    X: FloatArray,
    P: FloatArray,
    faces: NDArray[np.int64] | None,
    edges: NDArray[np.int64] | None,
) -> float:
    """Change of enclosed volume (closed mesh) or area (closed 2D polygon), in percent."""
    before = enclosed_measure(P, faces, edges)
    after = enclosed_measure(X, faces, edges)
    return 100.0 * (after - before) / before
