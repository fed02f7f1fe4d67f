"""``Gram``: products of a scattered ``A`` in reverse Cuthill-McKee order, the same to the bit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from service.core.linalg import gram
from service.core.linalg.gram import Gram


def _scattered(n: int, seed: int = 0) -> sp.csr_matrix:
    """A Laplacian-like matrix of a ring of ``n`` points numbered in random order."""
    rng = np.random.default_rng(seed)
    label = rng.permutation(n)
    i = np.arange(n)
    rows = np.r_[label, label, label]
    cols = np.r_[label, label[(i + 1) % n], label[(i - 1) % n]]
    vals = np.r_[np.full(n, 2.0), rng.uniform(-1.2, -0.8, 2 * n)]
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


@pytest.mark.parametrize("columns", [None, 1, 3])
def test_reordered_products_are_bitwise_the_plain_ones(
    monkeypatch: pytest.MonkeyPatch, columns: int | None
) -> None:
    monkeypatch.setattr(gram, "LOCALITY_FROM", 1000)
    A = _scattered(5000)
    G = Gram(A)
    assert G._local is not None  # reordered
    perm = G._local[0]
    band = lambda M: np.abs(M.tocoo().row - M.tocoo().col).max()  # noqa: E731
    assert band(A[perm][:, perm]) < 10 < band(A)  # the ring's order found
    rng = np.random.default_rng(1)
    X = rng.normal(size=5000 if columns is None else (5000, columns))
    expected = A.T.tocsr() @ (A @ X)
    np.testing.assert_array_equal(G @ X, expected)
    np.testing.assert_array_equal(G.tocsr() @ X, (A.T.tocsr() @ A).tocsr() @ X)  # as before


def test_ordered_or_small_matrices_are_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(gram, "LOCALITY_FROM", 1000)
    ring = sp.diags([np.full(4999, -1.0), np.full(5000, 2.0), np.full(4999, -1.0)], [-1, 0, 1])
    assert Gram(ring)._local is None  # entries next to the diagonal
    assert Gram(_scattered(500))._local is None  # below the size
    assert Gram(_scattered(5000)[:, :4000])._local is None  # not square
