"""Compiled pieces of the data weights for surfaces in 3-D (issue 30; the rules are
:mod:`.robust`'s).

* :func:`neighbours`: each point's ``k`` nearest by the exact grid search of
  :func:`service.core.operator.knn.knn` instead of a k-d tree; its distances tell coincident
  points (a zero distance to the second neighbour), which :mod:`.robust` otherwise looks for with
  ``np.unique(points, axis=0)`` on every run (inputs with coincident points keep that path);
* :func:`isolated_mask`: :func:`service.core.noise.robust.isolated` compiled (the mean
  distances from the ``k``-NN's, their neighbourhood medians, and the graph neighbours'
  coordinate-wise medians only where a bound from the elements says they could matter);
* :func:`local_sigma`: :func:`service.core.noise.uneven.local_sigma` compiled (same numbers);
* the leave-one-out fits are :func:`service.core.noise.fast_fits.leave_one_out`.

Measured (one thread): ``benchmarks/speed/weights_stage.py``, tables in
``benchmarks/speed/results/issue30-weights.md``. Same decisions as the NumPy path (tests).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.noise.estimate import NoiseEstimate, estimate_noise, manifold_dim
from service.core.noise.pointfits import COMPILED_FROM
from service.core.operator.knn import knn, release

__all__ = ["COMPILED_FROM", "isolated_mask", "isolation_distances", "local_sigma", "neighbours"]

Array = NDArray[np.float64]


def neighbours(
    geometry: Geometry,
) -> tuple[NoiseEstimate, int, NDArray[np.int64], Array] | None:
    """The noise estimate, the manifold dimension and each point's ``k + 1`` nearest (itself
    first) with their distances for the compiled path; ``None`` when it does not apply (small,
    not a surface in 3-D, no noise found, coincident points)."""
    if geometry.n < COMPILED_FROM or geometry.dim != 3:
        return None
    est = estimate_noise(geometry)
    d = manifold_dim(geometry)
    if est is None or not est.noise_found or d != 2:
        return None
    dist, nbr = knn(geometry.points, est.k + 1)  # the grid the noise estimate's sample used
    release()
    if np.any(dist[:, 1] == 0.0):
        return None
    return est, d, nbr, dist


def isolated_mask(
    geometry: Geometry,
    nbr: NDArray[np.int64],
    sigma: Array,
    spacings: float,
    noise: float,
    dist: Array | None = None,
) -> NDArray[np.bool_]:
    """:func:`service.core.noise.robust.isolated`: the points whose distance (module docstring)
    exceeds ``spacings`` times their local spacing and ``noise`` times their ``sigma``.

    For meshes and curves the distance to the graph neighbours' coordinate-wise median is
    bounded first in one pass over the elements, without the adjacency: the median lies in the
    neighbours' bounding box, so ``|x_i - c_i|^2 <= sum_a max_j (x_ia - x_ja)^2``; only the
    points whose bound passes both thresholds get their neighbours and the exact median (none
    on a regular mesh).
    """
    P = np.ascontiguousarray(geometry.points, dtype=np.float64)
    nbr = np.ascontiguousarray(nbr, dtype=np.int64)
    if dist is None or dist.shape != nbr.shape:
        dist = np.zeros((0, nbr.shape[1]))
    d, spacing = _isolation(P, nbr, np.ascontiguousarray(dist, dtype=np.float64))
    E = geometry.faces if geometry.faces is not None else geometry.edges
    if E is None:
        return (d > spacings * spacing) & (d > noise * sigma)
    E = np.ascontiguousarray(E, dtype=np.int64)
    with np.errstate(invalid="ignore"):
        # rounding: the median's interpolation and the differences, relative to the coordinates
        slack = 16 * np.finfo(np.float64).eps * float(np.max(np.abs(P), initial=0.0))
        bound = np.sqrt(_box_bound(P, E)) * (1.0 + 1e-9) + slack
        cand = np.flatnonzero((bound > spacings * spacing) & (bound > noise * sigma))
    out = np.zeros(geometry.n, dtype=np.bool_)
    if cand.size:
        slot = np.full(geometry.n, -1, dtype=np.int64)
        slot[cand] = np.arange(cand.size)
        delta = _medians_at(P, E, slot, cand)
        out[cand] = (delta > spacings * spacing[cand]) & (delta > noise * sigma[cand])
    return out


@njit(cache=True)
def _box_bound(P: Array, E: NDArray[np.int64]) -> Array:  # pragma: no cover
    """``sum_a max_j (x_ia - x_ja)^2`` over each vertex's neighbours ``j`` in the elements."""
    n = P.shape[0]
    box = np.zeros((n, 3))
    m = E.shape[1]
    for f in range(E.shape[0]):
        for x in range(m):
            i = E[f, x]
            for y in range(m):
                if x == y:
                    continue
                j = E[f, y]
                for a in range(3):
                    g = (P[i, a] - P[j, a]) ** 2
                    if g > box[i, a]:
                        box[i, a] = g
    out = np.empty(n)
    for i in range(n):
        out[i] = box[i, 0] + box[i, 1] + box[i, 2]
    return out


@njit(cache=True)
def _medians_at(
    P: Array, E: NDArray[np.int64], slot: NDArray[np.int64], cand: NDArray[np.int64]
) -> Array:  # pragma: no cover
    """For the vertices ``cand`` (``slot[v]`` their position, else -1): the distance to the
    coordinate-wise median of their first 32 distinct graph neighbours (``_isolation``'s)."""
    c = cand.size
    ptr = np.zeros(c + 1, dtype=np.int64)
    m = E.shape[1]
    for f in range(E.shape[0]):
        for x in range(m):
            s = slot[E[f, x]]
            if s >= 0:
                ptr[s + 1] += m - 1
    for s in range(c):
        ptr[s + 1] += ptr[s]
    fill = ptr[:-1].copy()
    cols = np.empty(ptr[c], dtype=np.int64)
    for f in range(E.shape[0]):
        for x in range(m):
            s = slot[E[f, x]]
            if s < 0:
                continue
            for y in range(m):
                if x != y:
                    cols[fill[s]] = E[f, y]
                    fill[s] += 1
    delta = np.zeros(c)
    col = np.empty(32)
    for s in range(c):
        a, b = ptr[s], ptr[s + 1]
        row = np.sort(cols[a:b])
        uniq = np.empty(b - a, dtype=np.int64)
        u = 0
        for t in range(b - a):
            if u == 0 or row[t] != uniq[u - 1]:
                uniq[u] = row[t]
                u += 1
        k = min(u, 32)
        if k == 0:
            continue
        i = cand[s]
        dd = 0.0
        for ax in range(3):
            for t in range(k):
                col[t] = P[uniq[t], ax]
            _sort_head(col, k)
            dd += (P[i, ax] - _median_sorted(col, k)) ** 2
        delta[s] = np.sqrt(dd)
    return delta


def isolation_distances(
    geometry: Geometry, nbr: NDArray[np.int64]
) -> tuple[Array, Array, Array | None]:
    """Every distance :func:`isolated_mask` may compare, for every point (no bound): the mean
    distance to the ``k`` nearest, the median of those over them, and for meshes and curves the
    distance to the coordinate-wise median of the first 32 graph neighbours (``None`` for
    clouds). Kept for the job pool's warm-up and the tests."""
    P = np.ascontiguousarray(geometry.points, dtype=np.float64)
    E = geometry.faces if geometry.faces is not None else geometry.edges
    nbr = np.ascontiguousarray(nbr, dtype=np.int64)
    d, spacing = _isolation(P, nbr, np.zeros((0, nbr.shape[1])))
    if E is None:
        return d, spacing, None
    E = np.ascontiguousarray(E, dtype=np.int64)
    _box_bound(P, E[:1])  # compiled with the rest (warm-up)
    every = np.arange(geometry.n, dtype=np.int64)
    return d, spacing, _medians_at(P, E, every, every)


def local_sigma(v: Array, nbr: NDArray[np.int64], nu: int) -> Array:
    """:func:`service.core.noise.uneven.local_sigma` with its row quantiles and row means
    compiled (the same arithmetic in the same order, NumPy's pairwise row sums included, so the
    same numbers; ``log``/``exp`` stay NumPy's)."""
    from service.core.noise.quantiles import chi2
    from service.core.noise.uneven import QUANTILE

    if nbr.shape[1] > 128:  # NumPy sums longer rows in blocks: :func:`_pairwise` is one block
        from service.core.noise.uneven import local_sigma as numpy_rule

        return numpy_rule(v, nbr, nu)
    nbr = np.ascontiguousarray(nbr, dtype=np.int64)
    s2 = _row_quantiles(np.ascontiguousarray(v, dtype=np.float64), nbr, QUANTILE)
    with np.errstate(all="ignore"):
        s2 = s2 / (chi2.ppf(QUANTILE, nu) / nu)
        logs = np.log(np.where(s2 > 0, s2, np.nan))
        for _ in range(2):
            logs = _row_means(logs, nbr)
        return np.sqrt(np.exp(logs))


@njit(cache=True)
def _row_quantiles(v: Array, nbr: NDArray[np.int64], q: float) -> Array:  # pragma: no cover
    """Each row's ``q`` quantile of the finite ``v[nbr]`` (``nan`` for none), as
    ``uneven.row_quantile``."""
    n, kk = nbr.shape
    out = np.empty(n)
    buf = np.empty(kk)
    for i in range(n):
        m = 0
        for t in range(kk):
            x = v[nbr[i, t]]
            if np.isfinite(x):
                buf[m] = x
                m += 1
        if m == 0:
            out[i] = np.nan
            continue
        _sort_head(buf, m)
        pos = q * (m - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, m - 1)
        out[i] = buf[lo] + (pos - lo) * (buf[hi] - buf[lo])
    return out


@njit(cache=True)
def _pairwise(a: Array, m: int) -> float:  # pragma: no cover
    """NumPy's pairwise sum of ``a[:m]`` for ``m <= 128`` (one block: eight partial sums)."""
    if m < 8:
        res = 0.0
        for t in range(m):
            res += a[t]
        return res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    t = 8
    while t < m - m % 8:
        r0, r1, r2, r3 = r0 + a[t], r1 + a[t + 1], r2 + a[t + 2], r3 + a[t + 3]
        r4, r5, r6, r7 = r4 + a[t + 4], r5 + a[t + 5], r6 + a[t + 6], r7 + a[t + 7]
        t += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while t < m:
        res += a[t]
        t += 1
    return res


@njit(cache=True)
def _row_means(logs: Array, nbr: NDArray[np.int64]) -> Array:  # pragma: no cover
    """Each row's sum of the non-``nan`` ``logs[nbr]`` (``nan`` as 0, NumPy's order) over their
    count (``nan`` for none)."""
    n, kk = nbr.shape
    out = np.empty(n)
    buf = np.empty(kk)
    for i in range(n):
        m = 0
        for t in range(kk):
            x = logs[nbr[i, t]]
            if np.isnan(x):
                buf[t] = 0.0
            else:
                buf[t] = x
                m += 1
        out[i] = _pairwise(buf, kk) / m if m > 0 else np.nan
    return out


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
    P: Array, nbr: NDArray[np.int64], dist: Array
) -> tuple[Array, Array]:  # pragma: no cover
    """Each point's mean distance to its ``k`` nearest (``dist``'s rows when it has them) and
    the median of those over them (``np.median``)."""
    n, kk = nbr.shape
    d = np.zeros(n)
    known = dist.shape[0] == n
    for i in range(n):
        acc = 0.0
        for t in range(1, kk):
            if known:
                acc += dist[i, t]
            else:
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
    return d, spacing
