"""Folds of a triangle mesh: faces whose normal points against those around them (used by the
tangential step's :func:`~service.core.finish.tangential.unfold` and the shape checks of
:mod:`service.core.checks.guards`). From :data:`COMPILED_FROM` faces the same
arithmetic runs compiled (:mod:`.mesh_kernels`, identical results)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["COMPILED_FROM", "face_normals", "fold_mask", "folded_faces"]

#: Faces from which the per-face passes run compiled (:mod:`.mesh_kernels`: the fold tests of a
#: 1M-vertex run 1.25 s -> 0.1 s); below it the NumPy expressions (no numba on small inputs).
COMPILED_FROM = 50_000


def _compiled(F: NDArray[np.int64]) -> NDArray[np.int64] | None:
    """``F`` as the kernels take it, or ``None`` below :data:`COMPILED_FROM` faces."""
    if len(F) < COMPILED_FROM:
        return None
    return np.ascontiguousarray(F, dtype=np.int64)


def face_normals(P: NDArray[np.float64], F: NDArray[np.int64]) -> NDArray[np.float64]:
    """Area-weighted normals ``(b - a) x (c - a)`` of the triangles ``F``."""
    Fc = _compiled(F)
    if Fc is not None and P.shape[1] == 3:
        from service.core.finish import mesh_kernels

        return mesh_kernels.face_normals(np.ascontiguousarray(P, dtype=np.float64), Fc)
    a, b, c = (P[F[:, i]] for i in range(3))
    return np.cross(b - a, c - a)


def folded_faces(normals: NDArray[np.float64], F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """Faces whose normal points against the sum of the (area-weighted) normals of the other
    faces around their three corners: a fold of the surface, whichever way it is oriented."""
    Fc = _compiled(F)
    if Fc is not None:
        from service.core.finish import mesh_kernels

        return mesh_kernels.folded(np.ascontiguousarray(normals, dtype=np.float64), Fc, n)
    vertex = np.zeros((n, 3))
    for i in range(3):
        np.add.at(vertex, F[:, i], normals)
    around = vertex[F[:, 0]] + vertex[F[:, 1]] + vertex[F[:, 2]] - 3.0 * normals
    return np.einsum("ij,ij->i", normals, around) < 0


def fold_mask(points: NDArray[np.float64], F: NDArray[np.int64], n: int) -> NDArray[np.bool_]:
    """:func:`folded_faces` of the mesh ``(points, F)``."""
    return folded_faces(face_normals(points, F), F, n)
