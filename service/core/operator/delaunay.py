"""Delaunay neighbourhoods of point clouds (report section 4.4).

The k nearest neighbours of each point are projected onto their least-squares plane (surface
samples) or line (curve samples) and the 1-ring of the point in the Delaunay triangulation of
the projection is its neighbourhood. The 1-ring of a point ``p`` among its projected neighbours
``q_j`` is computed without a triangulation call per point: ``q_j`` is a Delaunay neighbour of
``p`` exactly when its half-plane ``{x : x . q_j <= |q_j|^2 / 2}`` bounds the Voronoi cell of
``p``, i.e. when the polar point ``a_j = 2 q_j / |q_j|^2`` is a vertex of the convex hull of
``{0} U {a_j}``. The hulls of all points are found together by a gift-wrapping march vectorised
over the points, which also yields the neighbours in angular order (the fan).

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
    nbh = np.concatenate([points[:, None, :], points[idx]], axis=1)  # (n, k+1, s)
    centered = nbh - nbh.mean(axis=1, keepdims=True)
    size, s = nbh.shape[1], nbh.shape[2]
    if s <= size:
        cov = np.einsum("nki,nkj->nij", centered, centered) / size
        evals, evecs = np.linalg.eigh(cov)  # ascending
        top = evecs[:, :, ::-1][:, :, :2]
        vals = evals[:, ::-1][:, :2]
    else:
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
    n, m, _ = q.shape
    r2 = np.einsum("nmi,nmi->nm", q, q)
    valid = r2 > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(valid[..., None], 2.0 * q / r2[..., None], 0.0)
    # candidate set: the m polar points plus the origin (slot m)
    cand = np.concatenate([a, np.zeros((n, 1, 2))], axis=1)
    cvalid = np.concatenate([valid, np.ones((n, 1), dtype=bool)], axis=1)
    norms = np.where(cvalid, np.einsum("nmi,nmi->nm", cand, cand), -1.0)
    norms[:, m] = -1.0
    start = np.argmax(norms, axis=1)
    rows = np.arange(n)
    has_any = valid.any(axis=1)
    cur = start.copy()
    sp_ = cand[rows, start]
    direction = np.column_stack([-sp_[:, 1], sp_[:, 0]])  # CCW tangent of the circle |x| = |start|
    on_hull = np.zeros((n, m + 1), dtype=bool)
    on_hull[rows[has_any], start[has_any]] = True
    order = np.full((n, m + 1), -1, dtype=np.int64)
    order[:, 0] = np.where(has_any, start, -1)
    active = has_any.copy()
    for step in range(1, m + 1):  # at most m + 1 hull vertices: slots 0..m
        if not active.any():
            break
        ar = rows[active]
        c = cand[ar, cur[ar]]
        d = direction[ar]
        v = cand[ar] - c[:, None, :]
        cross = d[:, None, 0] * v[..., 1] - d[:, None, 1] * v[..., 0]
        dot = np.einsum("ni,nmi->nm", d, v)
        ang = np.mod(np.arctan2(cross, dot), 2 * np.pi)
        dist = np.einsum("nmi,nmi->nm", v, v)
        scale = np.maximum(dist.max(axis=1, keepdims=True), 1e-300)
        bad = ~cvalid[ar] | (dist <= 1e-24 * scale)
        ang = np.where(bad, np.inf, ang)
        # smallest turn; among (near-)collinear candidates the farthest one
        key = np.round(ang, 12) - dist / scale * 1e-13
        nxt = np.argmin(key, axis=1)
        done = (nxt == start[ar]) | on_hull[ar, nxt] | ~np.isfinite(ang[np.arange(ar.size), nxt])
        go = ar[~done]
        on_hull[go, nxt[~done]] = True
        order[go, step] = nxt[~done]
        direction[go] = cand[go, nxt[~done]] - cand[go, cur[go]]
        cur[go] = nxt[~done]
        active[ar[done]] = False
    open_fan = on_hull[:, m]
    # rotate each fan to start right after the origin (open fans), then drop the origin slot
    lengths = (order >= 0).sum(axis=1)
    fans = np.full((n, m), -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    for length in np.unique(lengths[lengths > 0]):
        for with_origin in (False, True):
            sel = np.flatnonzero((lengths == length) & (open_fan == with_origin))
            if sel.size == 0:
                continue
            o = order[sel, :length]
            if with_origin:
                shift = np.argmax(o == m, axis=1) + 1
                roll = (np.arange(length)[None, :] + shift[:, None]) % length
                o = np.take_along_axis(o, roll, axis=1)[:, : length - 1]
            fans[sel, : o.shape[1]] = o
            count[sel] = o.shape[1]
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
    rel = points[idx] - points[:, None, :]  # (n, k, s)
    curve_like = s == 1 or float(np.median(evals[:, 1] / np.maximum(evals[:, 0], 1e-300))) < (
        line_ratio
    )
    rows = np.arange(n)
    if curve_like:
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
    q = np.stack(
        [np.einsum("nks,ns->nk", rel, evecs[:, :, c]) for c in (0, 1)],
        axis=-1,
    )
    q = np.where((dist > 0)[..., None], q, 0.0)
    fans, count, open_fan = _polar_hull_fans(q)
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
