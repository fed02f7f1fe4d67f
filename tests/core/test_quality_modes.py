"""The quality modes through smooth(): dense oracles, tau met within xi, GCV, preset."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.build import build_laplacian
from service.core.system.displacement import normal_frames
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def _cloud(n: int = 600, seed: int = 0) -> Geometry:
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    return Geometry(P + rng.normal(0, 0.02, P.shape))


def _helix(n: int = 150, seed: int = 0) -> Geometry:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 4 * np.pi, n)
    P = np.column_stack([np.cos(t), np.sin(t), 0.2 * t]) + rng.normal(0, 0.01, (n, 3))
    return Geometry(P, edges=polyline_edges(n))


def _mesh() -> Geometry:
    P, F = noisy_icosphere(2, 0.02, seed=3)
    return Geometry(P, faces=F)


INPUTS = {"mesh": _mesh, "curve": _helix, "cloud": _cloud}


def test_normal_mode_matches_dense_oracle() -> None:
    """x_i = p_i + t_i n_i, t = argmin sum_i (n_i . (L(P + N t))_i)^2 + lam ||t||^2, dense."""
    g = _mesh()
    lam = 0.05
    params = SmoothingParams(lam=lam, displacement="normal", weights="uniform", order=1)
    X = smooth(g, params).points
    L, nb, _, _ = build_laplacian(g, params)
    N = normal_frames(g.points, nb.adjacency, 1)[:, :, 0]
    Ld = L.toarray()
    A = Ld * (N @ N.T)  # A_ij = L_ij n_i . n_j
    rhs = -np.sum(N * (Ld @ g.points), axis=1)
    t = np.linalg.solve(A.T @ A + lam * np.eye(g.n), A.T @ rhs)
    np.testing.assert_allclose(X, g.points + t[:, None] * N, atol=1e-9)


@pytest.mark.parametrize("kind", sorted(INPUTS))
@pytest.mark.parametrize(
    "mode",
    [
        {"displacement": "free", "order": 1},
        {"displacement": "free", "order": 2},
        {"displacement": "normal", "order": 1},
        {"displacement": "normal", "order": 2},
    ],
    ids=["free-1", "free-2", "normal-1", "normal-2"],
)
@pytest.mark.parametrize("target", ["tau", "auto"])
def test_tau_met_within_tolerance_in_every_mode(kind: str, mode: dict, target: str) -> None:
    g = INPUTS[kind]()
    weights = {"weights": "uniform"} if kind != "curve" else {}
    if target == "tau":
        tau = 0.3 * g.n * 0.02**2
        res = smooth(g, SmoothingParams(tau=tau, tolerance=1e-4, **mode, **weights))
    else:
        res = smooth(g, SmoothingParams(tolerance=1e-4, **mode, **weights))
        tau = res.tau
        assert res.sigma_estimate is not None and res.sigma_estimate > 0
        assert res.tau_rule == "auto" and res.tau_how
    phi = float(np.sum((res.points - g.points) ** 2))  # unit weights
    assert res.converged and abs(phi - tau) / tau <= 1e-4
    assert res.displacement == mode["displacement"]


def test_automatic_tau_follows_the_noise() -> None:
    """Twice the noise, about four times the budget (direction only, with margin)."""
    taus = []
    for sigma in (0.01, 0.02):
        P, F = noisy_icosphere(3, sigma, seed=5)
        taus.append(smooth(Geometry(P, faces=F), SmoothingParams()).tau)
    assert 2.5 < taus[1] / taus[0] < 6.0


def test_gcv_minimizes_the_dense_gcv_score() -> None:
    """tau='gcv': the chosen lambda's exact GCV score is within 5 % of the dense minimum."""
    g = _helix(120)
    res = smooth(g, SmoothingParams(tau="gcv", weights="uniform", order=1, ends="pulled"))
    L, _, _, _ = build_laplacian(g, SmoothingParams(weights="uniform", ends="pulled"))
    mu, V = np.linalg.eigh((L.T @ L).toarray())
    n, s = g.points.shape
    c2 = np.sum((V.T @ g.points) ** 2, axis=1)

    def score(lam: float) -> float:  # residual filter mu / (mu + lam) in the eigenbasis
        f = mu / (mu + lam)
        return float(np.sum(f**2 * c2) / (n * s) / (np.sum(f) / n) ** 2)

    grid = np.logspace(-6, 3, 2000)
    best = min(score(x) for x in grid)
    assert res.tau_rule == "gcv" and res.tau is not None and res.relative_error == 0.0
    assert score(res.lam) <= 1.05 * best


def test_report_preset_reproduces_the_report() -> None:
    """preset='report' equals the report's explicit choices whatever the defaults are."""
    g = _mesh()
    a = smooth(g, SmoothingParams(tau=0.05, preset="report"))
    b = smooth(g, SmoothingParams(tau=0.05, weights="auto", laplacian="normalized",
                                  displacement="free", order=1, search="rational",
                                  solver="cholmod"))
    assert a.weights == "mean-value" and a.search == "rational"
    np.testing.assert_array_equal(a.points, b.points)


def test_gcv_displaces_freely() -> None:
    from service.core.errors import ParameterError

    g = _mesh()
    assert smooth(g, SmoothingParams(tau="gcv", order=1)).displacement == "free"
    with pytest.raises(ParameterError) as info:
        smooth(g, SmoothingParams(tau="gcv", displacement="normal"))
    assert info.value.field == "params.displacement"


def test_auto_displacement_falls_back_to_free_where_normals_cannot_move() -> None:
    """A flat cloud is smooth across itself; a mesh in 2-D has no normal: free displacement."""
    rng = np.random.default_rng(1)
    flat = np.column_stack([rng.uniform(size=(200, 2)), np.full(200, 0.5)])
    res = smooth(Geometry(flat), SmoothingParams(rms=0.01))
    assert res.displacement == "free" and res.converged
    from tests.core.core_fixtures import grid_mesh

    P, F = grid_mesh(8, 7, jitter=0.3)
    res2 = smooth(Geometry(P[:, :2], faces=F), SmoothingParams(lam=0.1))
    assert res2.displacement == "free"
