"""Exact ``k`` nearest neighbours of every point on a uniform grid (numba; issue 30).

``scipy.spatial.cKDTree(P).query(P, k)`` costs ~2.3 s CPU for 1M points and ``k = 13`` on one
thread, and the default path asks for it twice (data weights and normal frames). Points of a
surface, curve or cloud sampled at a roughly even spacing are better served by a grid: cells of
the size that holds about ``k`` points each (chosen from the occupancy at two trial sizes, so
that the dimension of the point set does not matter), every cell's candidates gathered once from
its ``3^s`` block, each point's ``k`` nearest by insertion into a sorted list. A point whose
``k``-th distance exceeds its distance to the outside of the block (sparse corners, outliers)
is answered by the k-d tree, so the result is exact: the same neighbour sets as the k-d tree
(ties at equal distance aside), each row sorted by distance, the point itself first (coincident
points: in index order).

Coincident points cost both searches the square of their number (issue 42: 160K copies of one
point took 141 s). When copies would cost more than the search itself (the sum of the squared
multiplicities above :data:`COPIES_COST` ``k n``), the distinct points are searched instead and
each row is filled from their copies (:func:`_collapsed`): ``O(n log n)``, and still exact.
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["COPIES_COST", "GRID_FROM", "grid_knn", "knn", "nearest", "release", "tree_knn"]

Array = NDArray[np.float64]
#: Below this many points the k-d tree is as fast (and the grid's set-up is not worth it).
GRID_FROM = 50_000
#: Coincident points are collapsed when the sum of their squared multiplicities exceeds this
#: many times ``k n`` (a search's own cost); below it the outputs stay those of the plain search.
COPIES_COST = 4


def knn(P: Array, k: int) -> tuple[Array, NDArray[np.int64]]:
    """Distances and indices of the ``k`` nearest points of every point (itself included), as
    ``cKDTree(P).query(P, k)`` returns them for ``k > 1`` (shape ``(n, k)``)."""
    n, s = P.shape
    k = min(k, n)
    if n < GRID_FROM or s != 3 or k < 2:
        return tree_knn(P, k, np.arange(n))
    return grid_knn(P, k)


def grid_knn(P: Array, k: int) -> tuple[Array, NDArray[np.int64]]:
    """:func:`knn` on the uniform grid whatever the size (3-D points, ``2 <= k <= n``)."""
    n = P.shape[0]
    grid = _grid(P, k)
    if grid is None or (_clumped(grid[4], k) and _heavy(P, k)):
        return tree_knn(P, k, np.arange(n))
    S, lo, h, order, starts, cells, _ = grid
    dist = np.empty((n, k))
    idx = np.empty((n, k), dtype=np.int64)
    ok = np.zeros(n, dtype=np.bool_)
    from service.core.operator.knn_kernels import grid_query

    grid_query(S, lo, h, order, starts, cells, k, dist, idx, ok)
    bad = np.flatnonzero(~ok)
    if bad.size:
        dist[bad], idx[bad] = _widening(P, grid, bad, k, 2)
    return dist, idx


def nearest(
    P: Array, at: NDArray[np.int64], k: int, cell_k: int
) -> tuple[Array, NDArray[np.int64]]:
    """The ``k`` nearest points of the points ``at`` (rows of ``P``), as :func:`knn`'s rows:
    on the grid made for ``cell_k`` neighbours (shared with :func:`knn` for that ``k``: made once
    per points array) from ``GRID_FROM`` 3-D points, widening the searched block of cells until
    the block provably holds them, else by the k-d tree."""
    at = np.asarray(at, dtype=np.int64)
    n, s = P.shape
    k = min(k, n)
    grid = _grid(P, cell_k) if n >= GRID_FROM and s == 3 and k >= 2 else None
    if grid is None or (_clumped(grid[4], cell_k) and _heavy(P, k)):
        return tree_knn(P, k, at)
    return _widening(P, grid, at, k, 1)


def _clumped(starts: NDArray[np.int64], k: int) -> bool:
    """Whether the grid's cells are crowded enough (squared counts above the copies' bound)
    to look for coincident points (the cells' counts bound the groups' from above)."""
    counts = np.diff(starts).astype(np.float64)
    return float(counts @ counts) > COPIES_COST * k * float(starts[-1])


def tree_knn(P: Array, k: int, at: NDArray[np.int64]) -> tuple[Array, NDArray[np.int64]]:
    """The ``k`` nearest of the points ``at`` by the k-d tree (``cKDTree(P).query(P[at], k)``
    reshaped to ``(at.size, k)``), or :func:`_collapsed`'s rows when coincident points would
    make the search quadratic."""
    k = min(k, P.shape[0])
    if _heavy(P, k):
        return _collapsed(_copies(P), min(k, P.shape[0]), at)
    return _tree(P, k, at)


def _heavy(P: Array, k: int) -> bool:
    """Whether ``P``'s coincident points would cost a search of ``k`` more than the search."""
    return bool(_copies(P)[-1] > COPIES_COST * k * P.shape[0])


#: The last two points arrays' coincident groups (``(points, their sum, groups)``, as ``_MEMO``;
#: two: the distinct points' own search looks at theirs).
_COPIES: list[tuple[weakref.ref[Array], float, Any]] = []


def _copies(P: Array) -> Any:
    """The coincident groups of ``P``: distinct points, each point's group, the groups' runs
    in ``members`` (indices by group, in index order), the distinct points' searches so far
    (by ``k``) and the sum of the squared group sizes; remembered for the last array."""
    total = float(np.sum(P))
    for ref, tot, got in _COPIES:
        if ref() is P and (tot == total or (np.isnan(tot) and np.isnan(total))):
            return got
    members = np.lexsort(P.T[::-1])  # stable: a group's points in index order
    S = P[members]
    new = np.r_[True, np.any(S[1:] != S[:-1], axis=1)]
    gstart = np.r_[np.flatnonzero(new), P.shape[0]].astype(np.int64)
    inv = np.empty(P.shape[0], dtype=np.int64)
    inv[members] = np.cumsum(new) - 1
    sizes = np.diff(gstart).astype(np.float64)
    got = (np.ascontiguousarray(S[new]), inv, gstart, members.astype(np.int64), {}, sizes @ sizes)
    _COPIES[:] = [*_COPIES[-1:], (weakref.ref(P), total, got)]
    return got


def _collapsed(copies: Any, k: int, at: NDArray[np.int64]) -> tuple[Array, NDArray[np.int64]]:
    """Rows for the points ``at`` from the distinct points' ``min(k, m)`` nearest (searched
    once per ``k``): the point itself, then the copies of its distinct neighbours, nearest first
    (each group in index order)."""
    from service.core.operator.knn_kernels import expand_copies

    U, inv, gstart, members, searched, _ = copies
    ku = min(k, U.shape[0])
    if ku not in searched:
        searched[ku] = knn(U, ku) if ku > 1 else (np.zeros((U.shape[0], 1)), np.arange(
            U.shape[0], dtype=np.int64)[:, None])  # fmt: skip
    du, iu = searched[ku]
    dist = np.empty((at.size, k))
    idx = np.empty((at.size, k), dtype=np.int64)
    expand_copies(du, np.ascontiguousarray(iu, dtype=np.int64), inv, gstart, members,
                  np.ascontiguousarray(at, dtype=np.int64), dist, idx)  # fmt: skip
    return dist, idx


def _widening(
    P: Array, grid: tuple[Any, ...], at: NDArray[np.int64], k: int, first: int
) -> tuple[Array, NDArray[np.int64]]:
    """:func:`nearest` on ``grid``: blocks of ``2 first + 1`` cells a side, then wider up to 7,
    then the k-d tree (a grid made for fewer neighbours than ``k`` starts at 5)."""
    from service.core.operator.knn_kernels import query_at

    S, lo, h, order, starts, cells, rank = grid
    dist = np.empty((at.size, k))
    idx = np.empty((at.size, k), dtype=np.int64)
    todo = np.arange(at.size)
    for reach in range(first, 4):
        if not todo.size:
            break
        ok = np.zeros(todo.size, dtype=np.bool_)
        d, i = np.empty((todo.size, k)), np.empty((todo.size, k), dtype=np.int64)
        query_at(S, lo, h, rank, starts, cells, order, at[todo], k, reach, d, i, ok)
        dist[todo[ok]], idx[todo[ok]] = d[ok], i[ok]
        todo = todo[~ok]
    if todo.size:
        dist[todo], idx[todo] = _tree(P, k, at[todo])
    return dist, idx


#: The last points array's grid and k-d tree (the noise estimate's sample and the data weights'
#: full query share them): ``(points, their sum, cell k or 0 for the tree, structure)``; the
#: sum tells an array changed in place (as :func:`service.core.noise.estimate.estimate_noise`).
_MEMO: list[tuple[weakref.ref[Array], float, int, Any]] = []


def release() -> None:
    """Forget the remembered grid, tree and coincident groups (~50 bytes a point)."""
    _MEMO.clear()
    _COPIES.clear()


def _remembered(P: Array, k: int, make: Any) -> Any:
    total = float(np.sum(P))
    for ref, tot, kk, got in _MEMO:
        if ref() is P and kk == k and (tot == total or (np.isnan(tot) and np.isnan(total))):
            return got
    got = make()
    keep = [m for m in _MEMO if m[0]() is P and m[1] == total and m[2] != k]
    _MEMO[:] = [*keep, (weakref.ref(P), total, k, got)]
    return got


def _grid(P: Array, k: int) -> tuple[Any, ...] | None:
    """The grid for ``k`` neighbours of ``P`` (points in cell order, origin, cell size, order,
    run starts, cells, each point's position in the order), remembered for the last points
    array; ``None`` when the points span nothing."""

    def make() -> tuple[Any, ...] | None:
        Q = np.ascontiguousarray(P, dtype=np.float64)
        lo = Q.min(axis=0)
        span = float(np.max(Q.max(axis=0) - lo))
        if not span > 0:
            return None
        h = _cell_size(Q, lo, span, k)
        _, order, starts, cells = _cells(Q, lo, h)
        rank = np.empty_like(order)  # each point's position in cell order
        rank[order] = np.arange(order.size)
        return np.ascontiguousarray(Q[order]), lo, h, order, starts, cells, rank

    return _remembered(P, k, make)  # type: ignore[no-any-return]


def _tree(P: Array, k: int, at: NDArray[np.int64]) -> tuple[Array, NDArray[np.int64]]:
    from scipy.spatial import cKDTree

    dist, idx = _remembered(P, 0, lambda: cKDTree(P)).query(P[at], k=k)
    return (np.asarray(dist).reshape(at.size, k),
            np.asarray(idx, dtype=np.int64).reshape(at.size, k))  # fmt: skip


def _occupancy(P: Array, lo: Array, h: float) -> float:
    c = np.floor((P - lo) / h).astype(np.int64)
    key = (c[:, 0] * (c[:, 1].max() + 1) + c[:, 1]) * (c[:, 2].max() + 1) + c[:, 2]
    return P.shape[0] / np.unique(key).size


def _cell_size(P: Array, lo: Array, span: float, k: int) -> float:
    """A cell size with about ``3 k / 4`` points per occupied cell (from a sample of 20000)."""
    n = P.shape[0]
    sample = P if n <= 20000 else P[np.random.default_rng(0).choice(n, 20000, replace=False)]
    h1 = span / 16.0
    o1, o2 = _occupancy(sample, lo, h1), _occupancy(sample, lo, 2 * h1)
    dim = min(max(math.log2(max(o2 / o1, 1.0 + 1e-9)), 1.0), 3.0)
    scale = n / sample.shape[0]  # occupancy grows with the density of the full set
    return h1 * (0.5 * k / (o1 * scale)) ** (1.0 / dim)


def _cells(P: Array, lo: Array, h: float) -> tuple[
    NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:  # fmt: skip
    """Cell coordinates per point, points sorted by cell, and the sorted distinct cells with
    the start of their run in ``order`` (``starts[-1] = n``)."""
    c = np.floor((P - lo) / h).astype(np.int64)
    dims = c.max(axis=0) + 3  # room for the -1 / +1 neighbours
    keys = ((c[:, 0] + 1) * dims[1] + (c[:, 1] + 1)) * dims[2] + (c[:, 2] + 1)
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    first = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    cells = np.concatenate([sk[first], dims])  # the strides ride along at the end
    return keys, order, np.r_[first, keys.size].astype(np.int64), cells
