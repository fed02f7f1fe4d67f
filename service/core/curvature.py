"""Curvature estimates ``kappa_i`` for the scaled Laplacians of report section 4.1.

* Polylines (and line-like point clouds): the osculating circle through ``p_{i-1}, p_i,
  p_{i+1}``, ``kappa_i = 4A / (abc)`` (section 4.2); at a junction of a curve network, the largest
  value over pairs of neighbours; endpoints get 0.
* Meshes and Delaunay neighbourhoods of point clouds: the magnitude of the discrete mean
  curvature normal (eq. 11), ``|(1 / 4A) sum_j (cot beta_j + cot gamma_j)(p_i - p_j)|`` with ``A``
  the area of the triangles around ``p_i``.

Zero-area triangles and zero-length edges contribute nothing; the result is always finite.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from service.core.neighborhoods import Neighborhoods
from service.core.weights import cotangents

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
    np.maximum.at(kappa, chains[:, 0], k)
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
    np.add.at(out, w[:, 0], contrib)
    ring_area = np.zeros(n)
    np.add.at(ring_area, w[:, 0], area[ok])
    scale = np.divide(1.0, 4.0 * ring_area, out=np.zeros(n), where=ring_area > 0)
    return out * scale[:, None]


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
        mc = np.linalg.norm(mean_curvature_normal(points, nb.wedges, nb.n), axis=1)
        has_wedge = np.zeros(nb.n, dtype=bool)
        has_wedge[nb.wedges[:, 0]] = True
        kappa = np.where(has_wedge, mc, kappa)
    return np.nan_to_num(kappa, nan=0.0, posinf=0.0)
