"""Noise estimation: known sigma on generated surfaces, curves and clouds; the mode estimator."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry
from service.core.noise.estimate import estimate_noise, log_mode
from service.core.noise.pointfits import patch_variances
from tests.core.core_fixtures import polyline_edges


def _sphere_cloud(n: int, sigma: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    return P + sigma * P * rng.normal(size=(n, 1))  # along the normal


def _icosphere(sigma: float, seed: int) -> Geometry:
    import trimesh

    m = trimesh.creation.icosphere(4)
    rng = np.random.default_rng(seed)
    V = np.asarray(m.vertices)
    return Geometry(V + rng.normal(0, sigma, V.shape), faces=np.asarray(m.faces))


def _helix(n: int, sigma: float, seed: int) -> Geometry:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 6 * np.pi, n)
    P = np.column_stack([np.cos(t), np.sin(t), 0.2 * t]) + rng.normal(0, sigma, (n, 3))
    return Geometry(P, edges=polyline_edges(n))


def _circle(n: int, sigma: float, seed: int) -> Geometry:
    rng = np.random.default_rng(seed)
    u = np.arange(n) / n
    t = 2 * np.pi * (u + 0.1 * np.sin(2 * np.pi * u))  # non-uniform sampling
    P = np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, sigma, (n, 2))
    return Geometry(P, edges=polyline_edges(n, closed=True))


@pytest.mark.parametrize(
    ("make", "sigma"),
    [
        (lambda s, seed: _icosphere(s, seed), 0.004),  # mesh, isotropic noise (edge ~0.075)
        (lambda s, seed: _icosphere(s, seed), 0.02),
        (lambda s, seed: Geometry(_sphere_cloud(6000, s, seed)), 0.01),  # cloud, normal noise
        (lambda s, seed: _helix(800, s, seed), 0.01),  # 3-D curve: two normal directions
        (lambda s, seed: _circle(600, s, seed), 0.002),  # 2-D curve
    ],
)
def test_sigma_within_tolerance_on_known_noise(make, sigma: float) -> None:
    ratios = [estimate_noise(make(sigma, seed)).sigma / sigma for seed in (1, 2)]  # type: ignore[union-attr]
    assert all(abs(r - 1) <= 0.15 for r in ratios), ratios


def test_patch_variances_on_a_quadric() -> None:
    """On a noisy paraboloid the local quadratic fits leave the noise: curvature adds nothing,
    the PCA frame (the direction of least variance of the same points) takes a little."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1, 1, (4000, 2))
    z = 0.3 * xy[:, 0] ** 2 - 0.2 * xy[:, 0] * xy[:, 1] + 0.1 * xy[:, 1] ** 2
    sigma = 0.01
    P = np.column_stack([xy, z + rng.normal(0, sigma, 4000)])
    from scipy.spatial import cKDTree

    _, nbr = cKDTree(P).query(P, k=20)
    v = patch_variances(P, nbr, 2)
    assert 0.8 < np.mean(v) / sigma**2 < 1.02
    flat = patch_variances(np.column_stack([xy, rng.normal(0, sigma, 4000)]), nbr, 2)
    assert abs(np.mean(v) / np.mean(flat) - 1) < 0.1  # the curvature is (mostly) absorbed


def test_log_mode_of_scaled_chi_square_is_sigma_squared() -> None:
    rng = np.random.default_rng(4)
    nu = 6
    x = 2.5 * rng.chisquare(nu, 200000) / nu
    assert abs(log_mode(x) / 2.5 - 1) < 0.03
    # a heavy upper tail (neighbourhoods across creases) does not move the mode
    contaminated = np.concatenate([x, 2.5 * rng.uniform(3, 50, 150000)])
    assert abs(log_mode(contaminated) / 2.5 - 1) < 0.05
    assert abs(np.median(contaminated) / 2.5 - 1) > 0.5  # ... where the median fails


def test_noise_free_and_degenerate_inputs() -> None:
    t = np.linspace(0, 1, 50)
    line = np.column_stack([t, 2 * t])
    est = estimate_noise(Geometry(line, edges=polyline_edges(50)))
    assert est is not None and est.sigma == 0.0  # an exact line: no measurable noise
    assert estimate_noise(Geometry(np.zeros((5, 3)))) is None  # too few points
    # coincident copies of every vertex (split normals) give the same estimate as the originals
    g = _icosphere(0.01, 5)
    doubled = Geometry(np.vstack([g.points, g.points]), faces=g.faces)
    a, b = estimate_noise(g), estimate_noise(doubled)
    assert a is not None and b is not None and abs(a.sigma / b.sigma - 1) < 1e-9


def test_log_mode_of_values_equal_to_rounding_is_their_value() -> None:
    # variances that differ only in their last bits (an exactly regular clean shape) used to
    # raise numpy's "Too many bins for data range" from the 512-bin histogram
    v = 1e-7 * (1 + 1e-15 * np.arange(1000))
    assert log_mode(v) == pytest.approx(1e-7, rel=1e-12)
    assert log_mode(np.full(50, 3.0)) == pytest.approx(3.0, rel=1e-12)
