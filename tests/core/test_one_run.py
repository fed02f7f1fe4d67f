"""The one-run Lanczos solver (issue 30) against dense exact solves on small systems.

Systems are built here from a graph Laplacian (no engine module besides the two under test):
eq. (4) with fixed points eliminated (section 8: ``M = L_F^T L_F``, ``b = -L_F^T L_C P_C``,
``U0 = P_F``), a one-column system like the normal displacement's (``U0 = 0``), orders 1 and 2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize_scalar

from service.core.linalg.lanczos_run import LanczosRun, true_residual_bound
from service.core.search.one_run import one_run
from service.core.search.risk import invariant_radius, probe_block
from service.core.search.risk_rule import RiskRule


def _grid_laplacian(nu: int, nv: int) -> sp.csr_matrix:
    """Uniform Laplacian ``I - A / deg`` of a periodic ``nu x nv`` grid (8-neighbour)."""
    idx = np.arange(nu * nv).reshape(nu, nv)
    rows, cols = [], []
    for du, dv in ((0, 1), (1, 0), (1, 1), (1, -1)):
        j = np.roll(np.roll(idx, -du, 0), -dv, 1)
        rows += [idx.ravel(), j.ravel()]
        cols += [j.ravel(), idx.ravel()]
    r, c = np.concatenate(rows), np.concatenate(cols)
    A = sp.csr_matrix((np.ones(r.size), (r, c)), shape=(nu * nv,) * 2)
    deg = np.asarray(A.sum(axis=1)).ravel()
    return sp.csr_matrix(sp.identity(nu * nv) - sp.diags(1 / deg) @ A)


def _torus_points(nu: int, nv: int, noise: float, seed: int = 0) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False),
                       np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")  # fmt: skip
    P = np.stack([(1 + 0.4 * np.cos(v)) * np.cos(u), (1 + 0.4 * np.cos(v)) * np.sin(u),
                  0.4 * np.sin(v)], -1).reshape(-1, 3)  # fmt: skip
    return P + np.random.default_rng(seed).normal(0, noise, P.shape)


class System:
    """``min ||A U - g||^2 + lambda ||D (U - U0)||^2`` formed densely and as products."""

    def __init__(self, A: sp.spmatrix, g: np.ndarray, U0: np.ndarray, d2: np.ndarray) -> None:
        self.M = sp.csr_matrix(A.T @ A)
        self.b = np.asarray(A.T @ g)
        self.U0, self.d2 = U0, d2
        self.d = np.sqrt(d2)[:, None]
        self.r = self.b - self.M @ U0
        self.c = self.r / self.d
        Mt = (self.M.toarray() / self.d) / self.d.T
        self.mu, self.Q = np.linalg.eigh(0.5 * (Mt + Mt.T))
        self.mu = np.maximum(self.mu, 0.0)
        self.floor = 1e-13 * self.mu.max()

    def apply(self, V: np.ndarray) -> np.ndarray:
        return np.asarray(self.M @ (V / self.d)) / self.d

    def phi(self, lam: float, k: int) -> float:
        c2 = np.sum((self.Q.T @ self.c) ** 2, axis=1)
        return float(np.sum(c2 * self.mu ** (2 * k - 2) / (self.mu + lam) ** (2 * k)))

    def exact_e(self, lam: float, k: int) -> np.ndarray:
        """``E_k = U - U0`` by dense solves (Deviation's recurrence)."""
        K = self.M.toarray() + lam * np.diag(self.d2)
        E = np.linalg.solve(K, self.b + lam * self.d2[:, None] * self.U0) - self.U0
        for _ in range(1, k):
            E = E - lam * np.linalg.solve(K, self.d2[:, None] * E)
        return E

    def root(self, tau: float, k: int) -> float:
        a, b = math.log(self.floor), math.log(1e6)
        for _ in range(200):
            m = 0.5 * (a + b)
            a, b = (m, b) if self.phi(math.exp(m), k) > tau else (a, m)
        return math.exp(0.5 * (a + b))


def _free(nu: int = 12, nv: int = 10, fixed_every: int = 0, weights: bool = False) -> System:
    L = _grid_laplacian(nu, nv)
    P = _torus_points(nu, nv, 0.02)
    n = P.shape[0]
    fixed = np.zeros(n, bool)
    if fixed_every:
        fixed[::fixed_every] = True
    F, C = np.flatnonzero(~fixed), np.flatnonzero(fixed)
    L_F, L_C = L[F][:, F], L[F][:, C]
    g = -(L_C @ P[C]) if C.size else np.zeros((F.size, 3))
    w = np.random.default_rng(3).uniform(0.5, 2.0, n) if weights else np.ones(n)
    return System(L_F, g, P[F], w[F] ** 2)


def _normal(nu: int = 12, nv: int = 10) -> System:
    """One unknown per point (as normal displacement): ``U0 = 0``, ``g = -n . (L P)``."""
    L = _grid_laplacian(nu, nv)
    P = _torus_points(nu, nv, 0.02, seed=1)
    N = np.random.default_rng(2).normal(size=P.shape)
    N /= np.linalg.norm(N, axis=1)[:, None]
    A = sp.csr_matrix(L.multiply(N @ N.T))
    g = -np.einsum("ns,ns->n", N, np.asarray(L @ P))[:, None]
    return System(A, g, np.zeros((P.shape[0], 1)), np.ones(P.shape[0]))


SYSTEMS = {
    "free": lambda: _free(),
    "fixed+weights": lambda: _free(fixed_every=7, weights=True),
    "normal": _normal,
}


@pytest.mark.parametrize("name", list(SYSTEMS))
@pytest.mark.parametrize("k", [1, 2])
def test_phi_for_every_lambda_matches_dense(name: str, k: int) -> None:
    s = SYSTEMS[name]()
    run = LanczosRun(s.apply, s.c, dtype=np.float64)
    for _ in range(40):
        run.step()
    model = run.model(k)
    for lam in np.geomspace(1e-2, 10.0, 7) * s.mu.max():
        assert model.phi(lam) == pytest.approx(s.phi(lam, k), rel=1e-6)
    lams = np.geomspace(1e-5, 1.0, 7) * s.mu.max()
    if k == 1:  # Gauss below, Gauss-Radau above the exact phi after a few steps
        few = LanczosRun(s.apply, s.c, dtype=np.float64)
        for _ in range(6):
            few.step()
        m6 = few.model(1)
        exact = np.array([s.phi(x, 1) for x in lams])
        assert np.all(m6.phi(lams) <= exact * (1 + 1e-12))
        assert np.all(m6.phi(lams, radau=True) >= exact * (1 - 1e-12))


@pytest.mark.parametrize("name", list(SYSTEMS))
@pytest.mark.parametrize("k", [1, 2])
def test_root_and_solution_match_dense(name: str, k: int) -> None:
    s = SYSTEMS[name]()
    tau = 0.3 * s.phi(s.floor, k)
    got = one_run(s.apply, s.c, s.d, tau, s.floor, order=k)
    lam = s.root(tau, k)
    assert got.converged
    assert got.lam == pytest.approx(lam, rel=1e-3)
    E = s.exact_e(got.lam, k)  # the exact minimiser at the reported lambda
    size = np.linalg.norm(s.d * E)
    assert np.linalg.norm(s.d * (got.E - E)) <= 1e-3 * size
    assert got.bound <= 1e-3
    assert got.phi == pytest.approx(float(np.sum(s.d2[:, None] * got.E**2)))
    assert abs(got.phi - tau) <= 1e-3 * tau


def test_second_pass_is_bit_identical_to_the_kept_basis() -> None:
    s = _free(fixed_every=5)
    tau = 0.2 * s.phi(s.floor, 2)
    kept = one_run(s.apply, s.c, s.d, tau, s.floor, order=2, basis_dtype=np.float64)
    again = one_run(s.apply, s.c, s.d, tau, s.floor, order=2, keep_bytes=0)
    assert kept.lam == again.lam
    np.testing.assert_array_equal(kept.E, again.E)
    assert 0 < again.products - kept.products <= kept.steps - 1  # the second pass


def test_true_residual_bound_bounds_the_error() -> None:
    s = _free(weights=True)
    run = LanczosRun(s.apply, s.c, dtype=np.float64)
    for _ in range(12):
        run.step()
    lam = 1e-2 * s.mu.max()
    for k in (1, 2):
        model = run.model(k)
        Y = run.combine(model.chain(lam))
        err = np.linalg.norm(Y[-1] - s.d * s.exact_e(lam, k))
        bound = true_residual_bound(s.apply, s.c, Y, lam)
        assert err <= bound
        assert bound == pytest.approx(model.error_bound(lam), rel=1e-4)


def test_polished_when_the_bound_is_not_met() -> None:
    s = _free()
    tau = 0.3 * s.phi(s.floor, 1)
    got = one_run(s.apply, s.c, s.d, tau, s.floor, order=1, rtol=1e-12, max_steps=8)
    assert got.polished > 0
    assert got.bound <= 1e-12 * 1.01
    E = s.exact_e(got.lam, 1)
    assert np.linalg.norm(s.d * (got.E - E)) <= 1e-9 * np.linalg.norm(s.d * E)


def _dense_upre_min(s: System, W: np.ndarray, sigma2: float, k: int) -> tuple[float, float]:
    """The exact minimisers of GCV and of U with the same probes ``W`` (dense spectrum): a
    fine log grid, then bisection on the derivative's sign (the reference)."""
    cw = (s.Q.T @ s.c) ** 2  # data weights per eigenvalue
    pw = np.sum((s.Q.T @ W) ** 2, axis=1) / W.shape[1]
    cols = s.c.shape[1]

    def parts(lam: float) -> tuple[float, float]:
        g = (s.mu / (s.mu + lam)) ** k
        f = s.mu ** (2 * k - 2) / (s.mu + lam) ** (2 * k)
        return float(np.sum(f[:, None] * cw)), float(np.sum(g * pw))

    def best(score: object) -> float:
        grid = np.geomspace(s.floor * 10, 1e3, 2000)
        vals = [score(x) for x in grid]  # type: ignore[operator]
        i = int(np.argmin(vals))
        if i in (0, grid.size - 1):
            return float(grid[i])
        res = minimize_scalar(lambda x: score(math.exp(x)), method="bounded",  # type: ignore[operator]
                              bounds=(math.log(grid[i - 1]), math.log(grid[i + 1])),
                              options={"xatol": 1e-10})  # fmt: skip
        return float(math.exp(res.x))

    lam_g = best(lambda x: parts(x)[0] / parts(x)[1] ** 2)
    phi, t = parts(lam_g)
    s2 = max(sigma2, phi / (cols * t))
    return lam_g, best(lambda x: parts(x)[0] - 2 * cols * s2 * parts(x)[1])


@pytest.mark.parametrize("k", [1, 2])
def test_risk_rule_matches_the_dense_minimiser(k: int) -> None:
    """The rule's lambda* on converged curves is the exact minimiser of the unbiased risk
    with the same probes (to the reference grid's resolution, 0.5 %), and the solution there
    is the exact one (``rtol``)."""
    s = _free(nu=16, nv=12)
    rho = invariant_radius(_torus_points(16, 12, 0.0)[: s.c.shape[0]])
    S = np.ravel(s.d)
    sigma2 = 0.3 * float(np.sum(s.c**2)) / s.c.size
    rule = RiskRule(s.apply, S, rho, s.c.shape[1], sigma2, s.floor * 10, 1e3, 5000)
    got = one_run(s.apply, s.c, s.d, 0.0, s.floor, order=k, rule=rule, basis_dtype=np.float64)
    assert rule.choice is not None and rule.choice.converged
    lam_g, lam = _dense_upre_min(s, probe_block(rho, rule.count) * S[:, None], sigma2, k)
    assert rule.choice.lam_gcv == pytest.approx(lam_g, rel=2e-3)
    assert got.lam == rule.choice.lam == pytest.approx(lam, rel=2e-3)
    E = s.exact_e(got.lam, k)
    assert np.linalg.norm(s.d * (got.E - E)) <= 1e-3 * np.linalg.norm(s.d * E)


def test_second_pass_resumes_after_the_kept_vectors() -> None:
    s = _free(fixed_every=5)
    tau = 0.2 * s.phi(s.floor, 2)
    per_vector = s.c.size * 8
    kept = one_run(s.apply, s.c, s.d, tau, s.floor, order=2, basis_dtype=np.float64)
    part = one_run(s.apply, s.c, s.d, tau, s.floor, order=2, basis_dtype=np.float64,
                   keep_bytes=5 * per_vector)  # fmt: skip
    assert kept.lam == part.lam
    np.testing.assert_array_equal(kept.E, part.E)
    again = one_run(s.apply, s.c, s.d, tau, s.floor, order=2, keep_bytes=0)
    # the full second pass regenerates v_2 .. v_j, the resumed one v_6 .. v_j only
    assert part.products - kept.products == again.products - kept.products - 4 > 0


@pytest.mark.parametrize("k", [1, 2])
def test_risk_on_a_designed_spectrum_matches_the_closed_form(k: int) -> None:
    """A designed spectrum (diagonal ``M_t``, ``d = 1``): noise of variance sigma^2 = 1 in
    every mode, a signal 100 times stronger in ``mu in [1e-8, 1e-6]``. The rule's lambda*
    and the solution against U and ``y`` in closed form (the probes' projections on the
    eigenvectors are their entries)."""
    mu = np.concatenate([np.geomspace(1e-8, 1e-6, 100), np.geomspace(1e-2, 4.0, 900)])
    rng = np.random.default_rng(4)
    p = np.concatenate([np.full(100, 10.0), np.zeros(900)]) + rng.normal(0, 1, 1000)
    c = (mu * p)[:, None]
    d = np.ones((mu.size, 1))
    rho = np.linspace(0.0, 2.0, mu.size) + 1e-3 * rng.random(mu.size)
    floor = 1e-13 * mu.max()
    rule = RiskRule(lambda V: mu[:, None] * V, np.ones(mu.size), rho, 1, 1.0, 1e-9, 1e3, 5000)
    got = one_run(lambda V: mu[:, None] * V, c, d, 0.0, floor, order=k, rule=rule,
                  basis_dtype=np.float64)  # fmt: skip
    W = probe_block(rho, rule.count)
    pw = np.mean(W**2, axis=1)
    lams = np.geomspace(1e-9, 1e3, 20000)
    phi = np.array([np.sum(c[:, 0] ** 2 * mu ** (2 * k - 2) / (mu + x) ** (2 * k)) for x in lams])
    t = np.array([np.sum(pw * (mu / (mu + x)) ** k) for x in lams])
    gcv = lams[int(np.argmin(phi / t**2))]
    s2 = max(1.0, float(np.interp(np.log(gcv), np.log(lams), phi / t)))
    best = lams[int(np.argmin(phi - 2 * s2 * t))]
    assert rule.choice is not None
    assert rule.choice.lam == pytest.approx(best, rel=1e-2)
    y = c[:, 0] * mu ** (k - 1) / (mu + got.lam) ** k  # the exact minimiser at lambda
    assert np.linalg.norm(got.E[:, 0] - y) <= 1e-3 * np.linalg.norm(y)


@pytest.mark.parametrize("k", [1, 2])
def test_a_tau_above_phi0_stops_at_the_floor(k: int) -> None:
    """tau not below phi(0): the run stops once its phi(floor) has converged, says so, and
    reports that phi(0) (the dense one, to 1e-3), with no solution and no budget spent."""
    s = _free(nu=16, nv=12)
    phi0 = s.phi(s.floor, k)
    got = one_run(s.apply, s.c, s.d, 1.5 * phi0, s.floor, order=k, budget=10)
    assert got.at_floor and got.E is None
    assert got.tau == pytest.approx(phi0, rel=1e-3)
