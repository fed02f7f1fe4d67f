"""Delaunay neighbourhoods of point clouds (report section 4.4).

The k nearest neighbours of each point are projected onto their least-squares plane (surface
samples) or line (curve samples) and the 1-ring of the point in the Delaunay triangulation of
the projection is its neighbourhood. The 1-ring of a point ``p`` among its projected neighbours
``q_j`` is computed without a triangulation call per point: ``q_j`` is a Delaunay neighbour of
``p`` exactly when its half-plane ``{x : x . q_j <= |q_j|^2 / 2}`` bounds the Voronoi cell of
``p``, i.e. when the polar point ``a_j = 2 q_j / |q_j|^2`` is a vertex of the convex hull of
``{0} U {a_j}``. The hulls of all points are found together by a gift-wrapping march vectorised
per point (compiled, ``kernels.polar_hull_fans``), which also yields the neighbours in angular
order (the fan).

Defined in any dimension ``s`` (the projection makes it two-dimensional); the local frames cost
``O(n (k^2 s + k^3))`` (linear in ``s``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.core.operator.neighborhoods import (
    NO_TRIPLES,
    Neighborhoods,
    knn,
    pair_adjacency,
)

__all__ = ["cloud_delaunay_neighborhoods"]


def _local_frames(
    points: NDArray[np.float64], idx: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two largest principal variances and directions of each point with its neighbours.

    From the ``s x s`` covariance when ``s <= k + 1``, else from the ``(k+1) x (k+1)`` Gram
    matrix of the centred neighbourhood (same nonzero spectrum): the cost stays linear in the
    dimension ``s``.

    Returns
    -------
    evals : ndarray, shape (n, 2)
        Decreasing.
    dirs : ndarray, shape (n, s, 2)
        Unit directions as columns.
    """
    size, s = idx.shape[1] + 1, points.shape[1]
    if s <= size:  # compiled covariances: no (n, k+1, s) gather
        from service.core.operator.sized_kernels import neighbourhood_covariances

        own = np.column_stack([np.arange(len(points)), idx]).astype(np.int64)
        cov = neighbourhood_covariances(np.ascontiguousarray(points, dtype=np.float64), own)
        evals, evecs = np.linalg.eigh(cov / size)  # ascending
        top = evecs[:, :, ::-1][:, :, :2]
        vals = evals[:, ::-1][:, :2]
    else:
        nbh = np.concatenate([points[:, None, :], points[idx]], axis=1)  # (n, k+1, s)
        centered = nbh - nbh.mean(axis=1, keepdims=True)
        gram = np.einsum("nki,nli->nkl", centered, centered)
        evals, U = np.linalg.eigh(gram)
        vals = evals[:, ::-1][:, :2] / size
        dirs = np.einsum("nki,nkj->nij", centered, U[:, :, ::-1][:, :, :2])
        top = dirs / np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
    if s == 1:
        vals = np.concatenate([vals, np.zeros((vals.shape[0], 1))], axis=1)
        top = np.concatenate([top, np.zeros_like(top)], axis=2)
    return vals, top


def _polar_hull_fans(
    q: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Delaunay 1-rings of the origin among planar neighbours, for many points at once.

    Parameters
    ----------
    q : ndarray, shape (n, m, 2)
        Neighbours of each point, relative to the point, in its tangent plane.

    Returns
    -------
    order : ndarray, shape (n, m)
        Neighbour slots in counter-clockwise fan order, ``-1`` padded.
    count : ndarray, shape (n,)
        Fan size per point.
    open_fan : ndarray of bool, shape (n,)
        True where the origin is on the hull (the point lies on the cloud's border).
    """
    from service.core.operator.sized_kernels import polar_hull_fans

    fans, count, open_fan = polar_hull_fans(np.ascontiguousarray(q, dtype=np.float64))
    return fans, count, open_fan


def cloud_delaunay_neighborhoods(
    points: NDArray[np.float64], k: int, line_ratio: float = 0.05
) -> Neighborhoods:
    """Delaunay neighbourhoods of a point cloud (report section 4.4).

    The k nearest neighbours of each point are projected onto their least-squares plane
    (surface samples) or line (curve samples); the 1-ring of the point in the Delaunay
    triangulation of the projection is its neighbourhood. A cloud is taken as curve samples when
    the median ratio of the second to the first principal variance of the neighbourhoods is
    below ``line_ratio`` (and always for ``s == 1``).

    Parameters
    ----------
    points : ndarray, shape (n, s)
    k : int
        Neighbours considered per point.
    line_ratio : float
        Threshold for telling curve samples from surface samples.

    Returns
    -------
    Neighborhoods
        Surface samples get fans (wedges) and boundary flags for open fans; curve samples get
        chains (predecessor, successor along the local line).
    """
    n, s = points.shape
    dist, idx = knn(points, k)
    if idx.shape[1] == 0:
        empty = pair_adjacency(np.zeros(0, np.int64), np.zeros(0, np.int64), n)
        return Neighborhoods(n, empty, NO_TRIPLES, NO_TRIPLES, np.zeros(n, dtype=bool), "delaunay")
    evals, evecs = _local_frames(points, idx)
    curve_like = s == 1 or float(np.median(evals[:, 1] / np.maximum(evals[:, 0], 1e-300))) < (
        line_ratio
    )
    rows = np.arange(n)
    if curve_like:
        rel = points[idx] - points[:, None, :]  # (n, k, s)
        t = np.einsum("nks,ns->nk", rel, evecs[:, :, 0])
        t = np.where(dist > 0, t, np.nan)
        neg = np.where(t < 0, t, -np.inf)
        pos = np.where(t > 0, t, np.inf)
        prev = idx[rows, np.argmax(neg, axis=1)]
        nxt = idx[rows, np.argmin(pos, axis=1)]
        has_prev = np.isfinite(neg.max(axis=1))
        has_next = np.isfinite(pos.min(axis=1))
        i = np.concatenate([rows[has_prev], rows[has_next]])
        j = np.concatenate([prev[has_prev], nxt[has_next]])
        adj = pair_adjacency(i, j, n)
        both = has_prev & has_next
        chains = np.column_stack([rows[both], prev[both], nxt[both]]).astype(np.int64)
        return Neighborhoods(n, adj, NO_TRIPLES, chains, has_prev ^ has_next, "delaunay")
    # tangent-plane coordinates and fans in chunks: O(chunk k s) temporaries, not O(n k s)
    fans = np.empty((n, int(idx.shape[1])), dtype=np.int64)
    count = np.empty(n, dtype=np.int64)
    open_fan = np.empty(n, dtype=bool)
    for a in range(0, n, 65536):
        b = min(a + 65536, n)
        rel = points[idx[a:b]] - points[a:b, None, :]  # (chunk, k, s)
        q = np.einsum("nks,nsc->nkc", rel, evecs[a:b])
        q[dist[a:b] <= 0] = 0.0
        fans[a:b], count[a:b], open_fan[a:b] = _polar_hull_fans(q)
    slot_ok = fans >= 0
    nb = np.where(slot_ok, idx[rows[:, None], np.maximum(fans, 0)], -1)
    i = np.repeat(rows, slot_ok.sum(axis=1))
    adj = pair_adjacency(i, nb[slot_ok], n)
    # wedges between consecutive fan neighbours; closed fans wrap around
    w_i, w_j, w_k = [], [], []
    for t in range(fans.shape[1]):
        closing = np.asarray(t + 1 == count)  # last slot: wraps to slot 0 for closed fans
        ok = (t < count) & (~closing | (~open_fan & (count >= 3)))
        sel = rows[ok]
        w_i.append(sel)
        w_j.append(nb[sel, t])
        w_k.append(nb[sel, np.where(closing[sel], 0, t + 1)])
    wedges = np.column_stack([np.concatenate(w_i), np.concatenate(w_j), np.concatenate(w_k)])
    wedges = wedges[(wedges[:, 1] != wedges[:, 2])].astype(np.int64)
    return Neighborhoods(n, adj, wedges, NO_TRIPLES, open_fan, "delaunay")
