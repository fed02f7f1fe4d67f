"""The lambda search (issue 8): quadrature bounds, safeguarded Newton, tau met on every job
kind, the matrix-free path against the dense oracle at the lambda found."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.linalg.krylov import lanczos, log_bisect
from service.core.operator.build import build_laplacian
from service.core.search.roots import estimate_lambda, newton_search, unresolved_below
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def _spectral_phi(mu: np.ndarray, c2: np.ndarray, k: int = 1):
    return lambda lam: float(np.sum(c2 * mu ** (2 * k - 2) / (mu + lam) ** (2 * k)))


@pytest.mark.parametrize("order", [1, 2, 3])
def test_newton_never_leaves_the_bracket_and_is_monotone_from_the_left(order: int) -> None:
    rng = np.random.default_rng(order)
    mu = np.sort(rng.uniform(1e-4, 4, 300))
    c2 = rng.uniform(0, 1, 300) * mu**2
    phi = _spectral_phi(mu, c2, order)
    dphi = lambda lam: float(  # noqa: E731
        -2 * order * np.sum(c2 * mu ** (2 * order - 2) / (mu + lam) ** (2 * order + 1))
    )
    tau = 0.2 * phi(1e-9)
    root = log_bisect(phi, tau, 1e-12, 1e6, rtol=1e-13)
    lo, hi = 1e-12, math.sqrt(c2.sum() / tau)
    assert phi(hi) <= tau  # the a-priori ceiling ||c|| / sqrt(tau)
    for lam0 in (root * 1e-3, root * 0.5, root * 3, hi):
        res = newton_search(phi, dphi, tau, lam0, lo, hi, order=order, tolerance=1e-10)
        assert res.converged and abs(res.lam / root - 1) < 1e-8
        lams = [lam for lam, _ in res.history]
        assert all(lo <= lam <= hi for lam in lams)
        left = [lam for lam, p in res.history if p > tau]  # from the left: increasing, < root
        assert left == sorted(left) and all(lam <= root * (1 + 1e-9) for lam in left)


def test_newton_stops_when_rounding_swamps_phi() -> None:
    """A ``phi`` that is not monotone in lambda (a solve's rounding at tiny lambdas) ends the
    search as soon as it shows (not converged, the closest value kept) instead of running the
    evaluation cap; on a resolved ``phi`` the guard never fires (test above)."""
    mu = np.geomspace(1e-6, 4, 300)
    exact = _spectral_phi(mu, mu**2)
    rng = np.random.default_rng(0)
    noisy = lambda lam: exact(lam) * float(rng.uniform(0.1, 10))  # noqa: E731
    dphi = lambda lam: float(-2 * np.sum(mu**2 / (mu + lam) ** 3))  # noqa: E731
    tau = 0.5 * exact(1e-3)
    res = newton_search(noisy, dphi, tau, 1e-3, 1e-12, 1e6, tolerance=1e-10, max_iterations=50)
    assert not res.converged
    assert len(res.history) < 10
    assert abs(res.phi - tau) == min(abs(p - tau) for _, p in res.history)
    lams, phis = zip(*res.history, strict=True)
    order = np.argsort(lams)
    assert np.any(np.diff(np.asarray(phis)[order]) > 0)  # the rise that stopped it
    worst = unresolved_below(res.history)
    assert worst is not None and worst in lams
    assert unresolved_below([(1.0, 3.0), (2.0, 2.0), (4.0, 1.0)]) is None
    assert unresolved_below([(1.0, 3.0), (2.0, 2.0), (1.5, 1.0)]) == 2.0  # rose below 2.0


def test_quadrature_bounds_bracket_lambda_star() -> None:
    """Gauss (lower) and Gauss-Radau (upper) bounds of lambda* from Lanczos on M_t."""
    P, F = noisy_icosphere(2, 0.05, seed=3)
    L = build_laplacian(Geometry(P, faces=F), SmoothingParams(lam=1.0))[0].toarray()
    d2 = np.random.default_rng(0).uniform(0.5, 2, len(P))
    d = np.sqrt(d2)
    Mt = (L.T @ L) / d[:, None] / d[None, :]
    mu, V = np.linalg.eigh(Mt)
    c = -(Mt @ (d[:, None] * P))  # D^-1 r with r = -M P
    c2 = ((V.T @ c) ** 2).sum(axis=1)
    phi = _spectral_phi(np.clip(mu, 0, None), c2)
    for frac in (0.9, 0.3, 0.03):
        tau = frac * phi(1e-12)
        root = log_bisect(phi, tau, 1e-12, 1e6, rtol=1e-13)
        for steps in (5, 15, 40):
            _, lower, upper, _ = estimate_lambda(
                lambda X: Mt @ X, c, tau, 1e-12, 1e6, max_steps=steps, ratio=1.0
            )
            assert lower <= root * (1 + 1e-9) and upper >= root * (1 - 1e-9), (frac, steps)
        gauss, radau, _ = lanczos(lambda X: Mt @ X, c, 60)
        assert gauss.phi(root) <= tau * (1 + 1e-9) <= radau.phi(root) * (1 + 2e-9)


def _job_kinds() -> list[tuple[str, Geometry, dict]]:
    rng = np.random.default_rng(9)
    P, F = noisy_icosphere(3, 0.02)
    t = np.sort(rng.uniform(0, 6, 400))
    curve = np.c_[np.cos(t), np.sin(t), t / 5] + rng.normal(0, 0.01, (400, 3))
    Q = rng.normal(size=(1500, 3))
    Q /= np.linalg.norm(Q, axis=1)[:, None]
    cloud = Q + rng.normal(0, 0.02, Q.shape)
    w = rng.uniform(0.5, 2, len(P))
    return [
        ("mesh", Geometry(P, faces=F), {}),
        ("mesh-fixed", Geometry(P, faces=F, fixed=np.arange(0, len(P), 40)), {}),
        ("mesh-weights", Geometry(P, faces=F, weights=w), {}),
        ("mesh-kappa", Geometry(P, faces=F), {"laplacian": "curvature"}),
        ("mesh-feature", Geometry(P, faces=F), {"laplacian": "feature"}),
        ("mesh-order2", Geometry(P, faces=F), {"order": 2}),
        ("curve", Geometry(curve, edges=polyline_edges(400)), {"fix_boundary": True}),
        ("cloud", Geometry(cloud), {}),
        ("cloud-knn", Geometry(cloud), {"neighborhood": "knn"}),
    ]


@pytest.mark.parametrize(("name", "g", "kw"), _job_kinds(), ids=[j[0] for j in _job_kinds()])
def test_tau_met_on_every_job_kind_in_few_factorizations(name: str, g: Geometry, kw: dict) -> None:
    span = float(np.ptp(g.points, axis=0).max())
    for rms in (0.002 * span, 0.02 * span):
        res = smooth(g, SmoothingParams(rms=rms, **kw))
        assert res.converged and res.relative_error <= 1e-3, (name, rms, res.history)
        assert res.factorizations <= 3, (name, rms, res.history)
        phi = float(np.sum(g.omega()[:, None] ** 2 * (res.points - g.points) ** 2))
        assert phi == pytest.approx(res.phi, rel=1e-8)


@pytest.mark.parametrize(
    ("name", "g", "kw"),
    [
        j
        for j in _job_kinds()
        if j[0] in ("mesh", "mesh-fixed", "mesh-weights", "curve", "cloud", "mesh-order2")
    ],
    ids=["mesh", "mesh-fixed", "mesh-weights", "mesh-order2", "curve", "cloud"],
)
def test_matrix_free_path_meets_tau_and_matches_the_dense_oracle(
    name: str, g: Geometry, kw: dict
) -> None:
    span = float(np.ptp(g.points, axis=0).max())
    kw = {"displacement": "free", "order": 1, **kw}  # the oracle below is eq. (4)
    res = smooth(g, SmoothingParams(rms=0.005 * span, solver="cg", **kw))
    assert res.solver == "cg" and res.factorizations == 0
    assert res.converged and res.relative_error <= 1e-3
    # dense oracle at the lambda found: iterated Tikhonov on the normal equations
    L = build_laplacian(
        g, SmoothingParams(lam=1.0, **{k: v for k, v in kw.items() if k != "order"})
    )[0].toarray()
    fixed = g.fixed_mask()
    if kw.get("fix_boundary"):
        fixed[[0, len(fixed) - 1]] = True
    F, C = ~fixed, fixed
    P, w2 = g.points, g.omega() ** 2
    A = L[F][:, F]
    K = A.T @ A + res.lam * np.diag(w2[F])
    U = np.linalg.solve(K, -A.T @ (L[F][:, C] @ P[C]) + res.lam * w2[F, None] * P[F])
    for _ in range(kw.get("order", 1) - 1):
        U = U + np.linalg.solve(K, res.lam * w2[F, None] * (P[F] - U))
    E = U - P[F]
    assert np.linalg.norm(res.points[F] - U) <= 1e-6 * np.linalg.norm(E)
