"""Local fits: the residual variance of each neighbourhood's quadratic fit
(:func:`patch_variances`, the noise estimate's), and every point against the quadratic fit of
its neighbours without it (:func:`leave_one_out`, the data weights').

For point ``i`` with neighbours ``N_i`` (``k`` nearest, ``i`` excluded) the local frame comes
from principal component analysis of ``N_i`` alone and a quadratic height function ``z(u)`` is
fitted to them by least squares (as in :func:`patch_variances`). Two
numbers per point follow, both free of point ``i`` itself:

* ``v_i = RSS_i / (c (m - p))``: the residual variance of the neighbours' fit, unbiased for
  ``sigma^2`` where the shape is locally quadratic and the neighbours are clean (``m`` the
  neighbours used, ``c`` normal directions, ``p`` coefficients);
* ``r_i = ||z_i - z(u_i)||^2 / (1 + h_i)``: the squared normal residual of ``i`` against that
  fit, with ``h_i = b_i^T (B^T B)^-1 b_i`` the prediction variance of the fit at ``u_i``; for
  Gaussian noise ``r_i / sigma^2`` is ``chi^2_c`` (the leave-one-out residual, so an outlier
  cannot pull the fit it is measured against).

A point far from its neighbours' fit while that fit is consistent with the noise is an outlier;
far from a fit that is itself poor (a crease, a corner, another outlier among the neighbours) it
is undecided (:mod:`service.core.noise.robust`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core.geometry import Geometry
from service.core.operator.knn import GRID_FROM, tree_knn

__all__ = [
    "ACROSS_HOPS",
    "COMPILED_FROM",
    "across",
    "adjacency",
    "curve_neighbours",
    "design",
    "leave_one_out",
    "mesh_neighbours",
    "patch_variances",
    "point_neighbours",
]

Array = NDArray[np.float64]
_CHUNK = 20000
#: Points from which surfaces in 3-D take the compiled kernels of the noise estimate and the data
#: weights (issue 30; below, NumPy is as fast and small inputs load no compiled code): where the
#: grid k-NN takes over.
COMPILED_FROM = GRID_FROM


def design(u: Array, degree: int = 2) -> Array:
    """``[1, u, quadratic (and cubic) monomials of u]`` for ``u`` of shape (..., k, d)."""
    d = u.shape[-1]
    cols = [np.ones(u.shape[:-1]), *(u[..., a] for a in range(d))]
    cols += [u[..., a] * u[..., b] for a in range(d) for b in range(a, d)]
    if degree >= 3:
        cols += [
            u[..., a] * u[..., b] * u[..., c]
            for a in range(d)
            for b in range(a, d)
            for c in range(b, d)
        ]
    return np.stack(cols, axis=-1)


def patch_variances(
    points: NDArray[np.float64],
    neighbours: NDArray[np.int64],
    manifold_dim: int,
    degree: int = 2,
    compiled: bool = True,
) -> NDArray[np.float64]:
    """Residual variance of the local quadratic fit of every neighbourhood.

    Parameters
    ----------
    points : ndarray, shape (n, s)
    neighbours : ndarray, shape (n, k)
        Indices of each point's neighbourhood (the point itself included).
    manifold_dim : int
        ``d``: tangent dimensions of the local fit.
    degree : int
        Of the height function: 2 (quadratic, the estimate) or 3 (cubic, the scale test).

    Returns
    -------
    ndarray, shape (n,)
        ``RSS_i / (c (k - p))`` with ``c = s - d`` normal directions and ``p`` coefficients:
        an unbiased estimate of ``sigma^2`` where the shape is locally a quadratic height
        function; ``nan`` where the fit is rank deficient.

    Surfaces in 3-D from :data:`COMPILED_FROM` points take
    :func:`service.core.noise.fast_fits.patch_variances` (``compiled``; same numbers to rounding).
    """
    if compiled and points.shape[0] >= COMPILED_FROM and points.shape[1] == 3 and (
            manifold_dim == 2 and degree == 2):  # fmt: skip
        from service.core.noise.fast_fits import patch_variances as fast

        v, unsure = fast(points, neighbours)
        rows = np.flatnonzero(unsure)  # cond(G) near 1e10: measured as below
        v[rows] = patch_variances(points, neighbours[rows], 2, compiled=False)
        return v
    n, k = neighbours.shape
    d = manifold_dim
    out = np.full(n, np.nan)
    for start in range(0, n, _CHUNK):
        idx = neighbours[start : start + _CHUNK]
        Q = points[idx]
        Q = Q - Q.mean(axis=1, keepdims=True)
        _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))
        local = np.einsum("nki,nij->nkj", Q, vecs[:, :, ::-1])  # tangents first, then normals
        u = local[..., :d]
        scale = np.sqrt(np.mean(u**2, axis=(1, 2)))
        B = design(u / np.where(scale > 0, scale, 1.0)[:, None, None], degree)
        z = local[..., d:]
        G = np.einsum("nkp,nkq->npq", B, B)
        ok = np.linalg.cond(G) < 1e10
        coef = np.linalg.solve(G[ok], np.einsum("nkp,nkc->npc", B[ok], z[ok]))
        res = z[ok] - np.einsum("nkp,npc->nkc", B[ok], coef)
        p = B.shape[2]
        v = np.full(len(idx), np.nan)
        v[ok] = np.sum(res**2, axis=(1, 2)) / (z.shape[2] * (k - p))
        out[start : start + len(idx)] = v
    return out


def curve_neighbours(
    geometry: Geometry, K: int, at: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The ``K`` nearest points along the curves (hops over the edges, then distance) of the
    points ``at`` whose curve has that many; nearest in space would
    take points of the next turn of a helix or of a neighbouring strand for the curve's own (a
    helix with 100 points a turn and pitch 0.63: 20 nearest in space span two turns).

    Returns the points kept (those with ``K`` such neighbours) and their neighbours."""
    n = geometry.n
    E = np.asarray(geometry.edges)
    A = sp.csr_matrix(
        (np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)
    )
    A = (A + sp.identity(n, format="csr")).astype(bool).astype(np.float64)
    R = sp.csr_matrix((np.ones(at.size), (np.arange(at.size), at)), shape=(at.size, n))
    score = R.copy()
    for _ in range(K):  # each hop adds 1 to every point reached so far: nearer, higher
        R = (R @ A).astype(bool).astype(np.float64)
        score = score + R
    score = score.tocsr()
    P = geometry.points
    rows, kept = [], []
    for i in range(at.size):
        lo, hi = score.indptr[i], score.indptr[i + 1]
        if hi - lo < K:
            continue
        cols = score.indices[lo:hi]
        dist = np.linalg.norm(P[cols] - P[at[i]], axis=1)
        rows.append(cols[np.lexsort((dist, -score.data[lo:hi]))[:K]])
        kept.append(at[i])
    return np.array(kept, dtype=np.int64), np.array(rows, dtype=np.int64).reshape(-1, K)


#: Hops over the mesh's edges a surface neighbourhood may span (:func:`mesh_neighbours`).
MAX_HOPS = 8


def mesh_neighbours(
    points: Array, faces: NDArray[np.int64], K: int, at: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The ``K`` nearest points (itself first) of each point ``at`` among those within the fewest
    hops over the mesh's edges that reach ``K`` (issue 40): a neighbourhood that follows the
    surface, never across a thin wall, fold or plate whose other side is nearer in space than
    along the mesh (a 4 x 4 x 0.3 plate: the 24 nearest in space of a face's vertex take the
    other face's; its noise read 35x the truth). Inside each hop ball the choice is by
    distance, so long thin triangles (20:1) and fans of high valence still give neighbourhoods
    spread over the surface. Points whose component has fewer than ``K`` points within
    :data:`MAX_HOPS` hops are left out.

    Returns the points kept (in ``at``'s order) and their neighbours, nearest first."""
    n = points.shape[0]
    A = adjacency(n, faces)
    live = np.arange(at.size)  # the rows still growing, and their reached sets R
    R = sp.csr_matrix((np.ones(at.size), (live, at)), shape=(at.size, n))
    rows = np.full((at.size, K), -1, dtype=np.int64)
    for _ in range(MAX_HOPS):
        R = (R @ A).astype(bool).astype(np.float64).tocsr()
        ready = np.diff(R.indptr) >= K
        if ready.any():
            rows[live[ready]] = _nearest_in(points, at[live[ready]], R[ready], K)
            live, R = live[~ready], R[~ready]
        if live.size == 0:
            break
    kept = np.ones(at.size, dtype=bool)
    kept[live] = False
    deg = np.diff(A.indptr) - 1
    for i in np.flatnonzero(kept & (deg[at] >= 2 * K)):  # a fan's hub: spread around it
        rows[i] = _around(points, at[i], A.indices[A.indptr[at[i]]:A.indptr[at[i] + 1]], K)
    return at[kept], rows[kept]


#: Hops beyond which a neighbour in space is across a thin part, not beside the point
#: (:func:`across`): the 24 nearest of a regular mesh are within 3 hops (sigma^ on issue 31's
#: 1 - 1.5 edge spheres and helicoid as with k-NN alone); the other face of a plate 3 edges
#: thick is 8 hops or more away 2.5 edges inside its rim.
ACROSS_HOPS = 5


def adjacency(n: int, faces: NDArray[np.int64]) -> sp.csr_matrix:
    """The mesh's vertex adjacency with the diagonal (0/1, CSR)."""
    T = np.asarray(faces, dtype=np.int64)
    a = np.concatenate([T[:, j] for j in range(T.shape[1])])
    b = np.concatenate([T[:, (j + 1) % T.shape[1]] for j in range(T.shape[1])])
    A = sp.csr_matrix((np.ones(2 * a.size), (np.r_[a, b], np.r_[b, a])), shape=(n, n))
    return (A + sp.identity(n, format="csr")).astype(bool).astype(np.float64).tocsr()


def across(
    A: sp.csr_matrix, at: NDArray[np.int64], nbr: NDArray[np.int64], hops: int = ACROSS_HOPS
) -> NDArray[np.bool_]:
    """Rows whose neighbours ``nbr`` (of points ``at``) include one more than ``hops`` hops
    away along the mesh (or in another component): a neighbourhood in space that jumped across
    a thin wall, plate or fold, or along a thin triangle (issue 40)."""
    R = sp.csr_matrix((np.ones(at.size), (np.arange(at.size), at)), shape=(at.size, A.shape[0]))
    for _ in range(hops):
        R = (R @ A).astype(bool).astype(np.float64).tocsr()
    rows = np.repeat(np.arange(at.size), nbr.shape[1])
    hit = np.asarray(R[rows, nbr.ravel()]).reshape(nbr.shape)
    return ~np.all(hit > 0, axis=1)


def _around(points: Array, centre: int, ring: NDArray[np.int64], K: int) -> NDArray[np.int64]:
    """``centre`` and ``K - 1`` of its ring spread evenly by angle about it: the ``K`` nearest
    of a cap's fan (valence 200) are an arc on one side, whose fit extrapolates to the hub and
    reads it as an outlier (issue 40)."""
    ring = ring[ring != centre]
    Q = points[ring] - points[ring].mean(axis=0)
    _, _, Vt = np.linalg.svd(Q, full_matrices=False)
    uv = (points[ring] - points[centre]) @ Vt[:2].T
    order = ring[np.argsort(np.arctan2(uv[:, 1], uv[:, 0]), kind="stable")]
    pick = order[(np.arange(K - 1) * order.size) // (K - 1)]
    return np.r_[centre, pick].astype(np.int64)


def _nearest_in(
    points: Array, centre: NDArray[np.int64], R: sp.csr_matrix, K: int
) -> NDArray[np.int64]:
    """Per row of ``R`` (at least ``K`` candidates for point ``centre[i]``), the ``K``
    candidates nearest to the centre, nearest first (the centre itself first)."""
    R = R.tocsr()
    row = np.repeat(np.arange(R.shape[0]), np.diff(R.indptr))
    col = R.indices.astype(np.int64)
    dist = np.sum((points[col] - points[centre[row]]) ** 2, axis=1)
    dist[col == centre[row]] = -1.0  # the point itself first, before coincident copies
    order = np.lexsort((dist, row))
    return col[order][R.indptr[:-1, None] + np.arange(K)]


def point_neighbours(
    geometry: Geometry, k: int, manifold_dim: int, known: NDArray[np.int64] | None = None
) -> NDArray[np.int64]:
    """Each point (column 0) and its ``k`` nearest neighbours: along the curves for polylines
    (:func:`curve_neighbours`), in space otherwise; the first
    ``k + 1`` columns of ``known`` (the noise estimate's, same rule) when given."""
    n = geometry.n
    if known is not None and known.shape == (n, known.shape[1]) and known.shape[1] > k:
        return _self_first(known[:, : k + 1], np.arange(n))
    P = geometry.points
    if geometry.faces is None and geometry.edges is not None and manifold_dim == 1:
        rows, nbr = curve_neighbours(geometry, k + 1, np.arange(n))
        if rows.size == n:
            return _self_first(nbr, np.arange(n))
    _, nbr = tree_knn(P, k + 1, np.arange(n))  # coincident points collapsed (issue 42)
    return _self_first(nbr, np.arange(n))


def _self_first(nbr: NDArray[np.int64], rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """Put each row's own point in column 0 (coincident points may come first)."""
    nbr = nbr.copy()
    bad = np.flatnonzero(nbr[:, 0] != rows)
    for i in bad:
        where = np.flatnonzero(nbr[i] == rows[i])
        if where.size:
            nbr[i, where[0]] = nbr[i, 0]
        nbr[i, 0] = rows[i]
    return nbr


def leave_one_out(
    points: Array,
    nbr: NDArray[np.int64],
    manifold_dim: int,
    use: NDArray[np.bool_] | None = None,
) -> tuple[Array, Array]:
    """``(r, v)`` of the module docstring for every row of ``nbr`` (centre in column 0).

    Parameters
    ----------
    points : ndarray, shape (n, s)
    nbr : ndarray, shape (m, k + 1)
        Row ``i``: the point, then its neighbours.
    manifold_dim : int
        ``d``: tangent dimensions (2 surfaces, 1 curves).
    use : ndarray of bool, shape (m, k), optional
        Which neighbours enter the fit (default all): excluded ones are e.g. known outliers.

    Returns
    -------
    r, v : ndarray, shape (m,)
        ``nan`` where the fit is rank deficient or has no degree of freedom left.
    """
    m_rows = nbr.shape[0]
    r = np.full(m_rows, np.nan)
    v = np.full(m_rows, np.nan)
    for start in range(0, m_rows, _CHUNK):
        sl = slice(start, start + _CHUNK)
        W = None if use is None else use[sl].astype(np.float64)
        r[sl], v[sl] = _fit(points, nbr[sl], manifold_dim, W)
    return r, v


def _fit(P: Array, nbr: NDArray[np.int64], d: int, W: Array | None) -> tuple[Array, Array]:
    X0 = P[nbr[:, 0]]
    Q = P[nbr[:, 1:]]
    if W is None:
        W = np.ones(Q.shape[:2])
    cnt = W.sum(axis=1)
    Wc = W[..., None]
    mean = np.sum(Wc * Q, axis=1) / np.maximum(cnt, 1.0)[:, None]
    Qc = Q - mean[:, None, :]
    lam, vecs = np.linalg.eigh(np.matmul((Wc * Qc).transpose(0, 2, 1), Qc))
    V = vecs[:, :, ::-1]  # tangents first, then normals
    local = np.matmul(Qc, V)
    local0 = np.matmul((X0 - mean)[:, None, :], V)[:, 0]
    u, z = local[..., :d], local[..., d:]
    scale = np.sqrt(np.sum(W * np.sum(u**2, axis=2), axis=1) / np.maximum(cnt * d, 1.0))
    scale = np.where(scale > 0, scale, 1.0)
    B = design(u / scale[:, None, None])
    b0 = design(local0[:, :d] / scale[:, None])
    p, c = B.shape[2], z.shape[2]
    BW = (Wc * B).transpose(0, 2, 1)
    G = np.matmul(BW, B)
    spread = lam[:, ::-1][:, :d]  # tangent variances: a neighbourhood flat in one is degenerate
    ok = (cnt - p >= 1) & (spread[:, -1] > 1e-8 * np.maximum(spread[:, 0], 1e-300))
    r = np.full(len(nbr), np.nan)
    v = np.full(len(nbr), np.nan)
    try:
        Gi = np.linalg.inv(G[ok])
    except np.linalg.LinAlgError:  # a singular one among them: the pseudo-inverse, checked
        Gi = np.linalg.pinv(G[ok])
    good = np.all(np.isfinite(Gi), axis=(1, 2)) & (
        np.abs(np.matmul(Gi, G[ok]) - np.eye(p)).max(axis=(1, 2)) < 1e-6
    )
    ok[ok] = good
    Gi = Gi[good]
    if not ok.any():
        return r, v
    coef = np.matmul(Gi, np.matmul(BW[ok], z[ok]))
    res = z[ok] - np.matmul(B[ok], coef)
    v[ok] = np.sum(W[ok] * np.sum(res**2, axis=2), axis=1) / (c * (cnt[ok] - p))
    e0 = local0[ok, d:] - np.matmul(b0[ok][:, None, :], coef)[:, 0]
    h0 = np.einsum("np,np->n", b0[ok], np.matmul(Gi, b0[ok][..., None])[..., 0])
    r[ok] = np.sum(e0**2, axis=1) / (1.0 + h0)
    return r, v
