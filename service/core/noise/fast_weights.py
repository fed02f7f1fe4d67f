"""Compiled pieces of the data weights for surfaces in 3-D (issue 30; the rules are
:mod:`.robust`'s).

* :func:`neighbours`: each point's ``k`` nearest by the exact grid search of
  :func:`service.core.operator.knn.knn` instead of a k-d tree; its distances tell coincident
  points (a zero distance to the second neighbour), which :mod:`.robust` otherwise looks for with
  ``np.unique(points, axis=0)`` on every run (inputs with coincident points keep that path);
* :func:`isolation_distances`: what :func:`service.core.noise.robust.isolated` compares, in one
  compiled pass (the mean distances, their neighbourhood medians, the graph neighbours'
  coordinate-wise medians);
* the leave-one-out fits are :func:`service.core.noise.fast_fits.leave_one_out`.

Measured (164K icosphere, one thread): the factors 2.4-2.9 s -> 0.65 s; 1M torus 12.4 s ->
see ``benchmarks/speed/results``. Same decisions as the NumPy path (tests).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.noise.estimate import NoiseEstimate, estimate_noise, manifold_dim
from service.core.operator.knn import GRID_FROM, knn

__all__ = ["COMPILED_FROM", "isolation_distances", "neighbours"]

Array = NDArray[np.float64]
#: Points from which surfaces in 3-D take the compiled path (below, the NumPy path is as fast
#: and small inputs load no compiled code).
COMPILED_FROM = GRID_FROM


def neighbours(geometry: Geometry) -> tuple[NoiseEstimate, int, NDArray[np.int64]] | None:
    """The noise estimate, the manifold dimension and each point's ``k + 1`` nearest (itself
    first) for the compiled path; ``None`` when it does not apply (small, not a surface in 3-D,
    no noise found, coincident points)."""
    if geometry.n < COMPILED_FROM or geometry.dim != 3:
        return None
    est = estimate_noise(geometry)
    d = manifold_dim(geometry)
    if est is None or not est.noise_found or d != 2:
        return None
    dist, nbr = knn(geometry.points, est.k + 1)
    if np.any(dist[:, 1] == 0.0):
        return None
    return est, d, nbr


def isolation_distances(
    geometry: Geometry, nbr: NDArray[np.int64]
) -> tuple[Array, Array, Array | None]:
    """The distances :func:`service.core.noise.robust.isolated` compares, in one compiled pass:
    each point's mean distance to its ``k`` nearest, the median of those over them
    (``np.median``), and for meshes and curves the distance to the coordinate-wise median of its
    first 32 graph neighbours (``None`` for clouds)."""
    P = np.ascontiguousarray(geometry.points, dtype=np.float64)
    E = geometry.faces if geometry.faces is not None else geometry.edges
    n = geometry.n
    if E is None:
        indptr, cols = np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    else:
        from service.core.operator.kernels import rows_from_pairs

        E = np.asarray(E, dtype=np.int64)
        m = E.shape[1]
        a = np.concatenate([E[:, x] for x in range(m) for y in range(m) if x != y])
        b = np.concatenate([E[:, y] for x in range(m) for y in range(m) if x != y])
        indptr, cols, _ = rows_from_pairs(a, b, n)
    nbr = np.ascontiguousarray(nbr, dtype=np.int64)
    d, spacing, delta = _isolation(P, nbr, indptr, cols, E is not None)
    return d, spacing, (None if E is None else delta)


@njit(cache=True)
def _sort_head(b: Array, m: int) -> None:  # pragma: no cover
    """Insertion sort of ``b[:m]`` in place (rows of ~12 values)."""
    for p in range(1, m):
        x = b[p]
        q = p - 1
        while q >= 0 and b[q] > x:
            b[q + 1] = b[q]
            q -= 1
        b[q + 1] = x


@njit(cache=True)
def _median_sorted(b: Array, m: int) -> float:  # pragma: no cover
    """``robust.row_quantile(., 0.5)`` of the first ``m`` (sorted) values."""
    pos = 0.5 * (m - 1)
    lo = int(np.floor(pos))
    hi = min(lo + 1, m - 1)
    return b[lo] + (pos - lo) * (b[hi] - b[lo])


@njit(cache=True)
def _isolation(
    P: Array,
    nbr: NDArray[np.int64],
    indptr: NDArray[np.int64],
    cols: NDArray[np.int64],
    graph: bool,
) -> tuple[Array, Array, Array]:  # pragma: no cover
    """Mean distance to the ``k`` nearest, its median over them (``np.median``), and the
    distance to the coordinate-wise median of the first 32 graph neighbours."""
    n, kk = nbr.shape
    d = np.zeros(n)
    for i in range(n):
        acc = 0.0
        for t in range(1, kk):
            j = nbr[i, t]
            acc += np.sqrt((P[j, 0] - P[i, 0]) ** 2 + (P[j, 1] - P[i, 1]) ** 2
                           + (P[j, 2] - P[i, 2]) ** 2)  # fmt: skip
        d[i] = acc / max(kk - 1, 1)
    spacing = np.zeros(n)
    buf = np.empty(max(kk - 1, 1))
    for i in range(n):
        for t in range(1, kk):
            buf[t - 1] = d[nbr[i, t]]
        _sort_head(buf, kk - 1)
        h = (kk - 1) // 2
        spacing[i] = buf[h] if (kk - 1) % 2 else 0.5 * (buf[h - 1] + buf[h])
    delta = np.zeros(n)
    if not graph:
        return d, spacing, delta
    col = np.empty(32)
    for i in range(n):
        m = min(indptr[i + 1] - indptr[i], 32)
        if m == 0:
            continue
        dd = 0.0
        for a in range(3):
            for t in range(m):
                col[t] = P[cols[indptr[i] + t], a]
            _sort_head(col, m)
            c = _median_sorted(col, m)
            dd += (P[i, a] - c) ** 2
        delta[i] = np.sqrt(dd)
    return d, spacing, delta
