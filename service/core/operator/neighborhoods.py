"""Neighbourhoods: who is a neighbour of whom (the edge sets E_i of report section 2.1).

Three sources of neighbourhoods:

* triangle meshes: 1-rings from the faces (section 4.3), with the incident triangles kept as
  *wedges* ``(i, j, k)`` (triangle ``i j k`` seen from vertex ``i``) for mean-value and
  cotangent weights and for the mean-curvature normal (eq. 11);
* polylines and curve networks: the edge graph (section 4.2), with *chains* ``(i, j, k)``
  (vertex ``i`` between ``j`` and ``k``) for the osculating-circle curvature;
* point clouds: k nearest neighbours, or the Delaunay neighbourhoods of section 4.4 — the k
  nearest neighbours projected onto their least-squares plane (surface samples) or line (curve
  samples), triangulated, and the 1-ring of the point taken.

The Delaunay 1-ring of a point ``p`` among its projected neighbours ``q_j`` is computed without a
triangulation call per point: ``q_j`` is a Delaunay neighbour of ``p`` exactly when its
half-plane ``{x : x . q_j <= |q_j|^2 / 2}`` bounds the Voronoi cell of ``p``, i.e. when the polar
point ``a_j = 2 q_j / |q_j|^2`` is a vertex of the convex hull of ``{0} U {a_j}``. The hulls of all
points are found together by a gift-wrapping march vectorised over the points, which also
yields the neighbours in angular order (the fan).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from service.core._arrays import unique_keys

__all__ = [
    "NO_TRIPLES",
    "Neighborhoods",
    "cloud_knn_neighborhoods",
    "curve_neighborhoods",
    "knn",
    "mesh_neighborhoods",
    "pair_adjacency",
    "unique_faces",
]

Source = Literal["mesh", "curve", "knn", "delaunay"]
NO_TRIPLES = np.zeros((0, 3), dtype=np.int64)


@dataclass(frozen=True)
class Neighborhoods:
    """Neighbour sets of every point.

    Attributes
    ----------
    n : int
        Number of points.
    adjacency : scipy.sparse.csr_matrix, shape (n, n)
        Row ``i`` holds a 1 for every neighbour ``j`` of ``i`` (the set I_i of eq. 1). Not
        necessarily symmetric (k-NN and Delaunay neighbourhoods are directed).
    wedges : ndarray, shape (w, 3)
        Triangles ``(i, j, k)`` incident to vertex ``i`` (mesh faces per corner, Delaunay fans).
    chains : ndarray, shape (c, 3)
        Curve vertices ``i`` with two neighbours ``j, k`` (every pair at a junction).
    boundary : ndarray of bool, shape (n,)
        Mesh boundary vertices, open-polyline endpoints, cloud points with an open fan.
    source : str
        ``"mesh"``, ``"curve"``, ``"knn"`` or ``"delaunay"``.
    """

    n: int
    adjacency: sp.csr_matrix
    wedges: NDArray[np.int64]
    chains: NDArray[np.int64]
    boundary: NDArray[np.bool_]
    source: Source

    def degree(self) -> NDArray[np.int64]:
        """Number of neighbours per point."""
        return np.diff(self.adjacency.indptr).astype(np.int64)


def pair_adjacency(i: NDArray[np.int64], j: NDArray[np.int64], n: int) -> sp.csr_matrix:
    """Pattern (ones) of the pairs ``(i, j)``, duplicates merged, rows sorted (compiled
    counting sort: linear in the number of pairs, see ``kernels.rows_from_pairs``)."""
    from service.core.operator.sized_kernels import rows_from_pairs

    ii = np.ascontiguousarray(i, dtype=np.int64)
    jj = np.ascontiguousarray(j, dtype=np.int64)
    indptr, cols, _ = rows_from_pairs(ii, jj, n)
    return sp.csr_matrix((np.ones(cols.size), cols, indptr), shape=(n, n))


def _row_keys(rows: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """One integer per row of small non-negative integers below ``n`` (sorted rows recommended):
    exact mixed-radix keys when they fit in int64, else the row's index among distinct rows."""
    width = rows.shape[1]
    if width * np.log2(max(n, 2)) < 62:
        key = np.zeros(rows.shape[0], dtype=np.int64)
        for c in range(width):
            key = key * n + rows[:, c]
        return key
    order = np.lexsort(rows.T[::-1])
    srt = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = (srt[1:] != srt[:-1]).any(axis=1)
    key = np.empty(len(rows), dtype=np.int64)
    key[order] = np.cumsum(new) - 1
    return key


def unique_faces(faces: NDArray[np.int64]) -> NDArray[np.int64]:
    """Drop duplicate triangles (same vertex set, any order or winding), keeping the first."""
    if len(faces) == 0:
        return faces
    from service.core.operator.kernels import has_duplicate_faces

    n = int(faces.max()) + 1
    if not has_duplicate_faces(np.ascontiguousarray(faces, dtype=np.int64), n):
        return faces  # the common case: one linear pass (issue 30)
    key = _row_keys(np.sort(faces, axis=1), n)
    _, first, _, _ = unique_keys(key)
    if first.size == len(faces):
        return faces
    return faces[np.sort(first)]


def _edge_graph(edges: NDArray[np.int64], n: int) -> sp.csr_matrix:
    i = np.concatenate([edges[:, 0], edges[:, 1]])
    j = np.concatenate([edges[:, 1], edges[:, 0]])
    return pair_adjacency(i, j, n)


def _chains(adj: sp.csr_matrix, rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """``(i, j, k)`` for every pair of neighbours ``j < k`` of each vertex in ``rows``."""
    deg = np.diff(adj.indptr)
    two = rows[deg[rows] == 2]
    start = adj.indptr[two]
    out = [np.column_stack([two, adj.indices[start], adj.indices[start + 1]])]
    for i in rows[deg[rows] > 2]:  # junctions of curve networks: few, loop is fine
        nb = adj.indices[adj.indptr[i] : adj.indptr[i + 1]]
        a, b = np.triu_indices(nb.size, 1)
        out.append(np.column_stack([np.full(a.size, i), nb[a], nb[b]]))
    return np.concatenate(out).astype(np.int64) if out else NO_TRIPLES


def curve_neighborhoods(edges: NDArray[np.int64], n: int) -> Neighborhoods:
    """Neighbourhoods of polylines and curve networks (report section 4.2).

    Parameters
    ----------
    edges : ndarray, shape (k, 2)
        Undirected edges; duplicates are merged.
    n : int
        Number of points.

    Returns
    -------
    Neighborhoods
        Endpoints (degree 1) are marked as boundary.
    """
    adj = _edge_graph(edges, n)
    deg = np.diff(adj.indptr)
    chains = _chains(adj, np.flatnonzero(deg >= 2))
    return Neighborhoods(n, adj, NO_TRIPLES, chains, deg == 1, "curve")


def mesh_neighborhoods(
    faces: NDArray[np.int64], n: int, edges: NDArray[np.int64] | None = None
) -> Neighborhoods:
    """1-ring neighbourhoods of a triangle mesh (report section 4.3).

    Duplicate faces are merged. Vertices referenced by no face keep the neighbours given by
    ``edges`` (mixed input) or none (they pass through smoothing unchanged).

    Parameters
    ----------
    faces : ndarray, shape (m, 3)
        Triangles.
    n : int
        Number of points.
    edges : ndarray, shape (k, 2), optional
        Extra edges for vertices outside every face.

    Returns
    -------
    Neighborhoods
        Boundary vertices are those on an edge used by exactly one (distinct) face.
    """
    from service.core.operator.sized_kernels import mesh_rings

    faces = np.ascontiguousarray(unique_faces(faces), dtype=np.int64)
    m = len(faces)
    wedges = np.empty((3 * m, 3), dtype=np.int64)  # faces, then rotated once and twice
    for r in range(3):
        for c in range(3):
            wedges[r * m : (r + 1) * m, c] = faces[:, (c + r) % 3]
    indptr, cols, boundary = mesh_rings(faces, n)
    adj = sp.csr_matrix((np.ones(cols.size), cols, indptr), shape=(n, n))
    chains = NO_TRIPLES
    if edges is not None and len(edges):
        in_face = np.zeros(n, dtype=bool)
        in_face[faces.ravel()] = True
        keep = ~in_face[edges[:, 0]] | ~in_face[edges[:, 1]]
        eg = _edge_graph(edges[keep], n)
        free_rows = np.flatnonzero(~in_face)
        mask = sp.diags(np.isin(np.arange(n), free_rows).astype(float))
        eg = (mask @ eg).tocsr()
        eg.eliminate_zeros()
        adj = (adj + eg).tocsr()
        adj.data[:] = 1.0
        deg_e = np.diff(eg.indptr)
        boundary |= deg_e == 1
        chains = _chains(eg, np.flatnonzero(deg_e >= 2))
    return Neighborhoods(n, adj, wedges.astype(np.int64, copy=False), chains, boundary, "mesh")


def _query(points: NDArray[np.float64], k: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Each point's ``k`` nearest, itself included: :func:`service.core.operator.knn.knn` (the
    grid search from its size on, issue 30: 1M-point cloud 8.6 s -> ~1 s; else the k-d tree;
    coincident points collapsed, issue 42)."""
    from service.core.operator import knn as grid

    return grid.knn(points, k)


def knn(points: NDArray[np.float64], k: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """k nearest neighbours of every point (itself excluded); ``-1`` pads small clouds."""
    n = points.shape[0]
    kk = min(k, n - 1)
    if kk < 1:
        return np.zeros((n, 0)), np.zeros((n, 0), dtype=np.int64)
    dist, idx = _query(points, kk + 1)
    dist, idx = dist[:, 1:], idx[:, 1:].astype(np.int64)
    # exact duplicates of a point may come before the point itself: drop self explicitly
    self_hit = idx == np.arange(n)[:, None]
    if self_hit.any():
        dist2, idx2 = _query(points, kk + 2)
        keep = idx2 != np.arange(n)[:, None]
        order = np.argsort(~keep, axis=1, kind="stable")[:, :kk]
        idx = np.take_along_axis(idx2, order, axis=1).astype(np.int64)
        dist = np.take_along_axis(dist2, order, axis=1)
    return dist, idx


def cloud_knn_neighborhoods(points: NDArray[np.float64], k: int) -> Neighborhoods:
    """k-nearest-neighbour neighbourhoods of a point cloud (directed).

    Parameters
    ----------
    points : ndarray, shape (n, s)
    k : int
        Neighbours per point.
    """
    n = points.shape[0]
    _, idx = knn(points, k)
    rows = np.repeat(np.arange(n), idx.shape[1])
    adj = pair_adjacency(rows, idx.ravel(), n)
    return Neighborhoods(n, adj, NO_TRIPLES, NO_TRIPLES, np.zeros(n, dtype=bool), "knn")
