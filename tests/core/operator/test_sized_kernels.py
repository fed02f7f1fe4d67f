"""The NumPy kernels small inputs take give the compiled kernels' outputs bit for bit."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from service.core.operator import kernels, sized_kernels


@pytest.fixture
def numpy_path() -> Iterator[Callable[..., Any]]:
    """Call a :mod:`sized_kernels` function on its NumPy path (as if numba were not loaded)."""

    def call(f: Callable[..., Any], *args: Any) -> Any:
        mod = sys.modules.pop("service.core.operator.kernels")
        try:
            return f(*args)
        finally:
            sys.modules["service.core.operator.kernels"] = mod

    yield call


def _same(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> bool:
    return all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("seed", range(40))
def test_patterns_and_covariances(seed: int, numpy_path: Callable[..., Any]) -> None:
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 300)), int(rng.integers(1, 16))
    i, j = rng.integers(0, n, 3 * n), rng.integers(0, n, 3 * n)
    assert _same(
        kernels.rows_from_pairs(i, j, n), numpy_path(sized_kernels.rows_from_pairs, i, j, n)
    )
    faces = np.unique(np.sort(rng.integers(0, n, (2 * n, 3)), axis=1), axis=0)  # with self-edges
    assert _same(kernels.mesh_rings(faces, n), numpy_path(sized_kernels.mesh_rings, faces, n))
    X = rng.standard_normal((n, int(rng.integers(1, 5)))) * 10.0 ** int(rng.integers(-3, 4))
    idx = rng.integers(0, n, (n, k))
    assert np.array_equal(
        kernels.neighbourhood_covariances(X, idx),
        numpy_path(sized_kernels.neighbourhood_covariances, X, idx),
    )


@pytest.mark.parametrize("seed", range(60))
def test_polar_hull_fans(seed: int, numpy_path: Callable[..., Any]) -> None:
    """Random, grid (collinear, coincident, zero) and near-grid neighbourhoods."""
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 200)), int(rng.integers(1, 16))
    if seed % 3 == 0:
        q = rng.integers(-2, 3, (n, m, 2)).astype(float)
    elif seed % 3 == 1:
        q = rng.standard_normal((n, m, 2))
    else:
        q = rng.integers(-3, 4, (n, m, 2)) * 0.1 + 1e-14 * rng.standard_normal((n, m, 2))
    assert _same(kernels.polar_hull_fans(q), numpy_path(sized_kernels.polar_hull_fans, q))
