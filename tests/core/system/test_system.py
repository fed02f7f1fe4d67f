"""SmoothingSystem and Deviation (service/core/system/deviation.py) against dense oracles."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.build import build_laplacian
from service.core.system.deviation import Deviation, SmoothingSystem
from service.core.system.elimination import laplacian_system
from tests.core.core_fixtures import noisy_icosphere


def _dense_iterated(
    M: np.ndarray, d2: np.ndarray, b: np.ndarray, U0: np.ndarray, lam: float, k: int
) -> np.ndarray:
    """U_k by the definition: U_1 = argmin ||AU-g||^2 + lam||D(U-U0)||^2 (normal equations),
    U_{j+1} = U_j + S0(U0 - U_j) with the homogeneous smoother S0(V) = K^-1 lam D^2 V."""
    K = M + lam * np.diag(d2)
    U = np.linalg.solve(K, b + lam * d2[:, None] * U0)
    for _ in range(k - 1):
        U = U + np.linalg.solve(K, lam * d2[:, None] * (U0 - U))
    return U


def _random_system(seed: int = 0, fixed: bool = True) -> tuple[SmoothingSystem, np.ndarray]:
    rng = np.random.default_rng(seed)
    P, F = noisy_icosphere(1, 0.05, seed=seed)
    g = Geometry(P, faces=F)
    L = build_laplacian(g, SmoothingParams(lam=1.0))[0]
    mask = np.zeros(len(P), dtype=bool)
    if fixed:
        mask[[0, 7, 11]] = True
    omega = rng.uniform(0.5, 2.0, len(P))
    return laplacian_system(L, P, omega, mask), L.toarray()


@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("solver", ["cholmod", "superlu", "cg"])
def test_deviation_matches_dense_iterated_tikhonov(order: int, solver: str) -> None:
    system, _ = _random_system()
    M = system.explicit().toarray()
    dev = Deviation(system, solver=solver, order=order)  # type: ignore[arg-type]
    for lam in (0.03, 0.3, 3.0):
        U = _dense_iterated(M, system.d2, system.b, system.U0, lam, order)
        E = U - system.U0
        np.testing.assert_allclose(dev.solution(lam), U, atol=1e-9 * np.abs(E).max())
        phi = float(np.sum(system.d2[:, None] * E**2))
        assert dev.value(lam) == pytest.approx(phi, rel=1e-8)


@pytest.mark.parametrize("order", [1, 3])
def test_filter_is_one_minus_ratio_to_the_k(order: int) -> None:
    """Without fixed points the kept filter is 1 - (mu/(mu+lam))^k in the generalized
    eigenbasis of (M, D^2) (module docstring of service.core.system.deviation)."""
    system, _ = _random_system(fixed=False)
    M, d = system.explicit().toarray(), np.sqrt(system.d2)
    mu, V = np.linalg.eigh(M / d[:, None] / d[None, :])
    mu = np.clip(mu, 0, None)
    lam = 0.2
    Y0 = d[:, None] * system.U0
    kept = 1 - (mu / (mu + lam)) ** order
    X = (V @ (kept[:, None] * (V.T @ Y0))) / d[:, None]
    dev = Deviation(system, solver="cholmod", order=order)
    np.testing.assert_allclose(dev.solution(lam), X, atol=1e-9)


@pytest.mark.parametrize("order", [1, 2])
def test_derivative_matches_finite_difference(order: int) -> None:
    system, _ = _random_system()
    dev = Deviation(system, solver="cholmod", order=order)
    lam, h = 0.1, 1e-5
    fd = (dev.value(lam * (1 + h)) - dev.value(lam * (1 - h))) / (2 * lam * h)
    assert dev.derivative(lam) == pytest.approx(fd, rel=1e-6)


def test_reweighted_reuses_the_analysis_and_matches_a_fresh_system() -> None:
    system, _ = _random_system()
    dev = Deviation(system, solver="cholmod")
    dev(0.1)
    d2 = system.d2 * np.linspace(0.5, 2.0, system.size)
    again = dev.reweighted(d2)
    assert again.stats.analysis == 0.0
    fresh = Deviation(SmoothingSystem(system.M, d2, system.b, system.U0), solver="superlu")
    np.testing.assert_allclose(again.solution(0.1), fresh.solution(0.1), atol=1e-10)


def test_phi0_closed_form_is_the_limit() -> None:
    system, _ = _random_system(fixed=False)
    assert system.phi0 is not None
    dev = Deviation(system, solver="cholmod")
    assert dev.value(dev.floor * 1e3) == pytest.approx(system.phi0, rel=1e-6)


def test_lambda_floor_is_a_typed_error() -> None:
    """Issue 15: lam <= 1e-16 returned phi > phi(0) with the points collapsed; now an error."""
    from service.core import ParameterError

    P, F = noisy_icosphere(2, 0.02)
    with pytest.raises(ParameterError) as info:
        smooth(Geometry(P, faces=F), SmoothingParams(lam=1e-16))
    assert info.value.field == "params.lam"


def test_generic_system_not_a_laplacian() -> None:
    """A SmoothingSystem for another least-squares operator A (one unknown per point)."""
    rng = np.random.default_rng(3)
    A = sp.random(40, 25, density=0.2, random_state=4) + sp.eye(40, 25)
    g = rng.normal(size=(40, 1))
    U0 = rng.normal(size=(25, 1))
    d2 = rng.uniform(0.5, 2, 25)
    system = SmoothingSystem((A.T @ A).tocsr(), d2, A.T @ g, U0)
    dev = Deviation(system, solver="cholmod", order=2)
    Ad = A.toarray()
    U = _dense_iterated(Ad.T @ Ad, d2, Ad.T @ g, U0, 0.7, 2)
    np.testing.assert_allclose(dev.solution(0.7), U, atol=1e-10)
