"""Neighbourhoods: mesh 1-rings, curve graphs, k-NN and Delaunay neighbourhoods (section 4.4)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import Delaunay, cKDTree

from service.core.operator.delaunay import cloud_delaunay_neighborhoods
from service.core.operator.neighborhoods import (
    cloud_knn_neighborhoods,
    curve_neighborhoods,
    mesh_neighborhoods,
)
from tests.core.core_fixtures import random_rotation


def _nbrs(adj, i: int) -> set[int]:
    return set(adj.indices[adj.indptr[i] : adj.indptr[i + 1]].tolist())


def test_delaunay_neighbourhoods_match_a_triangulation() -> None:
    """For planar samples, the 1-ring equals scipy's Delaunay 1-ring whenever the whole ring is
    among the k nearest neighbours (the report's definition triangulates only those)."""
    rng = np.random.default_rng(0)
    Q = rng.random((1500, 2))
    P = np.c_[Q, np.zeros(len(Q))] @ random_rotation(3, seed=1)
    k = 20
    nb = cloud_delaunay_neighborhoods(P, k)
    tri = Delaunay(Q)
    indptr, ind = tri.vertex_neighbor_vertices
    _, knn = cKDTree(Q).query(Q, k + 1)
    checked = 0
    for i in range(len(Q)):
        ring = set(ind[indptr[i] : indptr[i + 1]].tolist())
        if ring <= set(knn[i].tolist()) and not nb.boundary[i]:
            assert _nbrs(nb.adjacency, i) == ring, i
            checked += 1
    assert checked > 1300
    # hull points of the sample have open fans
    hull = set(np.unique(tri.convex_hull).tolist())
    assert hull <= set(np.flatnonzero(nb.boundary).tolist())


def test_delaunay_on_curve_samples_gives_line_neighbours() -> None:
    # jittered even sampling: each point has samples on both sides among its 8 nearest
    t = np.linspace(0, 3, 200) + np.random.default_rng(2).uniform(-0.005, 0.005, 200)
    P = np.c_[t, np.sin(t), 0.5 * t]
    nb = cloud_delaunay_neighborhoods(P, 8)
    assert len(nb.wedges) == 0
    for i in range(1, 199):
        assert _nbrs(nb.adjacency, i) == {i - 1, i + 1}
    assert np.flatnonzero(nb.boundary).tolist() == [0, 199]


def test_knn_excludes_self_even_with_duplicates() -> None:
    P = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    nb = cloud_knn_neighborhoods(P, 2)
    for i in range(5):
        assert i not in _nbrs(nb.adjacency, i)
        assert len(_nbrs(nb.adjacency, i)) == 2


def test_knn_of_a_large_cloud_is_the_tree_query_with_self_dropped() -> None:
    """From GRID_FROM points the grid search answers; it must equal the k-d tree's answer
    (random coordinates: no ties), duplicates included (self dropped wherever it comes)."""
    from service.core.operator.knn import GRID_FROM
    from service.core.operator.neighborhoods import knn

    rng = np.random.default_rng(3)
    P = rng.normal(size=(GRID_FROM + 5000, 3))
    P[:, 2] *= 0.05  # a thick sheet
    P[100:110] = P[0]  # ten copies of point 0: the self-drop path
    dist, idx = knn(P, 8)
    tree_i = cKDTree(P).query(P, k=10)[1]
    rows = np.arange(P.shape[0])
    copies = {0, *range(100, 110)}
    for i in rng.choice(np.setdiff1d(rows, list(copies)), 2000, replace=False).tolist():
        assert idx[i].tolist() == [j for j in tree_i[i].tolist() if j != i][:8]
    for i in copies:  # 10 others at distance 0: any 8 of them (a tie)
        assert set(idx[i].tolist()) <= copies - {i} and not dist[i].any()
    assert not np.any(idx == rows[:, None])
    np.testing.assert_allclose(dist, np.linalg.norm(P[idx] - P[:, None], axis=2), rtol=1e-12)


def test_mesh_boundary_nonmanifold_and_duplicates() -> None:
    F = np.array([[0, 1, 2], [0, 2, 3], [2, 1, 0], [0, 1, 4]])  # duplicate + third face on 0-1
    nb = mesh_neighborhoods(F, 6)
    assert _nbrs(nb.adjacency, 0) == {1, 2, 3, 4}
    assert nb.degree()[5] == 0
    # edges 0-2 is shared; 1-2, 2-3, 0-3, 1-4, 0-4 are single: boundary is all of 0..4
    assert nb.boundary.tolist() == [True] * 5 + [False]
    assert len(nb.wedges) == 9


def test_curve_network_junctions() -> None:
    E = np.array([[0, 1], [0, 2], [0, 3], [3, 4]])
    nb = curve_neighborhoods(E, 5)
    assert _nbrs(nb.adjacency, 0) == {1, 2, 3}
    assert nb.boundary.tolist() == [False, True, True, False, True]
    assert sorted(map(tuple, nb.chains[nb.chains[:, 0] == 0][:, 1:].tolist())) == [
        (1, 2),
        (1, 3),
        (2, 3),
    ]


def test_delaunay_small_k_matches_local_triangulations() -> None:
    """Regression (issues 9, 15): k = 3..8 crashed in _polar_hull_fans (IndexError). The ring
    is the Delaunay 1-ring of the point among its k nearest neighbours (planar sample)."""
    rng = np.random.default_rng(4)
    Q = rng.random((300, 2))
    P = np.c_[Q, np.zeros(len(Q))] @ random_rotation(3, seed=5)
    for k in range(3, 9):
        nb = cloud_delaunay_neighborhoods(P, k)
        _, knn = cKDTree(Q).query(Q, k + 1)
        for i in range(0, len(Q), 7):
            local = knn[i]  # i itself first
            tri = Delaunay(Q[local])
            indptr, ind = tri.vertex_neighbor_vertices
            first = int(np.flatnonzero(local == i)[0])
            ring = set(local[ind[indptr[first] : indptr[first + 1]]].tolist())
            assert _nbrs(nb.adjacency, i) == ring, (k, i)


def _reference_rings(F: np.ndarray, n: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """Independent build: SciPy's COO -> CSR and np.unique edge counts over distinct faces."""
    _, first = np.unique(np.sort(F, axis=1), axis=0, return_index=True)
    F = F[np.sort(first)]
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    i, j = np.concatenate([a, b]), np.concatenate([b, a])
    A = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    A.sum_duplicates()
    A.sort_indices()
    edges, counts = np.unique(np.sort(np.column_stack([a, b]), axis=1), axis=0, return_counts=True)
    boundary = np.zeros(n, dtype=bool)
    boundary[edges[counts == 1].ravel()] = True
    return A, boundary


def test_compiled_mesh_rings_match_a_scipy_build_with_messy_faces() -> None:
    rng = np.random.default_rng(5)
    n = 300
    F = rng.integers(0, n, size=(900, 3))
    F = np.concatenate([F, F[:40, [2, 1, 0]], F[40:60], [[3, 3, 7], [8, 9, 9], [5, 5, 5]]])
    nb = mesh_neighborhoods(F, n + 4)
    A, boundary = _reference_rings(F, n + 4)
    assert np.array_equal(nb.adjacency.indptr, A.indptr)
    assert np.array_equal(nb.adjacency.indices, A.indices)
    assert np.all(nb.adjacency.data == 1.0)
    assert np.array_equal(nb.boundary, boundary)


def test_adjacency_from_pairs_matches_scipy() -> None:
    from service.core.operator.neighborhoods import pair_adjacency

    rng = np.random.default_rng(6)
    i, j = rng.integers(0, 50, 2000), rng.integers(0, 50, 2000)
    A = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(60, 60)).tocsr()
    A.sum_duplicates()
    A.sort_indices()
    B = pair_adjacency(i, j, 60)
    assert np.array_equal(B.indptr, A.indptr) and np.array_equal(B.indices, A.indices)


def test_unique_faces_keeps_the_first_of_each_vertex_set() -> None:
    from service.core.operator.kernels import has_duplicate_faces
    from service.core.operator.neighborhoods import unique_faces

    rng = np.random.default_rng(7)
    n = 400
    F = np.unique(np.sort(rng.integers(0, n, size=(2000, 3)), axis=1), axis=0)  # distinct sets
    F = rng.permuted(F, axis=1)  # any order within a face
    hub = np.c_[np.zeros(300, dtype=np.int64), np.arange(1, 301), np.arange(2, 302)]  # one bucket
    for faces in (F, hub):
        assert not has_duplicate_faces(faces, n + 2)
        assert unique_faces(faces) is faces
    messy = np.concatenate([F, F[[5, 9]][:, [2, 0, 1]], hub, hub[[299]][:, [1, 0, 2]]])
    assert has_duplicate_faces(messy, n + 2)
    seen: set[tuple[int, ...]] = set()
    keep = []
    for row in messy.tolist():  # the first face of each sorted vertex triple, by a loop
        if tuple(sorted(row)) not in seen:
            seen.add(tuple(sorted(row)))
            keep.append(row)
    np.testing.assert_array_equal(unique_faces(messy), keep)
