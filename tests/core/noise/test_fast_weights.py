"""Issue 30, item 3: the data weights' compiled pieces against the NumPy/SciPy code they stand
for (the k-d tree, ``uneven.local_sigma``, ``robust.isolated``, ``pointfits.patch_variances``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core.geometry import Geometry
from service.core.noise import estimate, fast_fits, fast_weights, pointfits, robust, uneven
from service.core.operator import knn


def _sheet(side: int, noise: float, seed: int = 0) -> Geometry:
    """A noisy height field on a ``side x side`` grid, triangulated."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side))
    P = np.c_[u.ravel(), v.ravel(), 0.2 * np.sin(3 * u.ravel()) * np.cos(2 * v.ravel())]
    P = P + rng.normal(0, noise, P.shape)
    q = np.arange(side * side).reshape(side, side)[:-1, :-1].ravel()
    F = np.r_[np.c_[q, q + 1, q + side], np.c_[q + 1, q + side + 1, q + side]]
    return Geometry(P, faces=F)


@pytest.mark.parametrize("width", [7, 13, 21])
def test_local_sigma_is_the_numpy_rule_bit_for_bit(width: int) -> None:
    rng = np.random.default_rng(width)
    P = rng.normal(size=(4000, 3))
    _, nbr = cKDTree(P).query(P, k=width)
    v = rng.gamma(3.0, size=4000)
    v[rng.random(4000) < 0.05] = np.nan
    v[rng.random(4000) < 0.02] = 0.0
    v[:7] = np.inf
    a = uneven.local_sigma(v, nbr, 6)
    b = fast_weights.local_sigma(v, nbr, 6)
    assert np.array_equal(a, b, equal_nan=True)


def test_isolated_mask_is_the_numpy_test() -> None:
    g = _sheet(70, 0.002)
    P = g.points.copy()
    rng = np.random.default_rng(3)
    far = rng.choice(g.n, 12, replace=False)
    P[far[:6], 2] += 0.3  # off the surface
    P[far[6:], :2] += 0.25  # far along it: the graph median is then far from the point
    g = Geometry(P, faces=g.faces)
    dist, nbr = cKDTree(P).query(P, k=13)
    sigma = np.full(g.n, 0.002)
    F = np.asarray(g.faces)
    edges = np.unique(np.sort(np.r_[F[:, :2], F[:, 1:]], axis=1), axis=0)
    for geom in (g, Geometry(P, edges=edges), Geometry(P)):
        ref = robust.isolated(geom, nbr, sigma)
        assert np.array_equal(robust.isolated(geom, nbr, sigma, True, dist), ref)
        assert np.array_equal(robust.isolated(geom, nbr, sigma, True), ref)
        assert (geom.faces is None and geom.edges is None) or ref[far].all()


def test_the_elements_bound_the_graph_median_distance() -> None:
    g = _sheet(40, 0.01)
    P = np.ascontiguousarray(g.points)
    _, nbr = cKDTree(P).query(P, k=13)
    _, _, delta = fast_weights.isolation_distances(g, nbr)
    box_bound = getattr(fast_weights, "_box_bound")  # noqa: B009
    bound = np.sqrt(box_bound(P, np.asarray(g.faces, dtype=np.int64)))
    assert delta is not None and np.all(delta <= bound * (1 + 1e-12))


@pytest.mark.parametrize("width", [12, 24])
def test_patch_variances_compiled_agree(monkeypatch: pytest.MonkeyPatch, width: int) -> None:
    g = _sheet(60, 0.003)
    P = g.points.copy()
    P[:60, 2] = 0.0  # one grid row flat and collinear: rank-deficient fits (the NumPy rows)
    P[:60, 1] = 0.0
    _, nbr = cKDTree(P).query(P, k=width)
    a = pointfits.patch_variances(P, nbr, 2, compiled=False)
    b, unsure = fast_fits.patch_variances(P, nbr)
    b[unsure] = a[unsure]  # those rows are the NumPy code's (pointfits.patch_variances)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    monkeypatch.setattr(pointfits, "COMPILED_FROM", 100)
    c = pointfits.patch_variances(P, nbr, 2)
    np.testing.assert_allclose(c, b, rtol=1e-12)
    ok = ~np.isnan(a)
    np.testing.assert_allclose(b[ok], a[ok], rtol=1e-9, atol=1e-14 * np.nanmax(a))


@pytest.mark.parametrize("k", [2, 13, 24, 40])
def test_nearest_equals_the_kd_tree(monkeypatch: pytest.MonkeyPatch, k: int) -> None:
    monkeypatch.setattr(knn, "GRID_FROM", 100)
    P = _sheet(80, 0.002).points.copy()
    P[:5] += 0.5  # isolated points: wider blocks, then the tree
    at = np.random.default_rng(1).choice(P.shape[0], 700, replace=False)
    at[:5] = np.arange(5)
    d1, i1 = cKDTree(P).query(P[at], k=k)
    knn.release()
    d2, i2 = knn.nearest(P, at, k, 13)
    np.testing.assert_array_equal(i2, np.asarray(i1).reshape(at.size, k))
    np.testing.assert_allclose(d2, np.asarray(d1).reshape(at.size, k), rtol=1e-12, atol=0)
    knn.release()


def test_noise_estimate_on_the_grid_is_the_tree_estimate(monkeypatch: pytest.MonkeyPatch) -> None:
    g = _sheet(120, 0.002)
    ref = estimate.noise_of(g)
    monkeypatch.setattr(knn, "GRID_FROM", 100)
    monkeypatch.setattr(pointfits, "COMPILED_FROM", 100)
    knn.release()
    got = estimate.noise_of(g)
    knn.release()
    assert ref is not None and got is not None and ref.sigma > 0
    assert got.sigma == pytest.approx(ref.sigma, rel=1e-12)
    assert got.scale_ratio == pytest.approx(ref.scale_ratio, rel=1e-12)
    np.testing.assert_allclose(got.residuals, ref.residuals, rtol=1e-9)


def test_a_grid_is_not_reused_for_points_changed_in_place(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(knn, "GRID_FROM", 100)
    P = _sheet(40, 0.002).points.copy()
    at = np.arange(0, P.shape[0], 5)
    knn.nearest(P, at, 8, 8)
    P[:, 2] += np.random.default_rng(2).normal(0, 0.05, P.shape[0])  # same array, new points
    got = knn.nearest(P, at, 8, 8)[1]
    knn.release()
    np.testing.assert_array_equal(got, cKDTree(P).query(P[at], k=8)[1])
