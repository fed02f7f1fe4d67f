"""Issue 30's compiled kernels against the NumPy/SciPy paths they replace (same answers)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core.geometry import Geometry
from service.core.noise import fast_weights, robust
from service.core.noise.estimate import estimate_noise
from service.core.noise.fast_fits import leave_one_out as fast_loo
from service.core.noise.pointfits import leave_one_out
from service.core.operator import knn as knn_module


def _sphere(n: int, noise: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1)[:, None]
    return P + rng.normal(0, noise, P.shape)


def _icosphere(subdivisions: int, noise: float, seed: int = 1) -> Geometry:
    trimesh = pytest.importorskip("trimesh")
    m = trimesh.creation.icosphere(subdivisions)
    P = np.asarray(m.vertices)
    P = P + np.random.default_rng(seed).normal(0, noise, P.shape)
    return Geometry(P, faces=np.asarray(m.faces))


@pytest.mark.parametrize("k", [2, 13])
def test_grid_knn_equals_the_kd_tree(monkeypatch: pytest.MonkeyPatch, k: int) -> None:
    monkeypatch.setattr(knn_module, "GRID_FROM", 100)
    P = _sphere(6000, 0.01)
    P[:10] *= 3.0  # isolated points: answered by the tree
    d1, i1 = cKDTree(P).query(P, k=k)
    d2, i2 = knn_module.knn(P, k)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_allclose(d1, d2, rtol=1e-12, atol=0)


def test_surface_fits_agree_with_numpy() -> None:
    P = _sphere(3000, 0.01)
    _, nbr = cKDTree(P).query(P, k=13)
    nbr = np.asarray(nbr, dtype=np.int64)
    use = np.random.default_rng(2).random((P.shape[0], 12)) > 0.15
    for mask in (None, use):
        r1, v1 = leave_one_out(P, nbr, 2, mask)
        r2, v2 = fast_loo(P, nbr, 2, mask)
        np.testing.assert_array_equal(np.isnan(r1), np.isnan(r2))
        ok = ~np.isnan(r1)
        np.testing.assert_allclose(v2[ok], v1[ok], rtol=1e-9)
        np.testing.assert_allclose(r2[ok], r1[ok], rtol=1e-6, atol=1e-12 * np.nanmax(r1))


def test_data_weight_factors_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(knn_module, "GRID_FROM", 100)
    g = _icosphere(5, 0.002)
    P = g.points.copy()
    rng = np.random.default_rng(4)
    out = rng.choice(g.n, 25, replace=False)
    P[out] += rng.normal(0, 0.05, (out.size, 3))
    g = Geometry(P, faces=g.faces)
    estimate_noise(g)
    factors = getattr(robust, "_factors")  # noqa: B009
    monkeypatch.setattr(fast_weights, "COMPILED_FROM", 10**9)
    a = factors(g, "auto", "auto")  # the NumPy path
    monkeypatch.setattr(fast_weights, "COMPILED_FROM", 100)
    assert fast_weights.neighbours(g) is not None
    b = factors(g, "auto", "auto")
    assert a is not None and b is not None
    np.testing.assert_allclose(b[0], a[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(b[1], a[1])
    np.testing.assert_array_equal(b[2], a[2])
    assert b[2].size > 0 and b[3:5] == a[3:5]
    assert b[5] == pytest.approx(a[5], rel=1e-9)


def test_isolated_agrees() -> None:
    g = _icosphere(4, 0.002)
    P = g.points.copy()
    P[:5] *= 1.5
    g = Geometry(P, faces=g.faces)
    _, nbr = cKDTree(P).query(P, k=13)
    nbr = np.asarray(nbr, dtype=np.int64)
    sigma = np.full(g.n, 0.002)
    for geom in (g, Geometry(P)):
        np.testing.assert_array_equal(
            robust.isolated(geom, nbr, sigma, compiled=True), robust.isolated(geom, nbr, sigma)
        )


def test_closed_form_normals_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    from service.core.operator.build import build_operator
    from service.core.params import SmoothingParams
    from service.core.system import displacement

    g = _icosphere(4, 0.003)
    A = build_operator(g, SmoothingParams()).neighborhoods.adjacency
    frames = getattr(displacement, "_frames")  # noqa: B009
    ref = frames(g.points, A, 1, 12, 5, None)
    monkeypatch.setattr(displacement, "COMPILED_FRAMES_FROM", 100)
    monkeypatch.setattr(knn_module, "GRID_FROM", 100)
    got = frames(g.points, A, 1, 12, 5, None)
    assert got.shape == ref.shape
    cos = np.abs(np.einsum("ns,ns->n", ref[:, :, 0], got[:, :, 0]))
    assert np.all(cos > 1 - 1e-12)
