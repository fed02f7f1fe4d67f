"""Curvature estimates ``kappa_i`` for the scaled Laplacians of report section 4.1.

* Polylines (and line-like point clouds): the osculating circle through ``p_{i-1}, p_i,
  p_{i+1}``, ``kappa_i = 4A / (abc)`` (section 4.2); at a junction of a curve network, the largest
  value over pairs of neighbours; endpoints get 0.
* Meshes and Delaunay neighbourhoods of point clouds: the magnitude of the discrete mean
  curvature normal (eq. 11), ``|(1 / 4A) sum_j (cot beta_j + cot gamma_j)(p_i - p_j)|`` with ``A``
  the barycentric area of ``p_i`` (a third of the area of its triangles), which makes it the
  mean curvature ``H`` (``1/r`` on a sphere).

Zero-area triangles and zero-length edges contribute nothing; the result is always finite.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.core.operator.neighborhoods import Neighborhoods
from service.core.operator.weights import cotangents

__all__ = ["curvature", "mean_curvature_normal", "osculating_curvature"]


def osculating_curvature(
    points: NDArray[np.float64], chains: NDArray[np.int64], n: int
) -> NDArray[np.float64]:
    """``4A / (abc)`` per chain ``(i, j, k)``; the maximum over chains sharing a vertex.

    Parameters
    ----------
    points : ndarray, shape (n, s)
    chains : ndarray, shape (c, 3)
    n : int

    Returns
    -------
    ndarray, shape (n,)
        Zero for vertices without a chain.
    """
    kappa = np.zeros(n)
    if len(chains) == 0:
        return kappa
    pi, pj, pk = (points[chains[:, c]] for c in range(3))
    u, v = pj - pi, pk - pi
    a = np.linalg.norm(u, axis=1)
    b = np.linalg.norm(v, axis=1)
    c = np.linalg.norm(pk - pj, axis=1)
    dot = np.einsum("ij,ij->i", u, v)
    area = 0.5 * np.sqrt(np.maximum(a**2 * b**2 - dot**2, 0.0))
    den = a * b * c
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(den > 0, 4.0 * area / den, 0.0)
    order = np.lexsort((k, chains[:, 0]))  # by vertex, then value: the last one is the max
    last = np.ones(order.size, dtype=bool)
    last[:-1] = chains[order[1:], 0] != chains[order[:-1], 0]
    kappa[chains[order[last], 0]] = k[order[last]]
    return kappa


def mean_curvature_normal(
    points: NDArray[np.float64], wedges: NDArray[np.int64], n: int
) -> NDArray[np.float64]:
    """Discrete mean curvature normal ``kappa_i n_i`` of eq. (11) from the wedges.

    Parameters
    ----------
    points : ndarray, shape (n, s)
    wedges : ndarray, shape (w, 3)
        Triangles ``(i, j, k)`` around each apex ``i``.
    n : int

    Returns
    -------
    ndarray, shape (n, s)
    """
    out = np.zeros((n, points.shape[1]))
    if len(wedges) == 0:
        return out
    cot_j, cot_k, area = cotangents(points, wedges)
    ok = np.isfinite(cot_j) & np.isfinite(cot_k) & (area > 0)
    w = wedges[ok]
    pi = points[w[:, 0]]
    contrib = cot_k[ok, None] * (pi - points[w[:, 1]]) + cot_j[ok, None] * (pi - points[w[:, 2]])
    for c in range(points.shape[1]):  # bincount: one pass, unlike np.add.at
        out[:, c] = np.bincount(w[:, 0], weights=contrib[:, c], minlength=n)
    ring_area = np.bincount(w[:, 0], weights=area[ok], minlength=n)
    # A of eq. (11) is the barycentric area (a third of the ring), so that |kappa n| is the
    # mean curvature H (1/r on a sphere), on the same scale as the polylines' 1/r
    scale = np.divide(3.0, 4.0 * ring_area, out=np.zeros(n), where=ring_area > 0)
    return out * scale[:, None]


def _normal_part(
    points: NDArray[np.float64], K: NDArray[np.float64], rows: NDArray[np.int64], nb: Neighborhoods
) -> NDArray[np.float64]:
    """Component of ``K[rows]`` normal to the tangent plane at each boundary vertex.

    At a boundary vertex eq. (11) also contains an in-plane (geodesic) term that is unbounded on
    sliver triangles; the tangent plane is spanned by the two principal directions of the
    vertex's neighbours (relative to the vertex).
    """
    adj = nb.adjacency
    deg = np.diff(adj.indptr)[rows]
    width = int(deg.max()) if rows.size else 0
    rel = np.zeros((rows.size, max(width, 1), points.shape[1]))
    for t in range(width):
        has = deg > t
        nbr = adj.indices[adj.indptr[rows[has]] + t]
        rel[has, t] = points[nbr] - points[rows[has]]
    scatter = np.einsum("bki,bkj->bij", rel, rel)
    _, vecs = np.linalg.eigh(scatter)
    T = vecs[:, :, -2:]  # two largest principal directions
    k = K[rows]
    return k - np.einsum("bij,bj->bi", T, np.einsum("bji,bj->bi", T, k))


def curvature(points: NDArray[np.float64], nb: Neighborhoods) -> NDArray[np.float64]:
    """Curvature estimate ``kappa_i >= 0`` for every point (report sections 4.2-4.4).

    Parameters
    ----------
    points : ndarray, shape (n, s)
    nb : Neighborhoods
        Must carry wedges (meshes, Delaunay fans) or chains (curves); other points get 0.

    Returns
    -------
    ndarray, shape (n,)
    """
    kappa = osculating_curvature(points, nb.chains, nb.n)
    if len(nb.wedges):
        K = mean_curvature_normal(points, nb.wedges, nb.n)
        edge = np.flatnonzero(nb.boundary & (np.diff(nb.adjacency.indptr) >= 2))
        if edge.size and points.shape[1] > 2:
            K[edge] = _normal_part(points, K, edge, nb)
        mc = np.linalg.norm(K, axis=1)
        has_wedge = np.zeros(nb.n, dtype=bool)
        has_wedge[nb.wedges[:, 0]] = True
        kappa = np.where(has_wedge, mc, kappa)
    return np.nan_to_num(kappa, nan=0.0, posinf=0.0)
