"""pcg: the cheap stopping test still stops on the rigorous bound (checked against dense solves)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from service.core.linalg.krylov import _wsq, pcg


def _laplacian_gram(n: int) -> sp.csr_matrix:
    L = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    return (L.T @ L).tocsr()


def test_weighted_square_sum_matches_numpy() -> None:
    rng = np.random.default_rng(0)
    X, w = rng.normal(size=(50, 3)), rng.uniform(0.5, 2.0, 50)
    assert np.isclose(_wsq(X, w), float(np.sum(w[:, None] * X**2)))


def test_pcg_meets_its_error_bound_against_a_dense_solve() -> None:
    rng = np.random.default_rng(1)
    n = 400
    M = _laplacian_gram(n)
    d2 = rng.uniform(0.5, 2.0, n)
    R = rng.normal(size=(n, 3))
    for lam in (1e-1, 1e-3):
        K = M + lam * sp.diags(d2)
        exact = np.linalg.solve(K.toarray(), R)
        diag = K.diagonal()[:, None]
        X, products, ok = pcg(lambda Q, K=K: K @ Q, R, lambda Q, g=diag: Q / g, lam, d2,
                              rtol=1e-9, maxiter=20000)  # fmt: skip
        assert ok and products > 10
        err = np.sqrt(_wsq(X - exact, d2))
        assert err <= 1e-9 * np.sqrt(_wsq(exact, d2))


def test_pcg_from_a_start_and_zero_right_hand_side() -> None:
    n = 100
    M = _laplacian_gram(n)
    d2 = np.ones(n)
    K = M + 0.5 * sp.eye(n)
    X, products, ok = pcg(lambda Q: K @ Q, np.zeros((n, 2)), lambda Q: Q, 0.5, d2)
    assert ok and products == 0 and not X.any()
    R = np.random.default_rng(2).normal(size=(n, 2))
    exact = np.linalg.solve(K.toarray(), R)
    X, _, ok = pcg(lambda Q: K @ Q, R, lambda Q: Q, 0.5, d2, x0=exact * 0.9, rtol=1e-11)
    assert ok and np.allclose(X, exact, rtol=0, atol=1e-9 * np.abs(exact).max())
