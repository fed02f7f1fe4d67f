"""The spectral view of report section 5 (eq. 12) and the diagnostics it feeds."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.build import build_laplacian
from tests.core.core_fixtures import noisy_icosphere


def test_solution_equals_filtered_svd_expansion_identity_weights() -> None:
    P, F = noisy_icosphere(1, 0.05)
    g = Geometry(P, faces=F)
    lam = 0.3
    res = smooth(g, SmoothingParams(lam=lam, spectrum=True, preset="report"))
    L = build_laplacian(g, SmoothingParams(lam=lam, preset="report"))[0].toarray()
    _, sig, vt = np.linalg.svd(L)  # independent dense SVD (eq. 12)
    gamma = lam / (sig**2 + lam)
    X = vt.T @ (gamma[:, None] * (vt @ P))
    np.testing.assert_allclose(res.points, X, atol=1e-10)
    np.testing.assert_allclose(res.spectrum.sigma, sig, atol=1e-12)
    np.testing.assert_allclose(res.spectrum.gamma, gamma, atol=1e-12)
    assert res.spectrum.sigma[-1] == pytest.approx(0.0, abs=1e-12)  # L has zero row sums
    assert res.spectrum.gamma[-1] == pytest.approx(1.0)
    assert max(res.spectrum.sigma) ** 2 <= 4.0 + 1e-9  # eq. (19) bound seen in practice


def test_generalized_singular_values_with_weights() -> None:
    P, F = noisy_icosphere(1, 0.05)
    omega = np.random.default_rng(3).uniform(0.5, 2.0, len(P))
    g = Geometry(P, faces=F, weights=omega)
    lam = 0.2
    res = smooth(g, SmoothingParams(lam=lam, spectrum=True, preset="report"))
    L = build_laplacian(g, SmoothingParams(lam=lam, preset="report"))[0].toarray()
    # generalized singular values of (L, D): sigma with L^T L v = sigma^2 D^2 v
    ev = np.sort(np.linalg.eigvals(np.linalg.solve(np.diag(omega**2), L.T @ L)).real)[::-1]
    np.testing.assert_allclose(res.spectrum.sigma**2, np.clip(ev, 0, None), atol=1e-9)


def test_spectrum_size_limit_is_a_warning() -> None:
    P, F = noisy_icosphere(5, 0.001)  # 10242 points > SPECTRUM_MAX_POINTS
    res = smooth(Geometry(P, faces=F), SmoothingParams(lam=0.1, spectrum=True, preset="report"))
    assert res.spectrum is None
    assert any(w.code == "spectrum-unavailable" for w in res.warnings)
