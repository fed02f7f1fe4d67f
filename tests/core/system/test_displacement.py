"""Normal-only displacement: the assembled system against a dense least-squares oracle."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from service.core import Geometry, SmoothingParams
from service.core.operator.build import build_laplacian
from service.core.system.displacement import normal_frames, normal_system, projected_normal_system
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def _dense_oracle(L, P, N, w2, lam):
    """min_t ||L (P + N t)||_F^2 + lam sum_i w2_i ||t_i||^2 by a stacked dense lstsq."""
    n, s = P.shape
    r = N.shape[2]
    Ld = L.toarray()
    A = np.zeros((n * s, n * r))
    for c in range(s):
        for a in range(r):
            A[c * n : (c + 1) * n, a::r] = Ld * N[:, c, a][None, :]
    g = -(Ld @ P).T.reshape(-1)
    reg = np.sqrt(lam * np.repeat(w2, r))
    t, *_ = np.linalg.lstsq(
        np.vstack([A, np.diag(reg)]), np.concatenate([g, np.zeros(n * r)]), rcond=None
    )
    return P + np.einsum("nsa,na->ns", N, t.reshape(n, r))


@pytest.mark.parametrize("kind", ["mesh", "curve2d", "curve3d"])
def test_normal_system_matches_dense_oracle(kind: str) -> None:
    rng = np.random.default_rng(1)
    if kind == "mesh":
        P, F = noisy_icosphere(2, 0.02)
        g = Geometry(P, faces=F)
        codim = 1
    else:
        s = 2 if kind == "curve2d" else 3
        t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
        P = np.column_stack([np.cos(t), np.sin(t), 0.3 * np.sin(3 * t)][:s])
        P = P + rng.normal(0, 0.02, P.shape)
        g = Geometry(P, edges=polyline_edges(60, closed=True))
        codim = s - 1
    L, nb, _, _ = build_laplacian(g, SmoothingParams(lam=1.0))
    N = normal_frames(g.points, nb.adjacency, codim)
    assert np.allclose(np.einsum("nsa,nsb->nab", N, N), np.eye(codim), atol=1e-12)
    w2 = rng.uniform(0.5, 2.0, g.n)
    sysn = normal_system(L, np.asarray(L @ g.points), N, w2)
    lam = 0.3
    K = sysn.M.toarray() + lam * np.diag(sysn.d2)
    U = np.linalg.solve(K, sysn.b + lam * sysn.d2[:, None] * sysn.U0)
    X = sysn.points(g.points, U)
    X_ref = _dense_oracle(L, g.points, N, w2, lam)
    np.testing.assert_allclose(X, X_ref, rtol=1e-9, atol=1e-11)
    # every point moved along its normal space only
    D = X - g.points
    tangential = D - np.einsum("nsa,na->ns", N, np.einsum("nsa,ns->na", N, D))
    assert np.abs(tangential).max() < 1e-12
    # the deviation is the free problem's: sum w2 ||x - p||^2 == sum d2 U^2
    assert np.isclose(np.sum(w2 * np.sum(D**2, axis=1)), float(np.sum(sysn.d2[:, None] * U**2)))


def test_fixed_points_use_reduced_columns() -> None:
    P, F = noisy_icosphere(1, 0.02)
    g = Geometry(P, faces=F)
    L, nb, _, _ = build_laplacian(g, SmoothingParams(lam=1.0))
    fixed = np.zeros(g.n, dtype=bool)
    fixed[:5] = True
    free = np.flatnonzero(~fixed)
    L_R = sp.csr_matrix(L)[free]
    N = normal_frames(g.points, nb.adjacency, 1)
    sysn = normal_system(L_R[:, free], np.asarray(L_R @ g.points), N[free], np.ones(free.size))
    lam = 0.5
    U = np.linalg.solve(sysn.M.toarray() + lam * np.eye(free.size), sysn.b)
    X = g.points.copy()
    X[free] = sysn.points(g.points[free], U)
    # oracle: minimize over the free t only, rows of free points, fixed points at P
    Ld = L_R.toarray()
    A = np.zeros((free.size * 3, free.size))
    for c in range(3):
        A[c * free.size : (c + 1) * free.size] = Ld[:, free] * N[free, c, 0][None, :]
    gvec = -(Ld @ g.points).T.reshape(-1)
    t, *_ = np.linalg.lstsq(
        np.vstack([A, np.sqrt(lam) * np.eye(free.size)]),
        np.concatenate([gvec, np.zeros(free.size)]),
        rcond=None,
    )
    np.testing.assert_allclose(X[free], g.points[free] + N[free, :, 0] * t[:, None], atol=1e-11)
    assert np.array_equal(X[:5], g.points[:5])


def test_projected_system_matches_dense_oracle_in_a_normal_plane() -> None:
    """Curve in 3-D (two unknowns per point): min sum_i ||N_i^T (L(P + N t))_i||^2 + lam ..."""
    rng = np.random.default_rng(4)
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    P = np.column_stack([np.cos(t), np.sin(t), 0.3 * np.sin(3 * t)]) + rng.normal(0, 0.02, (50, 3))
    g = Geometry(P, edges=polyline_edges(50, closed=True))
    L, nb, _, _ = build_laplacian(g, SmoothingParams(lam=1.0))
    N = normal_frames(P, nb.adjacency, 2)
    w2 = rng.uniform(0.5, 2.0, 50)
    sysn = projected_normal_system(L, np.asarray(L @ P), N, w2)
    lam = 0.2
    U = np.linalg.solve(sysn.M.toarray() + lam * np.diag(sysn.d2), sysn.b)
    Ld = L.toarray()
    A = np.zeros((100, 100))
    for i in range(50):
        for j in np.flatnonzero(Ld[i]):
            A[2 * i : 2 * i + 2, 2 * j : 2 * j + 2] = Ld[i, j] * N[i].T @ N[j]
    gvec = -np.einsum("nsa,ns->na", N, Ld @ P).reshape(-1)
    ref = np.linalg.solve(A.T @ A + lam * np.diag(np.repeat(w2, 2)), A.T @ gvec)
    np.testing.assert_allclose(U[:, 0], ref, rtol=1e-9, atol=1e-12)


def test_projected_system_fast_path_matches_the_block_assembly() -> None:
    """r = 1: A = L_F scaled by n_i . n_j equals the generic block assembly (dense check)."""
    from service.core.system.displacement import _blocks

    rng = np.random.default_rng(7)
    m = 60
    L = sp.random(m, m, density=0.1, random_state=8, format="csr") + sp.eye(m)
    frames = rng.normal(size=(m, 3, 1))
    frames /= np.linalg.norm(frames, axis=1, keepdims=True)
    LP = rng.normal(size=(m, 3))
    w2 = rng.uniform(0.5, 2.0, m)
    ns = projected_normal_system(L, LP, frames, w2)
    rows, cols, vals = _blocks(sp.coo_matrix(L), frames, 1)
    A = sp.csr_matrix((vals, (rows, cols)), shape=(m, m)).toarray()
    dense = L.toarray() * (frames[:, :, 0] @ frames[:, :, 0].T)
    assert np.allclose(A, dense)
    g = -np.einsum("ns,ns->n", frames[:, :, 0], LP)
    assert np.allclose(ns.M.toarray(), dense.T @ dense)
    assert np.allclose(ns.b.ravel(), dense.T @ g)
    assert np.array_equal(ns.d2, w2)


def test_compiled_covariances_match_numpy() -> None:
    from service.core.operator.kernels import neighbourhood_covariances

    rng = np.random.default_rng(9)
    X = rng.normal(size=(40, 3))
    idx = rng.integers(0, 40, size=(40, 7))
    Q = X[idx] - X[idx].mean(axis=1, keepdims=True)
    assert np.allclose(neighbourhood_covariances(X, idx), np.einsum("nki,nkj->nij", Q, Q))


def test_compiled_scaling_of_the_normal_system_is_the_numpy_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """From COMPILED_FRAMES_FROM unknowns A_ij = L_ij n_i . n_j is formed by a kernel: the same
    bits as the gathered einsum (and the dense product above checks the formula)."""
    from service.core.system import displacement

    rng = np.random.default_rng(3)
    m = 80
    L = sp.random(m, m, density=0.1, random_state=4, format="csr") + sp.eye(m)
    frames = rng.normal(size=(m, 3, 1))
    frames /= np.linalg.norm(frames, axis=1, keepdims=True)
    LP, w2 = rng.normal(size=(m, 3)), rng.uniform(0.5, 2.0, m)
    plain = projected_normal_system(L, LP, frames, w2)
    monkeypatch.setattr(displacement, "COMPILED_FRAMES_FROM", 1)
    compiled = projected_normal_system(L, LP, frames, w2)
    assert np.array_equal(plain.M.tocsr().toarray(), compiled.M.tocsr().toarray())
    assert np.array_equal(plain.b, compiled.b)


def test_no_fixed_points_give_the_system_of_the_full_selection() -> None:
    """normal_mode without fixed points skips the row and column selections: same system."""
    from service.core.operator.build import build_operator
    from service.core.system.displacement import normal_mode

    P, F = noisy_icosphere(3, 0.02)
    g = Geometry(P, faces=F)
    op = build_operator(g, SmoothingParams())
    Q = op.frame.points(P)
    omega = np.random.default_rng(2).uniform(0.5, 2.0, g.n)
    system, to_points = normal_mode(g, op.L, op.neighborhoods, Q, omega, np.zeros(g.n, bool))
    every = np.arange(g.n)
    L_R = sp.csr_matrix(op.L)[every]
    frames = normal_frames(Q, op.neighborhoods.adjacency, 1)[every]
    ref = projected_normal_system(L_R[:, every], np.asarray(L_R @ Q), frames, omega[every] ** 2)
    assert np.array_equal(system.M.tocsr().toarray(), ref.M.tocsr().toarray())
    assert np.array_equal(system.b, ref.b) and np.array_equal(system.d2, ref.d2)
    U = np.random.default_rng(3).normal(size=(g.n, 1))
    assert np.array_equal(to_points(U), ref.points(Q[every], U))
