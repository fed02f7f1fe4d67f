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
from service.core.finish import folds
from service.core.geometry import Geometry
from service.core.operator.neighborhoods import unique_faces

__all__ = [
    "check_preservable",
    "edge_counts",
    "enclosed_measure",
    "enclosed_measures",
    "is_closed_curve_set",
    "is_closed_mesh",
    "preserve_measure",
    "rescale_to_measure",
]


def edge_counts(faces: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], ...]:
    """The distinct undirected edges ``(a, b)``, ``a <= b``, of the triangles ``faces`` on
    ``n`` points and how many faces use each: ``(a, b, counts)``, sorted by ``(a, b)``.

    Linear from :data:`~service.core.finish.folds.COMPILED_FROM` faces (a counting sort on
    ``a``, :func:`service.core.operator.kernels.rows_from_pairs`), a sort of keys below.
    """
    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]]).astype(np.int64)
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]]).astype(np.int64)
    a, b = np.minimum(i, j), np.maximum(i, j)
    if len(faces) >= folds.COMPILED_FROM:
        from service.core.operator.kernels import rows_from_pairs

        indptr, cols, mult = rows_from_pairs(a, b, n)
        return np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr)), cols, mult
    uniq, _, counts, _ = unique_keys(a * n + b)
    return uniq // n, uniq % n, counts


def is_closed_mesh(faces: NDArray[np.int64]) -> bool:
    """Every (undirected) edge is shared by exactly two faces."""
    n = int(faces.max()) + 1 if faces.size else 1
    return bool(np.all(edge_counts(faces, n)[2] == 2))


def is_closed_curve_set(edges: NDArray[np.int64], n: int) -> bool:
    """Every vertex on an edge has degree two (a union of closed polygons)."""
    deg = np.bincount(edges.ravel(), minlength=n)
    return bool(np.all((deg == 0) | (deg == 2)))


def _component_labels(pairs: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    g = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


def _signed(
    points: NDArray[np.float64],
    faces: NDArray[np.int64] | None,
    edges: NDArray[np.int64] | None,
) -> NDArray[np.float64]:
    """Signed volume of each face's cone from the origin (3D) or area of each edge's (2D)."""
    if faces is not None:
        if len(faces) >= folds.COMPILED_FROM and points.shape[1] == 3:  # same numbers, no gathers
            from service.core.finish.mesh_kernels import signed_volumes

            return signed_volumes(
                np.ascontiguousarray(points, dtype=np.float64),
                np.ascontiguousarray(faces, dtype=np.int64),
            )
        a, b, c = (points[faces[:, i]] for i in range(3))
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    assert edges is not None
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    return (a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]) / 2.0


def enclosed_measures(
    point_sets: tuple[NDArray[np.float64], ...],
    faces: NDArray[np.int64] | None = None,
    edges: NDArray[np.int64] | None = None,
) -> list[float]:
    """Enclosed volume of closed meshes (3D) or area of closed polygons (2D), summed over parts,
    for each of ``point_sets`` (same connectivity: its parts are found once).

    Parameters
    ----------
    point_sets : tuple of ndarray, each of shape (n, 3) or (n, 2)
    faces : ndarray, shape (m, 3), optional
        Consistently wound closed triangle mesh.
    edges : ndarray, shape (k, 2), optional
        Directed edges of closed polygons, each polygon consistently oriented.

    Returns
    -------
    list of float
        Per point set, the sum over connected components of the absolute signed volume or area.
    """
    n = point_sets[0].shape[0]
    cells = faces if faces is not None else edges
    assert cells is not None
    labels = _component_labels(cells[:, :2], n)[cells[:, 0]]
    out = []
    for points in point_sets:
        signed = _signed(points, faces, edges)
        per = np.bincount(labels, weights=signed).astype(np.float64) if labels.size else signed
        out.append(float(np.abs(per).sum()))
    return out


def enclosed_measure(
    points: NDArray[np.float64],
    faces: NDArray[np.int64] | None = None,
    edges: NDArray[np.int64] | None = None,
) -> float:
    """:func:`enclosed_measures` of one point set."""
    return enclosed_measures((points,), faces, edges)[0]


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
    before, after = enclosed_measures((geometry.points, X), faces, edges)
    referenced = np.zeros(geometry.n, dtype=bool)
    referenced[(faces if faces is not None else edges).ravel()] = True  # type: ignore[union-attr]
    return rescale_to_measure(X, referenced, before, after, geometry.dim)
