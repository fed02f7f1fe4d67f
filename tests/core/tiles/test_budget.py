"""The coordinator: sum of exact shares meets tau, from models that are only approximate."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from service.core.tiles.budget import PhiModel, model_root, solve_budget


def _shares(a: np.ndarray, b: np.ndarray, order: int = 2):
    """phi_t(lambda) = sum_j a_tj (b_tj / (b_tj + lambda))^(2k): Tikhonov-like shares."""

    def phi(lam: float) -> list[float]:
        return [
            float(np.sum(ai * (bi / (bi + lam)) ** (2 * order)))
            for ai, bi in zip(a, b, strict=True)
        ]

    return phi


@pytest.mark.parametrize("seed", range(5))
def test_solve_budget_meets_tau_within_xi(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.1, 1.0, (16, 50))
    b = 10 ** rng.uniform(-3, 1, (16, 50))
    phi = _shares(a, b)
    tau = 0.3 * sum(phi(0.0))
    exact = brentq(lambda lam: sum(phi(lam)) - tau, 1e-9, 1e6, xtol=1e-14)
    # models: three samples per tile at tile-specific lambdas, the core ratio off by 10 %
    models = []
    for t in range(16):
        lams = exact * 10 ** rng.uniform(-1, 1, 3)
        models.append(PhiModel.of([(lam, phi(lam)[t] * 1.1) for lam in lams], 1.0))
    calls: list[float] = []

    def evaluate(lam: float) -> list[float]:
        calls.append(lam)
        return phi(lam)

    res = solve_budget(tau, models, evaluate, tolerance=1e-3)
    assert res.converged
    assert abs(sum(phi(res.lam)) - tau) / tau <= 1e-3
    assert res.phi == pytest.approx(sum(phi(res.lam)), rel=1e-12)
    assert res.lam == pytest.approx(exact, rel=2e-2)
    assert len(calls) == res.rounds <= 5


def test_model_interpolates_and_extrapolates_log_log() -> None:
    m = PhiModel.of([(1.0, 8.0), (4.0, 2.0)], 0.5)
    assert m(2.0) == pytest.approx(0.5 * 4.0)  # slope -1 in log-log
    assert m(8.0) == pytest.approx(0.5 * 1.0)  # extrapolated with the end slope
    assert model_root(m, 1.0, 1.0, 2.0) == pytest.approx(4.0, rel=1e-9)  # bracket widened
