"""The data weights' factors with compiled kernels (issue 30; same rules as :mod:`.robust`).

:func:`factors` returns what ``robust._factors`` returns (``rho``, ``sigma_i / sigma``, the
outliers, the rule applied, whether the noise weights apply, the spread), computed the same way
for surfaces in 3-D with three costs replaced:

* neighbours: the exact grid ``k``-NN of :func:`service.core.operator.knn.knn` instead of a k-d
  tree, and coincident points detected from its distances (a zero distance to the second
  neighbour) instead of ``np.unique(points, axis=0)`` on every run (inputs with coincident points
  take the NumPy path, which measures them once);
* the leave-one-out fits: :func:`service.core.search.fast_fits.leave_one_out`;
* isolated points: one compiled pass (:func:`isolated`) for the mean distances, their
  neighbourhood medians and the graph neighbours' coordinate-wise medians.

Everything else (the calibration, outlier flags and refits, ``sigma_i``, the rules) is
:mod:`.robust`'s own code. Other inputs (curves, other dimensions, small inputs) take the
NumPy path unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.stats import chi2

from service.core.geometry import Geometry
from service.core.operator.knn import GRID_FROM, knn
from service.core.search import robust
from service.core.search.fast_fits import leave_one_out
from service.core.search.noise import estimate_noise, manifold_dim

__all__ = ["factors", "isolated"]

Array = NDArray[np.float64]
Factors = tuple[Array, Array, NDArray[np.int64], str, bool, float]


def factors(geometry: Geometry, rule: str, uneven: str) -> Factors | None:
    """``robust._factors(geometry, rule, uneven)`` with the compiled kernels (module
    docstring)."""
    P = geometry.points
    fallback = getattr(robust, "_factors")  # noqa: B009 (the NumPy path, same answers)
    if geometry.n < GRID_FROM or geometry.dim != 3:
        return fallback(geometry, rule, uneven)
    est = estimate_noise(geometry)
    d = manifold_dim(geometry)
    if est is None or not est.noise_found or d != 2:
        return fallback(geometry, rule, uneven)
    dist, nbr = knn(P, est.k + 1)
    if np.any(dist[:, 1] == 0.0):  # coincident points: measured once on the NumPy path
        return fallback(geometry, rule, uneven)
    r, v = leave_one_out(P, nbr, d)
    c = geometry.dim - d
    nu = max(c * (nbr.shape[1] - 1 - (1 + d + d * (d + 1) // 2)), 1)
    s2 = np.full(geometry.n, est.sigma**2) * _calibration(r, est.sigma**2, c)
    _, r, v = robust.flag_outliers(P, nbr, d, r, v, s2, nu)
    sig = robust.local_sigma(v, nbr, nu)
    finite = np.isfinite(sig) & (sig > 0)
    spread = (
        float(np.subtract(*np.quantile(np.log(sig[finite]), [0.9, 0.1]))) if finite.any() else 0.0
    )
    clean = est.scale_ratio is None or est.scale_ratio <= robust.SHAPE_FREE
    use_uneven = uneven == "local" or (uneven == "auto" and spread > robust.SPREAD and clean)
    ratio = np.where(finite, sig, est.sigma) / est.sigma if use_uneven else np.ones(geometry.n)
    ratio = np.clip(ratio, 0.05, 20.0)
    s2 = (est.sigma * ratio) ** 2
    far = isolated(geometry, nbr, np.sqrt(s2))
    rho, outliers, applied = robust.robust_weights(
        P, d, r, v, s2 * _calibration(r, s2, c), nu, rule, far
    )
    return rho, ratio, outliers, applied, use_uneven, spread


def _calibration(r: Array, s2: Array | float, c: int) -> float:
    return float(getattr(robust, "_calibration")(r, s2, c))  # noqa: B009


def isolated(geometry: Geometry, nbr: NDArray[np.int64], sigma: Array) -> NDArray[np.bool_]:
    """:func:`service.core.search.robust.isolated` in one compiled pass (same rule)."""
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
    d, spacing, delta = _isolation(P, np.ascontiguousarray(nbr, dtype=np.int64), indptr, cols,
                                   E is not None)  # fmt: skip
    z0 = float(np.sqrt(chi2.isf(robust.ALPHA, 1)))
    if E is None:
        return (d > robust.ISOLATION * spacing) & (d > 2 * z0 * sigma)
    return (delta > robust.ISOLATION * spacing) & (delta > 2 * z0 * sigma)


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
