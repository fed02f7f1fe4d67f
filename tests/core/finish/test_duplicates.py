"""Exact duplicates end exactly together (issue 40)."""

from __future__ import annotations

import numpy as np

from service.core import Geometry, SmoothingParams, smooth
from service.core.finish.duplicates import join_duplicates


def test_groups_get_their_mean_and_fixed_groups_the_input() -> None:
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0], [2, 0, 0], [1, 0, 0], [0, 0, 0]])
    X = P + np.arange(18, dtype=float).reshape(6, 3) * 0.01
    fixed = np.zeros(6, dtype=bool)
    Y = join_duplicates(P, X, fixed)
    assert np.allclose(Y[[0, 2, 5]], X[[0, 2, 5]].mean(axis=0))
    assert np.allclose(Y[[1, 4]], X[[1, 4]].mean(axis=0))
    assert np.array_equal(Y[3], X[3])  # no copy: untouched
    fixed[4] = True
    Z = join_duplicates(P, X, fixed)
    assert np.array_equal(Z[1], P[1]) and np.array_equal(Z[4], P[4])
    distinct = X[[0, 1, 3]]
    assert join_duplicates(P[[0, 1, 3]], distinct, fixed[[0, 1, 3]]) is distinct


def test_duplicated_cloud_points_end_together() -> None:
    rng = np.random.default_rng(2)
    Q = rng.normal(size=(3000, 3))
    Q /= np.linalg.norm(Q, axis=1, keepdims=True)
    Q += 0.01 * rng.normal(size=(3000, 1)) * Q
    src = rng.choice(3000, 15, replace=False)
    P = np.vstack([Q, Q[src]])
    res = smooth(Geometry(P), SmoothingParams())
    X = res.points
    assert not np.allclose(X, P)  # smoothed
    assert np.array_equal(X[src], X[3000:])
