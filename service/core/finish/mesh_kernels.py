"""Compiled per-face passes of the finish and the shape checks (issue 30: linear and cheap at 1M).

The fold test of :func:`service.core.finish.folds.folded_faces`, the face normals of
:func:`~service.core.finish.folds.face_normals` and the signed volumes of
:func:`service.core.finish.volume.enclosed_measure` each gathered ``(m, 3)`` copies of the
corners per call and summed the vertex normals with ``np.add.at``: 1.25 s for the four fold
tests of a 1M-vertex run, 0.38 s for the two volumes. The kernels below do the same
arithmetic, in the same order, in one loop over the faces (no gathers): their results are
those of the NumPy expressions bit for bit (tests; the dot products in ``np.einsum``'s order
of the three terms), so the callers switch to them from
:data:`service.core.finish.folds.COMPILED_FROM` faces only to keep small inputs free of
numba.

* :func:`face_normals` — ``(b - a) x (c - a)`` per face (``np.cross``'s operation order);
* :func:`folded` — the fold test: vertex sums of the face normals accumulated face by face
  (``np.add.at``'s order, corner 0, then 1, then 2), then the sign of ``n_f . (v_a + v_b + v_c
  - 3 n_f)``;
* :func:`signed_volumes` — ``a . (b x c) / 6`` per face.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["face_normals", "folded", "signed_volumes"]

Array = NDArray[np.float64]
Faces = NDArray[np.int64]


@njit(cache=True)
def face_normals(P: Array, F: Faces) -> Array:  # pragma: no cover
    """``(b - a) x (c - a)`` of every triangle ``F`` (area-weighted normals)."""
    m = F.shape[0]
    out = np.empty((m, 3))
    for f in range(m):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        u0, u1, u2 = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
        v0, v1, v2 = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
        out[f, 0] = u1 * v2 - u2 * v1
        out[f, 1] = u2 * v0 - u0 * v2
        out[f, 2] = u0 * v1 - u1 * v0
    return out


@njit(cache=True)
def folded(N: Array, F: Faces, n: int) -> NDArray[np.bool_]:  # pragma: no cover
    """Faces whose normal ``N[f]`` points against the summed normals of the other faces around
    their corners (:func:`service.core.finish.folds.folded_faces`)."""
    m = F.shape[0]
    vertex = np.zeros((n, 3))
    for i in range(3):
        for f in range(m):
            v = F[f, i]
            vertex[v, 0] += N[f, 0]
            vertex[v, 1] += N[f, 1]
            vertex[v, 2] += N[f, 2]
    out = np.empty(m, dtype=np.bool_)
    for f in range(m):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        d0 = N[f, 0] * (vertex[a, 0] + vertex[b, 0] + vertex[c, 0] - 3.0 * N[f, 0])
        d1 = N[f, 1] * (vertex[a, 1] + vertex[b, 1] + vertex[c, 1] - 3.0 * N[f, 1])
        d2 = N[f, 2] * (vertex[a, 2] + vertex[b, 2] + vertex[c, 2] - 3.0 * N[f, 2])
        out[f] = (d0 + d2) + d1 < 0  # einsum's order of the three products
    return out


@njit(cache=True)
def signed_volumes(P: Array, F: Faces) -> Array:  # pragma: no cover
    """``a . (b x c) / 6`` of every triangle ``F``: the signed volume of its cone from the
    origin (:func:`service.core.finish.volume.enclosed_measure`)."""
    m = F.shape[0]
    out = np.empty(m)
    for f in range(m):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        x0 = P[b, 1] * P[c, 2] - P[b, 2] * P[c, 1]
        x1 = P[b, 2] * P[c, 0] - P[b, 0] * P[c, 2]
        x2 = P[b, 0] * P[c, 1] - P[b, 1] * P[c, 0]
        out[f] = ((P[a, 0] * x0 + P[a, 2] * x2) + P[a, 1] * x1) / 6.0  # einsum's order
    return out
