"""Neighbour weights ``w_ij`` of the generalized Laplacian (report eq. 1, sections 4.2-4.4).

Every scheme returns a row-stochastic sparse matrix ``W`` (positive weights, each non-empty row
summing to one), so that ``L = I - W`` is the *normalized* Laplacian ``L^(n)`` with unit
diagonal. Rows of points without neighbours are empty.

* ``uniform``: ``w_ij = 1 / |I_i|``.
* ``reciprocal``: ``w_ij = l_ij^-1 / sum_k l_ik^-1`` (section 4.2, Taubin's reciprocal weights).
* ``mean-value``: Floater's weights ``(tan(a/2) + tan(b/2)) / l_ij`` (section 4.3), with ``a, b``
  the angles at ``p_i`` of the triangles on both sides of edge ``ij``.
* ``cotangent``: ``(cot alpha + cot beta) / 2`` with the angles opposite edge ``ij``; positive on
  Delaunay neighbourhoods (section 4.4), clamped to a small positive floor elsewhere.

Degenerate input never produces NaN: zero-length edges are floored, zero-area triangles add
nothing, and a row whose weights all vanish falls back to uniform weights.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.operator.neighborhoods import Neighborhoods

__all__ = ["ResolvedScheme", "cotangents", "neighbor_weights", "tan_half_angles"]

ResolvedScheme = Literal["uniform", "reciprocal", "mean-value", "cotangent"]
_COT_FLOOR = 1e-3  # clamped cotangent weights: at least this fraction of the row's mean weight


def _floor_length(points: NDArray[np.float64]) -> float:
    ext = float(np.ptp(points, axis=0).max()) if points.shape[0] > 1 else 0.0
    return max(ext, 1.0) * 1e-12


def _normalize_rows(W: sp.csr_matrix, adjacency: sp.csr_matrix) -> sp.csr_matrix:
    """Row-normalize; rows summing to zero (or non-finite) fall back to uniform weights."""
    W = W.tocsr()
    W.sum_duplicates()
    sums = np.asarray(W.sum(axis=1)).ravel()
    bad = ~(np.isfinite(sums) & (sums > 0))
    deg = np.diff(adjacency.indptr)
    bad &= deg > 0
    if bad.any():
        keep = sp.diags((~bad).astype(float)) @ W
        uni = sp.diags(bad.astype(float)) @ adjacency
        W = (keep + uni).tocsr()
        sums = np.asarray(W.sum(axis=1)).ravel()
    inv = np.divide(1.0, sums, out=np.zeros_like(sums), where=sums > 0)
    out = (sp.diags(inv) @ W).tocsr()
    out.eliminate_zeros()
    return out


def _reciprocal(points: NDArray[np.float64], adjacency: sp.csr_matrix) -> sp.csr_matrix:
    coo = adjacency.tocoo()
    lengths = np.linalg.norm(points[coo.row] - points[coo.col], axis=1)
    w = 1.0 / np.maximum(lengths, _floor_length(points))
    return sp.csr_matrix((w, (coo.row, coo.col)), shape=adjacency.shape)


def tan_half_angles(
    points: NDArray[np.float64], wedges: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``tan(theta_i / 2)`` at the apex of each wedge and the two edge lengths.

    Uses ``tan(theta / 2) = |e1 x e2| / (|e1| |e2| + e1 . e2)`` (any dimension, via the
    Lagrange identity), which stays finite for all but exactly straight angles.

    Parameters
    ----------
    points : ndarray, shape (n, s)
    wedges : ndarray, shape (w, 3)
        ``(i, j, k)``: apex ``i``, neighbours ``j`` and ``k``.

    Returns
    -------
    tan_half, lij, lik : ndarray, shape (w,)
    """
    e1 = points[wedges[:, 1]] - points[wedges[:, 0]]
    e2 = points[wedges[:, 2]] - points[wedges[:, 0]]
    l1 = np.linalg.norm(e1, axis=1)
    l2 = np.linalg.norm(e2, axis=1)
    dot = np.einsum("ij,ij->i", e1, e2)
    cross = np.sqrt(np.maximum(l1**2 * l2**2 - dot**2, 0.0))
    den = l1 * l2 + dot
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den > 1e-14 * l1 * l2, cross / den, np.inf)
    return t, l1, l2


def _mean_value(points: NDArray[np.float64], nb: Neighborhoods) -> sp.csr_matrix:
    w = nb.wedges
    t, l1, l2 = tan_half_angles(points, w)
    floor = _floor_length(points)
    ok = np.isfinite(t) & (l1 > floor) & (l2 > floor)
    t, l1, l2, w = t[ok], l1[ok], l2[ok], w[ok]
    rows = np.concatenate([w[:, 0], w[:, 0]])
    cols = np.concatenate([w[:, 1], w[:, 2]])
    vals = np.concatenate([t / l1, t / l2])
    return sp.csr_matrix((vals, (rows, cols)), shape=(nb.n, nb.n))


def cotangents(
    points: NDArray[np.float64], wedges: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Cotangents of the two base angles of each wedge triangle and its area.

    Returns
    -------
    cot_j, cot_k, area : ndarray, shape (w,)
        ``cot_j`` is the cotangent of the angle at ``j`` (opposite edge ``ik``), ``cot_k`` the
        one at ``k`` (opposite edge ``ij``); both are ``nan`` for zero-area triangles.
    """
    pi, pj, pk = points[wedges[:, 0]], points[wedges[:, 1]], points[wedges[:, 2]]

    def _cot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        dot = np.einsum("ij,ij->i", a, b)
        aa = np.einsum("ij,ij->i", a, a)
        bb = np.einsum("ij,ij->i", b, b)
        cross = np.sqrt(np.maximum(aa * bb - dot**2, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(cross > 0, dot / cross, np.nan)

    cot_j = _cot(pi - pj, pk - pj)
    cot_k = _cot(pi - pk, pj - pk)
    e1, e2 = pj - pi, pk - pi
    dot = np.einsum("ij,ij->i", e1, e2)
    area = 0.5 * np.sqrt(
        np.maximum(np.einsum("ij,ij->i", e1, e1) * np.einsum("ij,ij->i", e2, e2) - dot**2, 0.0)
    )
    return cot_j, cot_k, area


def _cotangent(points: NDArray[np.float64], nb: Neighborhoods) -> sp.csr_matrix:
    w = nb.wedges
    cot_j, cot_k, _ = cotangents(points, w)
    ok = np.isfinite(cot_j) & np.isfinite(cot_k)
    w, cot_j, cot_k = w[ok], cot_j[ok], cot_k[ok]
    rows = np.concatenate([w[:, 0], w[:, 0]])
    cols = np.concatenate([w[:, 1], w[:, 2]])
    vals = 0.5 * np.concatenate([cot_k, cot_j])
    W = sp.csr_matrix((vals, (rows, cols)), shape=(nb.n, nb.n))
    W.sum_duplicates()
    # clamp to a positive floor: a fraction of the row's mean absolute weight
    row_of = np.repeat(np.arange(nb.n), np.diff(W.indptr))
    mean_abs = np.bincount(row_of, weights=np.abs(W.data), minlength=nb.n).astype(np.float64)
    cnt = np.maximum(np.diff(W.indptr), 1)
    mean_abs /= cnt
    W.data = np.maximum(W.data, _COT_FLOOR * mean_abs[row_of])
    return W


def neighbor_weights(
    points: NDArray[np.float64], nb: Neighborhoods, scheme: ResolvedScheme
) -> sp.csr_matrix:
    """Row-stochastic weight matrix ``W`` for ``L^(n) = I - W`` (report eq. 1).

    Rows without triangles (curve vertices, line-like cloud samples, vertices only on extra
    edges) use reciprocal-distance weights under ``mean-value`` and ``cotangent``.

    Parameters
    ----------
    points : ndarray, shape (n, s)
    nb : Neighborhoods
    scheme : {"uniform", "reciprocal", "mean-value", "cotangent"}

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n, n)
        Positive weights; every row with neighbours sums to one.
    """
    adj = nb.adjacency
    if scheme == "uniform":
        W = adj.copy()
    elif scheme == "reciprocal":
        W = _reciprocal(points, adj)
    else:
        W = _mean_value(points, nb) if scheme == "mean-value" else _cotangent(points, nb)
        has_tri = np.zeros(nb.n, dtype=bool)
        has_tri[nb.wedges[:, 0]] = True
        if not has_tri.all():
            rec = sp.diags((~has_tri).astype(float)) @ _reciprocal(points, adj)
            W = (sp.diags(has_tri.astype(float)) @ W + rec).tocsr()
    return _normalize_rows(W.tocsr(), adj)
