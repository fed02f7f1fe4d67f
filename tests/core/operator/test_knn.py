"""Coincident points in the k-NN searches (issue 42 item 5): collapsed to the distinct points
when their copies would make the search quadratic, with the exact distances of the k-d tree."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core import SmoothingParams, smooth
from service.core.geometry import Geometry
from service.core.operator import knn as knn_module
from service.core.operator.neighborhoods import knn as neighbourhood_knn


def _with_copies(distinct: int, copies: int, seed: int = 0) -> np.ndarray:
    """``distinct`` points on a sphere and ``copies`` more spread over 5 of them, shuffled."""
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(distinct, 3))
    P /= np.linalg.norm(P, axis=1)[:, None]
    P = np.vstack([P, np.repeat(P[:5], copies // 5, axis=0)])
    return P[rng.permutation(P.shape[0])]


def _recording(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The sizes of the point sets the k-d tree searches from now on."""
    calls: list[int] = []
    real = knn_module._tree

    def tree(Q: np.ndarray, k: int, at: np.ndarray) -> Any:
        calls.append(Q.shape[0])
        return real(Q, k, at)

    monkeypatch.setattr(knn_module, "_tree", tree)
    return calls


def _check_rows(P: np.ndarray, at: np.ndarray, dist: np.ndarray, idx: np.ndarray) -> None:
    k = idx.shape[1]
    reference, _ = cKDTree(P).query(P[at], k=k)
    np.testing.assert_allclose(dist, reference.reshape(dist.shape), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(idx[:, 0], at)  # the point itself first
    np.testing.assert_allclose(dist, np.linalg.norm(P[idx] - P[at][:, None], axis=2), atol=0)
    assert all(np.unique(row).size == k for row in idx)  # no point twice in a row


@pytest.mark.parametrize("grid_from", [100, 10**9])  # the grid path, then the k-d tree path
def test_copies_are_collapsed_with_exact_distances(
    monkeypatch: pytest.MonkeyPatch, grid_from: int
) -> None:
    monkeypatch.setattr(knn_module, "GRID_FROM", grid_from)
    knn_module.release()
    P = _with_copies(1500, 4000)
    searched = _recording(monkeypatch)
    dist, idx = knn_module.knn(P, 13)
    _check_rows(P, np.arange(P.shape[0]), dist, idx)
    at = np.arange(0, P.shape[0], 7)
    d2, i2 = knn_module.nearest(P, at, 6, 13)
    _check_rows(P, at, d2, i2)
    assert set(searched) <= {1500}  # only the distinct points, never the 5,500


def test_thousands_of_identical_points_never_reach_the_tree(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    knn_module.release()
    P = np.ones((20000, 3))
    calls = _recording(monkeypatch)
    dist, idx = neighbourhood_knn(P, 10)
    assert calls in ([], [1])  # at most the one distinct point
    assert not dist.any()
    assert (idx != np.arange(20000)[:, None]).all()  # itself excluded, its copies instead
    assert all(np.unique(row).size == 10 for row in idx[::97])


def test_a_few_copies_keep_the_plain_search() -> None:
    """Below the copies' cost bound the k-d tree's own answer is returned, index for index."""
    knn_module.release()
    P = _with_copies(3000, 20)
    d1, i1 = cKDTree(P).query(P, k=13)
    d2, i2 = knn_module.knn(P, 13)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_array_equal(d1, d2)


def test_a_cloud_of_copies_is_smoothed() -> None:
    """5,000 copies of one point beside a noisy sphere: the run ends, every point finite."""
    rng = np.random.default_rng(3)
    P = _with_copies(4000, 5000, seed=2)
    P = P + 0.002 * rng.normal(size=P.shape) * (np.arange(P.shape[0]) % 2)[:, None]
    res = smooth(Geometry(P), SmoothingParams())
    assert np.isfinite(res.points).all()
    assert res.points.shape == P.shape
