"""Volume and area preservation by rescaling about the centroid (report sections 8-9).

Laplacian smoothing shrinks closed shapes. As suggested by Desbrun et al. (report [3]) the
smoothed points are scaled about their centroid so that the enclosed volume (closed triangle
meshes in 3D) or area (closed polygons in 2D) equals that of the input.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from service.core._arrays import unique_keys
from service.core.errors import ParameterError
from service.core.geometry import Geometry
from service.core.operator.neighborhoods import unique_faces

__all__ = [
    "check_preservable",
    "enclosed_measure",
    "is_closed_curve_set",
    "is_closed_mesh",
    "preserve_measure",
    "rescale_to_measure",
]


def is_closed_mesh(faces: NDArray[np.int64]) -> bool:
    """Every (undirected) edge is shared by exactly two faces."""
    a = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]]).astype(np.int64)
    b = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]]).astype(np.int64)
    n = int(max(a.max(), b.max())) + 1 if a.size else 1
    _, _, counts, _ = unique_keys(np.minimum(a, b) * n + np.maximum(a, b))
    return bool(np.all(counts == 2))


def is_closed_curve_set(edges: NDArray[np.int64], n: int) -> bool:
    """Every vertex on an edge has degree two (a union of closed polygons)."""
    deg = np.bincount(edges.ravel(), minlength=n)
    return bool(np.all((deg == 0) | (deg == 2)))


def _component_labels(pairs: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    g = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


def enclosed_measure(
    points: NDArray[np.float64],
    faces: NDArray[np.int64] | None = None,
    edges: NDArray[np.int64] | None = None,
) -> float:
    """Enclosed volume of closed meshes (3D) or area of closed polygons (2D), summed over parts.

    Parameters
    ----------
    points : ndarray, shape (n, 3) or (n, 2)
    faces : ndarray, shape (m, 3), optional
        Consistently wound closed triangle mesh.
    edges : ndarray, shape (k, 2), optional
        Directed edges of closed polygons, each polygon consistently oriented.

    Returns
    -------
    float
        Sum over connected components of the absolute signed volume or area.
    """
    n = points.shape[0]
    if faces is not None:
        a, b, c = (points[faces[:, i]] for i in range(3))
        signed = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
        labels = _component_labels(faces[:, :2], n)[faces[:, 0]]
    else:
        assert edges is not None
        a, b = points[edges[:, 0]], points[edges[:, 1]]
        signed = (a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]) / 2.0
        labels = _component_labels(edges, n)[edges[:, 0]]
    per = np.bincount(labels, weights=signed).astype(np.float64) if labels.size else np.zeros(0)
    return float(np.abs(per).sum())


def rescale_to_measure(
    X: NDArray[np.float64],
    referenced: NDArray[np.bool_],
    target: float,
    current: float,
    dim: int,
) -> tuple[NDArray[np.float64], float]:
    """Scale the referenced points about their centroid so the measure becomes ``target``.

    Parameters
    ----------
    X : ndarray, shape (n, s)
    referenced : ndarray of bool, shape (n,)
        Points on a face or edge (others are left as they are).
    target, current : float
        Measure before and after smoothing.
    dim : int
        3 for volume, 2 for area.

    Returns
    -------
    X_scaled : ndarray
    scale : float
    """
    if current <= 0:
        return X, 1.0
    scale = float((target / current) ** (1.0 / dim))
    out = X.copy()
    c = X[referenced].mean(axis=0)
    out[referenced] = c + (X[referenced] - c) * scale
    return out, scale


def check_preservable(geometry: Geometry, fixed: NDArray[np.bool_]) -> None:
    """Preservation needs a closed mesh in 3D or closed polygons in 2D, and no fixed points."""
    ok = False
    if geometry.faces is not None:
        ok = geometry.dim == 3 and is_closed_mesh(unique_faces(geometry.faces))
    elif geometry.edges is not None:
        ok = geometry.dim == 2 and is_closed_curve_set(geometry.edges, geometry.n)
    if not ok:
        raise ParameterError(
            "preserve_volume needs a closed triangle mesh in 3D or closed polygons in 2D",
            field="params.preserve_volume",
        )
    if fixed.any():
        raise ParameterError(
            "preserve_volume cannot be combined with fixed points (rescaling would move them)",
            field="params.preserve_volume",
        )


def preserve_measure(
    geometry: Geometry, X: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float]:
    """Rescale ``X`` so that it encloses the input's volume (3D mesh) or area (2D polygons)."""
    faces = unique_faces(geometry.faces) if geometry.faces is not None else None
    edges = geometry.edges if faces is None else None
    before = enclosed_measure(geometry.points, faces, edges)
    after = enclosed_measure(X, faces, edges)
    referenced = np.zeros(geometry.n, dtype=bool)
    referenced[(faces if faces is not None else edges).ravel()] = True  # type: ignore[union-attr]
    return rescale_to_measure(X, referenced, before, after, geometry.dim)
