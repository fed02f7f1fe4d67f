"""The residual test (issue 40): removed noise is incoherent, removed shape is coherent; the
run backs off only where it removed shape."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from service.core import Geometry, SmoothingParams, smooth
from service.core.finish.residual import RHO_BACKOFF, back_off, correlation
from tests.core.core_fixtures import grid_mesh, noisy_icosphere


def _graph_laplacian(F: np.ndarray, n: int) -> sp.csr_matrix:
    E = np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.csr_matrix((np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                      shape=(n, n))
    A.data[:] = 1.0
    return sp.csr_matrix(sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A)


def test_white_noise_is_not_coherent_and_a_bump_is() -> None:
    P, F = grid_mesh(40, 40)
    n = len(P)
    L = _graph_laplacian(F, n)
    use = np.ones(n, dtype=bool)
    rng = np.random.default_rng(0)
    noise = np.zeros((n, 3))
    noise[:, 2] = rng.normal(size=n)
    rho = correlation(noise, L, use)
    assert np.abs(np.mean(rho)) < 0.05 and rho.max() < RHO_BACKOFF  # white: about 0
    bump = np.zeros((n, 3))
    d2 = np.sum((P[:, :2] - P[:, :2].mean(axis=0)) ** 2, axis=1)
    bump[:, 2] = np.exp(-d2 / (2 * (4 * np.diff(np.unique(P[:, 0]))[0]) ** 2))
    rho_b = correlation(bump, L, use)
    centre = int(np.argmin(d2))
    assert rho_b[centre] > 0.9  # a smooth removed field: near 1


def test_back_off_restores_coherent_removal_only() -> None:
    P, F = grid_mesh(30, 30)
    n = len(P)
    L = _graph_laplacian(F, n)
    d2 = np.sum((P[:, :2] - P[:, :2].mean(axis=0)) ** 2, axis=1)
    h = np.diff(np.unique(P[:, 0]))[0]
    bump = np.where(d2 < (5 * h) ** 2, 1.0, 0.0)  # a removed plateau: shape
    X = P.copy()
    X[:, 2] -= bump
    Y, rec = back_off(P, X, L, np.zeros(0, np.int64), np.zeros(n, dtype=bool))
    assert rec is not None and rec.points.size > 0
    inside = np.flatnonzero(d2 < (3 * h) ** 2)
    assert np.allclose(Y[inside], P[inside])  # deep inside the plateau: fully backed off
    assert np.all(np.abs(Y[:, 2] - P[:, 2]) <= np.abs(X[:, 2] - P[:, 2]) + 1e-15)
    said = rec.describe()
    assert said.startswith(f"residual test: the displacement removed at {rec.points.size} ")
    rng = np.random.default_rng(1)
    Z = P.copy()
    Z[:, 2] += 0.01 * rng.normal(size=n)  # removed white noise: nothing to back off
    same, none = back_off(P, Z, L, np.zeros(0, np.int64), np.zeros(n, dtype=bool))
    assert none is None and same is Z


def test_default_on_a_noisy_sphere_backs_off_nowhere() -> None:
    P, F = noisy_icosphere(4, 0.01, seed=3)
    res = smooth(Geometry(P, faces=F), SmoothingParams())
    assert not [w for w in res.report()["warnings"] if w.startswith("residual test")]


def test_a_given_amount_of_smoothing_is_kept() -> None:
    P, F = noisy_icosphere(3, 0.01, seed=4)
    res = smooth(Geometry(P, faces=F), SmoothingParams(rms=0.3))  # melts the sphere, as asked
    assert not [w for w in res.report()["warnings"] if w.startswith("residual test")]
    assert float(np.sqrt(np.mean(np.sum((res.points - P) ** 2, axis=1)))) > 0.2
