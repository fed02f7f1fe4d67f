"""Robust and noise data weights (issue 21): closed forms and independent computations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core.geometry import Geometry
from service.core.noise.estimate import codimension, estimate_noise
from service.core.noise.pointfits import leave_one_out, point_neighbours
from service.core.noise.robust import OMEGA_MIN, robust_weights
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one as smooth
from tests.core.core_fixtures import planned_weights


def _sheet(n: int = 40, seed: int = 0, sigma: float | np.ndarray = 0.02) -> np.ndarray:
    """A gently curved height field z = 0.1 (x^2 - y^2) on a jittered grid, normal-ish noise."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    x = x.ravel() + rng.uniform(-0.005, 0.005, n * n)
    y = y.ravel() + rng.uniform(-0.005, 0.005, n * n)
    z = 0.1 * (x**2 - y**2) + sigma * rng.normal(size=n * n)
    return np.c_[x, y, z]


def test_leave_one_out_matches_a_dense_fit_without_the_point() -> None:
    """r_i and v_i against numpy's lstsq on the neighbours alone, in the PCA frame of them."""
    P = _sheet(12, seed=1)
    nbr = point_neighbours(Geometry(P), 12, 2)
    r, v = leave_one_out(P, nbr, 2)
    for i in (0, 17, 70, 143):
        Q = P[nbr[i, 1:]]
        mean = Q.mean(axis=0)
        _, vecs = np.linalg.eigh((Q - mean).T @ (Q - mean))
        loc = (Q - mean) @ vecs[:, ::-1]
        loc0 = (P[i] - mean) @ vecs[:, ::-1]
        u, z = loc[:, :2], loc[:, 2]
        sc = np.sqrt(np.mean(u**2))

        def design(w: np.ndarray, sc: float = sc) -> np.ndarray:
            w = np.atleast_2d(w) / sc
            return np.c_[np.ones(len(w)), w, w[:, 0] ** 2, w[:, 0] * w[:, 1], w[:, 1] ** 2]

        B = design(u)
        coef, *_ = np.linalg.lstsq(B, z, rcond=None)
        rss = float(np.sum((z - B @ coef) ** 2))
        b0 = design(loc0[:2])[0]
        h0 = b0 @ np.linalg.solve(B.T @ B, b0)
        assert v[i] == pytest.approx(rss / (12 - 6), rel=1e-8)
        assert r[i] == pytest.approx((loc0[2] - b0 @ coef) ** 2 / (1 + h0), rel=1e-8)


def test_leave_one_out_residuals_are_chi_square_for_gaussian_noise() -> None:
    """For Gaussian normal noise r_i / sigma^2 is chi^2_1: mean 1 (within sampling error); v_i
    is slightly low (measured 0.83: the PCA frame is chosen from the same noisy points)."""
    sigma = 0.02
    P = _sheet(50, seed=2, sigma=sigma)
    nbr = point_neighbours(Geometry(P), 12, 2)
    r, v = leave_one_out(P, nbr, 2)
    assert np.nanmean(r / sigma**2) == pytest.approx(1.0, abs=0.1)
    assert 0.75 < np.nanmean(v / sigma**2) < 1.05


def test_a_single_huge_outlier_gets_weight_near_zero_and_leaves_the_budget() -> None:
    """One point 50 sigma off: weight OMEGA_MIN, the others 1; the automatic tau equals the
    discrepancy rule n sigma^2 (codimension 1, c = 1 for normal displacement) over the inliers
    alone, computed here from the estimate independently."""
    sigma = 0.02
    P = _sheet(40, seed=3, sigma=sigma)
    P[555, 2] += 50 * sigma
    g = Geometry(P)
    params = SmoothingParams(displacement="normal", outliers="pull")
    g2, dw = planned_weights(g, params)
    assert dw is not None
    assert dw.outliers.tolist() == [555]
    assert g2.omega()[555] == pytest.approx(OMEGA_MIN)
    others = np.delete(g2.omega(), 555)
    assert np.all(others == 1.0)
    res = smooth(g, params)
    est = estimate_noise(g)
    assert est is not None
    w2 = float(np.sum(others**2) + OMEGA_MIN**2)  # = n - 1 + 1e-6
    expected = codimension(g) * est.sigma**2 * w2
    assert res.report()["outlier_count"] == 1 and res.report()["outliers"] == [555]
    assert res.data_weights == "robust (auto)"
    # the discrepancy tau (the rule's starting budget) counts the inliers only
    assert f"{expected:.6g}" in (res.tau_how or "")
    # the outlier is pulled in: it ends within a few sigma of the smooth sheet
    x, y = res.points[555, :2]
    assert abs(res.points[555, 2] - 0.1 * (x**2 - y**2)) < 5 * sigma
    # the rule's noise level is the inliers' (within 15 %); without robust weights the
    # outlier's energy reads as noise in Wahba's estimate (phi / tr G), which then exceeds
    # the local fits' and oversmooths the sheet: the weights keep it out of the budget
    assert res.report()["sigma_estimate"] == pytest.approx(sigma, rel=0.15)
    plain = smooth(g, SmoothingParams(displacement="normal", robust="none"))
    ev = plain.report()["plan"]["tau_rule"]["evidence"]
    assert ev["sigma_wahba"] > 1.4 * ev["sigma_local"] and ev["sigma"] == ev["sigma_wahba"]


def test_huber_irls_weights_match_a_dense_weighted_solve() -> None:
    """Huber weights rho^2 = min(1, k/z) in the system: the solution of eq. (4) with
    D = diag(rho) for a given lambda equals the dense weighted normal equations."""
    rng = np.random.default_rng(4)
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    P = np.c_[np.cos(t), np.sin(t)] * (1 + 0.01 * rng.normal(size=120))[:, None]
    P[7] *= 1.3
    edges = np.c_[np.arange(120), (np.arange(120) + 1) % 120]
    g = Geometry(P, edges=edges)
    params = SmoothingParams(lam=0.5, robust="huber", displacement="free", order=1)
    g2, dw = planned_weights(g, params)
    assert dw is not None and 7 in dw.outliers.tolist()
    rho = g2.omega()
    z_out = (1.345 / rho[7] ** 2)  # z of the outlier from its weight
    assert z_out > 10
    res = smooth(g, params)
    # dense: (L^T L + lam D^2) X = lam D^2 P with L the operator's Laplacian
    from service.core.operator.build import build_operator

    L = build_operator(g, params).L.toarray()
    D2 = np.diag(rho**2)
    X = np.linalg.solve(L.T @ L + 0.5 * D2, 0.5 * D2 @ P)
    assert np.allclose(res.points, X, atol=1e-8)


def test_robust_weight_rules_closed_forms() -> None:
    """Huber, Tukey and the automatic taper as functions of z (r = z^2 sigma^2, v = sigma^2)."""
    z = np.array([0.5, 2.0, 4.0, 6.0, 8.0, 100.0] + [0.3] * 2000)
    s2 = np.ones(z.size)
    r, v = z**2, np.ones(z.size)
    P = np.zeros((z.size, 3))
    rho, out, rule = robust_weights(P, 2, r, v, s2, 6, "huber")
    assert rule == "huber"
    assert np.allclose(rho[:6], np.sqrt(np.minimum(1, 1.345 / z[:6])))
    rho, _, _ = robust_weights(P, 2, r, v, s2, 6, "tukey")
    assert np.allclose(rho[:6], np.maximum(1 - (z[:6] / 4.685) ** 2, OMEGA_MIN))
    rho, out, rule = robust_weights(P, 2, r, v, s2, 6, "auto")
    z0 = 3.8906  # chi^2_1 upper 1e-4 quantile, square root
    assert rule == "auto" and out.tolist() == [2, 3, 4, 5]
    t = np.clip((z[:6] - z0) / z0, 0, 1)
    assert np.allclose(rho[:6], np.maximum(1 - t**2, OMEGA_MIN), atol=1e-4)
    # a fit inconsistent with the noise (v large: a crease) leaves the point undecided
    v2 = v.copy()
    v2[5] = 100.0
    rho, out, _ = robust_weights(P, 2, r, v2, s2, 6, "auto")
    assert rho[5] == 1.0 and 5 not in out.tolist()


def test_auto_leaves_gaussian_noise_alone() -> None:
    """No outliers: 'auto' changes nothing (the same points as robust='none')."""
    g = Geometry(_sheet(40, seed=5))
    params = SmoothingParams(displacement="normal")
    _, dw = planned_weights(g, params)
    assert dw is None or (dw.robust == "none" and not dw.uneven)
    a = smooth(g, params)
    b = smooth(g, SmoothingParams(displacement="normal", robust="none", noise_weights="none"))
    assert np.array_equal(a.points, b.points)
    assert a.report()["outlier_count"] == 0


def test_local_sigma_tracks_a_known_sigma() -> None:
    """sigma_i against sigma(x) varying 1 -> 5 across a sheet: within 30 % on 80 % of points,
    and the automatic rule switches the noise weights on (and not for constant noise)."""
    n = 60
    x = np.linspace(-1, 1, n)
    sig = 0.005 * np.exp(np.log(5.0) * (np.repeat(x[None, :], n, 0).ravel() + 1) / 2)
    P = _sheet(n, seed=6, sigma=sig)
    g = Geometry(P)
    _, dw = planned_weights(g, SmoothingParams(noise_weights="local"))
    est = estimate_noise(g)
    assert dw is not None and est is not None
    ratio = dw.tau_scale * est.sigma / sig
    assert np.mean(np.abs(np.log(ratio)) < np.log(1.3)) > 0.8
    _, auto = planned_weights(g, SmoothingParams())
    assert auto is not None and auto.uneven
    _, const = planned_weights(Geometry(_sheet(n, seed=6, sigma=0.01)), SmoothingParams())
    assert const is None or not const.uneven


def test_user_weights_win_and_the_report_preset_has_none() -> None:
    P = _sheet(30, seed=7)
    P[100, 2] += 1.0
    g = Geometry(P, weights=np.ones(len(P)))
    res = smooth(g, SmoothingParams())
    assert res.report()["outlier_count"] == 0
    assert [w.code for w in res.warnings] == ["data-weights-not-applied"]
    rep = SmoothingParams(preset="report")
    assert rep.robust == "none" and rep.noise_weights == "none"
    _, dw = planned_weights(Geometry(P), rep)
    assert dw is None


def test_given_tau_keeps_the_users_weights_unless_asked() -> None:
    """'auto' acts with the automatic tau only; 'tukey' with a given tau too."""
    P = _sheet(30, seed=8)
    P[100, 2] += 1.0
    g = Geometry(P)
    _, dw = planned_weights(g, SmoothingParams(tau=0.1))
    assert dw is None
    _, dw = planned_weights(g, SmoothingParams(tau=0.1, robust="tukey"))
    assert dw is not None and 100 in dw.outliers.tolist()


def test_point_neighbours_put_the_point_first_also_with_duplicates() -> None:
    P = np.r_[_sheet(10, seed=9), _sheet(10, seed=9)[:5]]
    nbr = point_neighbours(Geometry(P), 8, 2)
    assert np.array_equal(nbr[:, 0], np.arange(len(P)))
    d, _ = cKDTree(P).query(P, k=9)
    got = np.linalg.norm(P[nbr[:, 1:]] - P[:, None, :], axis=2)
    assert np.allclose(np.sort(got, axis=1)[:, -1], d[:, -1])


def test_pull_in_minimises_the_smoothness_over_the_outliers_alone() -> None:
    """argmin ||L X||^2 over two rows of X, the others held: against dense least squares."""
    from service.core.finish.outliers import pull_in

    rng = np.random.default_rng(10)
    n = 30
    L = np.eye(n) - 0.5 * (np.eye(n, k=1) + np.eye(n, k=-1))
    L[0, 1], L[-1, -2] = -1.0, -1.0
    X = np.c_[np.linspace(0, 1, n), 0.01 * rng.normal(size=n)]
    X[[9, 20]] += 5.0
    idx = np.array([9, 20])
    import scipy.sparse as sp

    got = pull_in(X, sp.csr_matrix(L), idx)
    rest = np.setdiff1d(np.arange(n), idx)
    want, *_ = np.linalg.lstsq(L[:, idx], -L[:, rest] @ X[rest], rcond=None)
    assert np.allclose(got[idx], want, atol=1e-8)
    assert np.array_equal(got[rest], X[rest])


def test_a_vertex_thrown_inside_a_sphere_mesh_is_found_and_pulled_back() -> None:
    """Its neighbours in space fit nothing (the residual test is undecided); isolation from
    its mesh neighbours finds it, and the result puts it back near the sphere."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(11)
    U = rng.normal(size=(1500, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    F = ConvexHull(U).simplices
    P = U * (1 + 0.01 * rng.normal(size=(1500, 1)))
    P[77] = 0.05 * U[77]  # next to the centre
    g = Geometry(P, faces=F)
    res = smooth(g, SmoothingParams())
    assert 77 in res.outliers.tolist()
    assert abs(np.linalg.norm(res.points[77]) - 1.0) < 0.1
    assert res.outliers.size <= 3


def test_row_quantile_is_nanquantile() -> None:
    from service.core.noise.uneven import row_quantile

    rng = np.random.default_rng(12)
    A = rng.normal(size=(200, 13))
    A[rng.random(A.shape) < 0.3] = np.nan
    A[5] = np.nan
    for q in (0.25, 0.5, 0.9):
        with np.errstate(all="ignore"), pytest.warns(RuntimeWarning):
            want = np.nanquantile(A, q, axis=1)
        assert np.allclose(row_quantile(A, q), want, equal_nan=True)
