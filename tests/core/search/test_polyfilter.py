"""method="windowed-sinc" (service/core/search/polyfilter.py) against dense eigendecompositions."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import chebyshev as cheb

from service.core import Geometry, ParameterError, SmoothingParams, smooth
from service.core.operator.build import build_laplacian
from service.core.search.polyfilter import (
    SincFilter,
    chebyshev_moments,
    combine,
    max_degree,
    sinc_degree,
    sinc_deviation,
    windowed_sinc,
)
from tests.core.core_fixtures import noisy_icosphere


def _dense_case(seed: int = 0):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(120, 120))
    Mt = A @ A.T / 120
    mu, V = np.linalg.eigh(Mt)
    return Mt, np.clip(mu, 0, None), V, rng.normal(size=(120, 3))


def test_moments_and_filter_match_the_eigendecomposition() -> None:
    Mt, mu, V, c = _dense_case()
    mu_max = 1.05 * mu.max()
    x = np.clip(2 * mu / mu_max - 1, -1, 1)
    w = ((V.T @ c) ** 2).sum(axis=1)
    m, products = chebyshev_moments(lambda X: Mt @ X, c, mu_max, 9)
    assert products == 9
    np.testing.assert_allclose(
        m, [np.sum(w * np.cos(j * np.arccos(x))) for j in range(19)], rtol=1e-12, atol=1e-12 * m[0]
    )
    flt = SincFilter(-0.3, mu_max, 10)
    g, q = flt.kept(), flt.q()
    assert cheb.chebval(-1.0, g) == pytest.approx(1.0)  # smooth shapes kept exactly
    np.testing.assert_allclose(cheb.chebval(x, q) * mu, 1 - cheb.chebval(x, g), atol=1e-12)
    dense = V @ (cheb.chebval(x, q)[:, None] * (V.T @ c))
    np.testing.assert_allclose(sinc_deviation(lambda X: Mt @ X, c, flt), dense, atol=1e-12)


def test_kept_chebyshev_vectors_give_the_filter_in_one_pass() -> None:
    """combine(moments' vectors, q) = q(M_t) c (dense), to single precision, no more products."""
    Mt, mu, V, c = _dense_case(3)
    mu_max = 1.05 * mu.max()
    flt = SincFilter(-0.5, mu_max, 16)
    keep: list[np.ndarray] = []
    calls = []
    _m, products = chebyshev_moments(lambda X: calls.append(1) or Mt @ X, c, mu_max, 15, keep)
    assert len(keep) == 16 and len(calls) == products == 15
    x = np.clip(2 * mu / mu_max - 1, -1, 1)
    dense = V @ (cheb.chebval(x, flt.q())[:, None] * (V.T @ c))
    out = combine(keep, flt.q())
    assert np.linalg.norm(out - dense) <= 1e-6 * np.linalg.norm(dense)
    assert len(calls) == 15


def test_windowed_sinc_with_point_weights_meets_tau() -> None:
    P, F = noisy_icosphere(3, 0.03)
    w = np.random.default_rng(4).uniform(0.5, 2.0, len(P))
    res = smooth(Geometry(P, faces=F, weights=w), SmoothingParams(rms=0.01, method="windowed-sinc"))
    assert res.converged and res.relative_error <= 1e-3
    phi = float(np.sum(w[:, None] ** 2 * (res.points - P) ** 2))
    assert phi == pytest.approx(res.phi, rel=1e-8)


@pytest.mark.parametrize("fixed", [False, True])
def test_windowed_sinc_meets_tau_without_factorization(fixed: bool) -> None:
    P, F = noisy_icosphere(3, 0.03)
    g = Geometry(P, faces=F, fixed=np.arange(0, len(P), 30) if fixed else None)
    for rms in (0.003, 0.02):
        res = smooth(g, SmoothingParams(rms=rms, method="windowed-sinc"))
        assert res.converged and res.relative_error <= 1e-3
        assert res.factorizations == 0 and res.solves == 0 and res.matvecs > 0
        assert res.solver == "none" and res.report()["method"] == "windowed-sinc"
        phi = float(np.sum((res.points - P) ** 2))
        assert phi == pytest.approx(res.phi, rel=1e-8)
        if fixed:
            assert np.array_equal(res.points[g.fixed], P[g.fixed])


def test_windowed_sinc_is_the_dense_filter_of_the_same_operator() -> None:
    """X = P + D^-1 q(M_t) c with the pass band the result reports (no fixed points)."""
    P, F = noisy_icosphere(2, 0.03)
    g = Geometry(P, faces=F)
    res = smooth(g, SmoothingParams(rms=0.01, method="windowed-sinc"))
    L = build_laplacian(g, SmoothingParams(lam=1.0))[0].toarray()
    Mt = L.T @ L
    mu_max = 1.01 * (np.abs(L).T @ (np.abs(L) @ np.ones(len(P)))).max()  # Gershgorin of |L|^T|L|
    flt = SincFilter(2 * res.lam / mu_max - 1, mu_max, sinc_degree(res.lam, mu_max))
    mu, V = np.linalg.eigh(Mt)
    x = np.clip(2 * np.clip(mu, 0, None) / mu_max - 1, -1, 1)
    kept = cheb.chebval(x, flt.kept())
    X = V @ (kept[:, None] * (V.T @ P))
    np.testing.assert_allclose(res.points, X, atol=1e-8)


def test_windowed_sinc_needs_the_normalized_laplacian() -> None:
    P, F = noisy_icosphere(1, 0.03)
    with pytest.raises(ParameterError) as info:
        smooth(
            Geometry(P, faces=F),
            SmoothingParams(rms=0.01, method="windowed-sinc", laplacian="feature"),
        )
    assert info.value.field == "params.method"


def test_the_degree_resolves_the_pass_band() -> None:
    """degree >= 2 sqrt(mu_max / mu_pb), doubling from 24: 4 -> 24, 200 -> 384, capped at 768."""
    assert sinc_degree(0.25, 1.0) == 24
    assert sinc_degree(1e-4, 1.0) == 384  # needs 200: 24, 48, 96, 192 are too coarse
    assert sinc_degree(1e-12, 1.0) == 768


def test_the_degree_cap_follows_the_size_not_the_budget() -> None:
    """degree * unknowns <= MAX_WORK (1e8), never below 96: 1M unknowns 96, 164K 384, 10K 768."""
    assert max_degree(1_000_000) == 96
    assert max_degree(163_842) == 384
    assert max_degree(10_000) == 768
    assert max_degree(10**9) == 96


def test_a_budget_beyond_the_shape_stops_at_the_cap(monkeypatch: pytest.MonkeyPatch) -> None:
    """tau twice phi(0) (no pass band meets it): the degree stops at the size's cap (192, then
    96: 191, then 95 products; 768 uncapped), and phi is the dense filter's for the band
    returned."""
    from service.core.search import polyfilter

    Mt, mu, V, c = _dense_case(5)
    mu_max = 1.05 * mu.max()
    w = ((V.T @ c) ** 2).sum(axis=1)
    tau = 2.0 * float(np.sum(w / mu**2))  # phi(0): every mode removed
    calls: list[int] = []

    def op(X: np.ndarray) -> np.ndarray:
        calls.append(1)
        return Mt @ X

    x = np.clip(2 * mu / mu_max - 1, -1, 1)
    for cap in (192, 96):
        monkeypatch.setattr(polyfilter, "MAX_WORK", cap * c.size)
        calls.clear()
        flt, phi, _ = windowed_sinc(op, c, tau, mu_max)
        assert flt.degree == cap and len(calls) == cap - 1
        assert phi == pytest.approx(float(np.sum(w * cheb.chebval(x, flt.q()) ** 2)), rel=1e-9)
        assert phi < tau


def test_a_narrow_pass_band_on_a_curve_is_the_dense_filter() -> None:
    """lam given: X = P + q(M) P with the resolving degree, on a closed curve (no fixed points),
    and the resolved filter keeps the large shape: the circle's radius shrinks less than 1 %."""
    n = 200
    t = 2 * np.pi * np.arange(n) / n
    P = np.column_stack([np.cos(t), np.sin(t)])
    P = P + 0.02 * np.random.default_rng(1).normal(size=P.shape)
    E = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    g = Geometry(P, edges=E)
    lam = 1e-4
    res = smooth(g, SmoothingParams(lam=lam, method="windowed-sinc"))
    L = build_laplacian(g, SmoothingParams(lam=1.0))[0].toarray()
    mu_max = 1.01 * (np.abs(L).T @ (np.abs(L) @ np.ones(n))).max()
    degree = sinc_degree(lam, mu_max)
    assert degree >= 2 * np.sqrt(mu_max / lam)
    mu, V = np.linalg.eigh(L.T @ L)
    x = np.clip(2 * np.clip(mu, 0, None) / mu_max - 1, -1, 1)
    kept = cheb.chebval(x, SincFilter(2 * lam / mu_max - 1, mu_max, degree).kept())
    np.testing.assert_allclose(res.points, V @ (kept[:, None] * (V.T @ P)), atol=1e-8)
    radius = np.linalg.norm(res.points - res.points.mean(axis=0), axis=1).mean()
    assert radius > 0.99
