"""Normal frames of surfaces in 3-D in closed form (issue 30: 3.7 s -> ~1 s at 1M vertices).

The frames of :func:`service.core.system.displacement.normal_frames` (the direction of least
variance of the ``k`` nearest neighbours after :data:`~.displacement.FRAME_STEPS` averaging
steps) with two costs replaced for one normal direction in 3-D: the neighbours come from the
exact grid search :func:`service.core.operator.knn.knn` instead of a k-d tree, and the normal
from the closed-form eigenvalues of each 3 x 3 covariance and the largest cross product of two
rows of ``C - mu_3 I`` (:func:`service.core.noise.local3.eig3`) instead of a batched
``eigh``. The sign of a normal is arbitrary on both paths (the normal system is invariant
under ``n_i -> -n_i``: ``t_i`` changes sign, ``p_i + n_i t_i`` does not); directions agree to
rounding (tests). :func:`service.core.system.displacement.normal_frames` takes this path for
one normal direction in 3-D at every point, from
:data:`~service.core.system.displacement.COMPILED_FRAMES_FROM` points (the averaging steps are
its own); from as many unknowns :func:`scale_by_normals` forms the normal system's ``A``
(:func:`~service.core.system.displacement.projected_normal_system`).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from service.core.noise.local3 import centred_covariance, eig3
from service.core.operator.knn import knn

__all__ = ["scale_by_normals", "surface_normals"]

Array = NDArray[np.float64]


def surface_normals(X: Array, k: int) -> NDArray[np.float64]:
    """Frames ``(n, 3, 1)`` of every point of the (averaged) surface points ``X`` in 3-D: the
    least-variance direction of each point's ``k`` nearest (itself included)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    _, idx = knn(X, min(k, X.shape[0]))
    return _normals(X, np.ascontiguousarray(idx, dtype=np.int64))[:, :, None]


@njit(cache=True)
def _normals(X: Array, idx: NDArray[np.int64]) -> Array:  # pragma: no cover
    """Unit eigenvector of the smallest eigenvalue of each neighbourhood's covariance."""
    n, k = idx.shape
    out = np.zeros((n, 3))
    for p in range(n):
        _, _, _, c00, c01, c02, c11, c12, c22 = centred_covariance(X, idx[p], k)
        _, _, nx, ny, nz = eig3(c00, c01, c02, c11, c12, c22)
        if nx == ny == nz == 0.0:  # isotropic or empty: any direction (eigh returns e_1)
            nx = 1.0
        out[p, 0], out[p, 1], out[p, 2] = nx, ny, nz
    return out


@njit(cache=True)
def scale_by_normals(
    indptr: NDArray[np.int64], indices: NDArray[np.int32], data: Array, f: Array
) -> None:  # pragma: no cover
    """``A_ij <- A_ij (n_i . n_j)`` in place on a CSR pattern, ``n`` the rows of ``f`` (the
    normal system's ``A`` for one normal direction in 3-D, without the two ``(nnz, 3)`` gathers
    of ``f``; the dot product in ``np.einsum``'s order of the three terms: same numbers)."""
    for i in range(indptr.size - 1):
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            data[p] *= (f[i, 0] * f[j, 0] + f[i, 2] * f[j, 2]) + f[i, 1] * f[j, 1]
