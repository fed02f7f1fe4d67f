"""Folds of a triangle mesh: faces whose normal points against those around them (used by the
tangential step's :func:`~service.core.finish.tangential.unfold` and the shape checks of
:mod:`service.core.checks.guards`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["face_normals", "fold_mask", "folded_faces"]


def face_normals(P: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """Area-weighted normals ``(b - a) x (c - a)`` of the triangles ``F``."""
    a, b, c = (P[F[:, i]] for i in range(3))
    return np.cross(b - a, c - a)


def folded_faces(normals: NDArray[np.float64], F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """Faces whose normal points against the sum of the (area-weighted) normals of the other
    faces around their three corners: a fold of the surface, whichever way it is oriented."""
    vertex = np.zeros((n, 3))
    for i in range(3):
        np.add.at(vertex, F[:, i], normals)
    around = vertex[F[:, 0]] + vertex[F[:, 1]] + vertex[F[:, 2]] - 3.0 * normals
    return np.einsum("ij,ij->i", normals, around) < 0


def fold_mask(points: NDArray[np.float64], F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """:func:`folded_faces` of the mesh ``(points, F)``."""
    return folded_faces(face_normals(points, F), F, n)
