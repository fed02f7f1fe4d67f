"""build_operator(): reuse across tau, the per-input cache and its invalidation."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, ParameterError, SmoothingParams, smooth
from service.core.linalg import cache
from service.core.operator.build import build_operator
from tests.core.core_fixtures import noisy_icosphere


def test_prebuilt_operator_gives_the_same_result_at_several_tau() -> None:
    P, F = noisy_icosphere(2, 0.02)
    g = Geometry(P, faces=F)
    cache.clear()
    op = build_operator(g, SmoothingParams(tau=1.0))
    for tau in (0.01, 0.05):
        a = smooth(g, SmoothingParams(tau=tau), operator=op)
        cache.clear()
        b = smooth(g, SmoothingParams(tau=tau))
        np.testing.assert_array_equal(a.points, b.points)


def test_operator_of_another_geometry_is_refused() -> None:
    P, F = noisy_icosphere(1, 0.02)
    op = build_operator(Geometry(P, faces=F), SmoothingParams(tau=1.0))
    with pytest.raises(ParameterError) as info:
        smooth(Geometry(P * 1.01, faces=F), SmoothingParams(tau=0.01), operator=op)
    assert info.value.field == "operator"
    with pytest.raises(ParameterError):
        smooth(Geometry(P, faces=F), SmoothingParams(tau=0.01, weights="mean-value"), operator=op)


def test_operator_cache_hits_and_any_change_misses() -> None:
    P, F = noisy_icosphere(1, 0.02)
    params = SmoothingParams(tau=0.01)
    cache.clear()
    a = build_operator(Geometry(P, faces=F), params)
    assert build_operator(Geometry(P.copy(), faces=F.copy()), params) is a
    F2 = F.copy()
    F2[0] = F2[0, ::-1]  # same triangle, other winding: connectivity data changed
    assert build_operator(Geometry(P, faces=F2), params) is not a
    P2 = P.copy()
    P2[3, 0] += 1e-12
    assert build_operator(Geometry(P2, faces=F), params) is not a
    assert build_operator(Geometry(P, faces=F), SmoothingParams(tau=0.01, k=13)) is not a


def test_analysis_cache_follows_the_sparsity_pattern(monkeypatch: pytest.MonkeyPatch) -> None:
    """One symbolic analysis per pattern: a second tau reuses it; fixing points or changing
    the connectivity changes the pattern and triggers a new analysis."""
    from service.core.linalg import solver

    calls = {"n": 0}
    real = solver._cholmod.analyze

    def counting(*args: object, **kwargs: object) -> object:
        calls["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(solver._cholmod, "analyze", counting)
    cache.clear()
    P, F = noisy_icosphere(2, 0.02)
    g = Geometry(P, faces=F)
    smooth(g, SmoothingParams(tau=0.05))
    smooth(g, SmoothingParams(tau=0.02))
    assert calls["n"] == 1
    smooth(Geometry(P, faces=F, fixed=[3]), SmoothingParams(tau=0.02))
    assert calls["n"] == 2
    far = np.argsort(np.linalg.norm(P - P[0], axis=1))[-2:]  # two vertices opposite vertex 0
    smooth(Geometry(P, faces=np.vstack([F, [[0, far[0], far[1]]]])), SmoothingParams(tau=0.02))
    assert calls["n"] == 3  # new edges: a new pattern
    keep = np.ones(len(F), dtype=bool)
    keep[5] = False  # a closed mesh minus one face keeps every edge: same pattern, cache hit
    smooth(Geometry(P, faces=F[keep]), SmoothingParams(tau=0.02))
    assert calls["n"] == 3


def test_presmooth_without_isolated_points_is_the_masked_iteration() -> None:
    """Every point with a neighbour: the averaging skips the masks, same bits; an isolated
    point added to the graph (masked path) leaves the others' results unchanged."""
    import scipy.sparse as sp

    from service.core.operator.laplacian import presmooth
    from service.core.operator.neighborhoods import mesh_neighborhoods

    P, F = noisy_icosphere(3, 0.05)
    A = mesh_neighborhoods(F, len(P)).adjacency
    fast = presmooth(P, A, 4)
    A1 = sp.csr_matrix(sp.block_diag([A, sp.csr_matrix((1, 1))]))
    masked = presmooth(np.vstack([P, [[9.0, 9.0, 9.0]]]), A1, 4)
    np.testing.assert_array_equal(fast, masked[:-1])
    np.testing.assert_array_equal(masked[-1], [9.0, 9.0, 9.0])
    W = np.diag(1.0 / A.toarray().sum(1)) @ A.toarray()  # dense reference
    X = P.copy()
    for _ in range(4):
        X = 0.5 * (X + W @ X)
    np.testing.assert_allclose(fast, X, rtol=0, atol=1e-13)
