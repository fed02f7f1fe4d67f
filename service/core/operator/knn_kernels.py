"""The compiled loops of :mod:`service.core.operator.knn` (numba; imported only on its grid
path, so that a small input loads no compiled code): the cell lookup, the sorted insertion,
the whole-grid query and the query of a subset of points."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["expand_copies", "grid_query", "query_at"]

Array = NDArray[np.float64]


@njit(cache=True)
def _find(cells: NDArray[np.int64], m: int, key: int) -> int:  # pragma: no cover
    a, b = 0, m
    while a < b:
        mid = (a + b) // 2
        if cells[mid] < key:
            a = mid + 1
        else:
            b = mid
    return a if a < m and cells[a] == key else -1


#: The 26 neighbouring cells' offsets, faces first, then edges, then corners: the k-th distance
#: shrinks before the far cells come, which are then skipped whole.
_OFFSETS = np.array(
    sorted(
        ((dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
         if (dx, dy, dz) != (0, 0, 0)),
        key=lambda o: abs(o[0]) + abs(o[1]) + abs(o[2]),
    ),
    dtype=np.int64,
)  # fmt: skip


@njit(cache=True)
def _insert(
    bd: Array, bi: NDArray[np.int64], filled: int, k: int, dd: float, q: int
) -> int:  # pragma: no cover
    """Insert ``(dd, q)`` into the sorted ``k`` best (ties by index); the new count."""
    if filled == k and (dd > bd[k - 1] or (dd == bd[k - 1] and q > bi[k - 1])):
        return filled
    pos = filled if filled < k else k - 1
    while pos > 0 and (bd[pos - 1] > dd or (bd[pos - 1] == dd and bi[pos - 1] > q)):
        bd[pos], bi[pos] = bd[pos - 1], bi[pos - 1]
        pos -= 1
    bd[pos], bi[pos] = dd, q
    return filled + 1 if filled < k else k


@njit(cache=True)
def grid_query(
    S: Array,
    lo: Array,
    h: float,
    order: NDArray[np.int64],
    starts: NDArray[np.int64],
    cells: NDArray[np.int64],
    k: int,
    dist: Array,
    idx: NDArray[np.int64],
    ok: NDArray[np.bool_],
) -> None:  # pragma: no cover
    """For every occupied cell: its block's runs of candidates (its own cell, then
    :data:`_OFFSETS`' order), then each of its points' ``k`` nearest (sorted by distance, ties
    by index); ``ok`` where the block provably holds them. ``S``: the points in cell order
    (contiguous candidates)."""
    m = starts.size - 1
    d1, d2 = cells[m + 1], cells[m + 2]
    offsets = _OFFSETS
    run_a = np.empty(27, dtype=np.int64)
    run_b = np.empty(27, dtype=np.int64)
    run_o = np.zeros((27, 3), dtype=np.int64)  # offset of the run's cell from the point's
    gap = np.empty((3, 3))
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    for cell in range(m):
        key = cells[cell]
        run_a[0], run_b[0] = starts[cell], starts[cell + 1]  # its own cell first
        nr = 1
        for o in range(26):
            dx, dy, dz = offsets[o, 0], offsets[o, 1], offsets[o, 2]
            j = _find(cells, m, key + (dx * d1 + dy) * d2 + dz)
            if j >= 0:
                run_a[nr], run_b[nr] = starts[j], starts[j + 1]
                run_o[nr, 0], run_o[nr, 1], run_o[nr, 2] = dx, dy, dz
                nr += 1
        for p in range(starts[cell], starts[cell + 1]):
            i = order[p]
            x0, y0, z0 = S[p, 0], S[p, 1], S[p, 2]
            filled = 0
            worst = np.inf
            for a in range(3):  # squared gaps to the cells below / at / above, per axis
                x = (S[p, a] - lo[a]) / h
                f = x - math.floor(x)
                gap[a, 0], gap[a, 1], gap[a, 2] = (f * h) ** 2, 0.0, ((1.0 - f) * h) ** 2
            for r in range(nr):
                box = (gap[0, run_o[r, 0] + 1] + gap[1, run_o[r, 1] + 1]
                       + gap[2, run_o[r, 2] + 1])  # fmt: skip
                if box > worst:
                    continue  # no point of that cell can be nearer than the k-th so far
                for t in range(run_a[r], run_b[r]):
                    dd = (S[t, 0] - x0) ** 2 + (S[t, 1] - y0) ** 2 + (S[t, 2] - z0) ** 2
                    if dd > worst:
                        continue
                    filled = _insert(bd, bi, filled, k, -1.0 if t == p else dd, order[t])
                    if filled == k:
                        worst = bd[k - 1]
            # distance from the point to the outside of its 3 x 3 x 3 block
            margin = 2.0 * h
            for a in range(3):
                x = (S[p, a] - lo[a]) / h
                f = x - math.floor(x)
                margin = min(margin, h * (1.0 + min(f, 1.0 - f)))
            ok[i] = filled == k and bd[k - 1] <= margin * margin
            for t in range(filled):
                dist[i, t] = math.sqrt(max(bd[t], 0.0))
                idx[i, t] = bi[t]


@njit(cache=True)
def query_at(
    S: Array,
    lo: Array,
    h: float,
    rank: NDArray[np.int64],
    starts: NDArray[np.int64],
    cells: NDArray[np.int64],
    order: NDArray[np.int64],
    at: NDArray[np.int64],
    k: int,
    reach: int,
    dist: Array,
    idx: NDArray[np.int64],
    ok: NDArray[np.bool_],
) -> None:  # pragma: no cover
    """The ``k`` nearest of the points ``at`` from the ``(2 reach + 1)^3`` cells around each
    (as :func:`grid_query`'s rows); ``ok`` where that block provably holds them."""
    m = starts.size - 1
    d0, d1, d2 = cells[m], cells[m + 1], cells[m + 2]
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    c = np.empty(3, dtype=np.int64)
    for q in range(at.size):
        i = at[q]
        p = rank[i]
        margin = np.inf
        for a in range(3):
            x = (S[p, a] - lo[a]) / h
            c[a] = math.floor(x) + 1
            f = x - math.floor(x)
            margin = min(margin, h * (reach + min(f, 1.0 - f)))
        filled = 0
        for dx in range(-reach, reach + 1):
            if c[0] + dx < 0 or c[0] + dx >= d0:
                continue
            for dy in range(-reach, reach + 1):
                if c[1] + dy < 0 or c[1] + dy >= d1:
                    continue
                for dz in range(-reach, reach + 1):
                    if c[2] + dz < 0 or c[2] + dz >= d2:
                        continue
                    j = _find(cells, m, ((c[0] + dx) * d1 + c[1] + dy) * d2 + c[2] + dz)
                    if j < 0:
                        continue
                    for t in range(starts[j], starts[j + 1]):
                        dd = ((S[t, 0] - S[p, 0]) ** 2 + (S[t, 1] - S[p, 1]) ** 2
                              + (S[t, 2] - S[p, 2]) ** 2)  # fmt: skip
                        filled = _insert(bd, bi, filled, k, -1.0 if t == p else dd, order[t])
        ok[q] = filled == k and bd[k - 1] <= margin * margin
        for t in range(filled):
            dist[q, t] = math.sqrt(max(bd[t], 0.0))
            idx[q, t] = bi[t]


@njit(cache=True)
def expand_copies(
    dist_u: Array,
    nbr_u: NDArray[np.int64],
    inv: NDArray[np.int64],
    gstart: NDArray[np.int64],
    members: NDArray[np.int64],
    at: NDArray[np.int64],
    dist: Array,
    idx: NDArray[np.int64],
) -> None:  # pragma: no cover
    """Rows of :func:`service.core.operator.knn.knn` from the distinct points' rows: point
    ``at[r]`` first, then the copies of its distinct neighbours, nearest first, each distinct
    point's copies in index order, until ``idx.shape[1]`` are found."""
    k = idx.shape[1]
    for r in range(at.size):
        i = at[r]
        u = inv[i]
        idx[r, 0], dist[r, 0] = i, 0.0
        f = 1
        for j in range(nbr_u.shape[1]):
            if f == k:
                break
            v = nbr_u[u, j]
            for t in range(gstart[v], gstart[v + 1]):
                p = members[t]
                if p != i:
                    idx[r, f], dist[r, f] = p, dist_u[u, j]
                    f += 1
                    if f == k:
                        break
