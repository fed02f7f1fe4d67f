"""The tangential step (issue 21): closed forms on flat grids, the fold guard, the pipeline."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.core import Geometry, SmoothingParams, smooth
from service.core.finish import tangential as tg
from tests.core.core_fixtures import grid_mesh

UP = np.array([0.0, 0.0, 1.0])


def _dense_uniform_laplacian(faces: np.ndarray, n: int) -> np.ndarray:
    """I - Deg^-1 A from the faces' edges, by loops (independent of the operator code)."""
    nbrs: list[set[int]] = [set() for _ in range(n)]
    for f in faces:
        for a in range(3):
            i, j = int(f[a]), int(f[(a + 1) % 3])
            nbrs[i].add(j)
            nbrs[j].add(i)
    L = np.eye(n)
    for i, js in enumerate(nbrs):
        for j in js:
            L[i, j] = -1.0 / len(js)
    return L


def _flat_case(nx: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    P, F = grid_mesh(nx, nx, jitter=0.3, seed=3)
    Q, _ = grid_mesh(nx, nx)  # the clean grid
    x, y = P[:, 0], P[:, 1]
    fixed = (x <= 0) | (x >= 1) | (y <= 0) | (y >= 1)
    return P, F, Q, fixed, _dense_uniform_laplacian(F, len(P))


def _flow(P, F, fixed, L, budget):
    import scipy.sparse as sp

    normals = np.tile(UP, (int((~fixed).sum()), 1))
    return tg.tangential_flow(sp.csr_matrix(L), P, np.ones(len(P)), fixed, normals, budget)


def test_one_full_step_is_half_the_in_plane_laplacian() -> None:
    P, F, _, fixed, L = _flat_case()
    G = -0.5 * (L @ P)[~fixed]
    G[:, 2] = 0.0  # the tangent plane of z = 0
    E, steps, psi = _flow(P, F, fixed, L, float(np.sum(G**2)))
    assert steps == 1
    np.testing.assert_allclose(E, G, atol=1e-12)
    assert psi == pytest.approx(float(np.sum(G**2)), rel=1e-12)


def test_a_shorter_budget_shortens_the_step() -> None:
    P, F, _, fixed, L = _flat_case()
    G = -0.5 * (L @ P)[~fixed]
    G[:, 2] = 0.0
    E, steps, psi = _flow(P, F, fixed, L, 0.5 * float(np.sum(G**2)))
    assert steps == 1
    np.testing.assert_allclose(E, np.sqrt(0.5) * G, atol=1e-12)  # psi(t) = t^2 |G|^2
    assert psi == pytest.approx(0.5 * float(np.sum(G**2)), rel=1e-10)


def test_two_steps_by_hand_and_the_jitter_shrinks() -> None:
    P, F, Q, fixed, L = _flat_case()
    X = P.copy()
    for _ in range(2):
        G = -0.5 * (L @ X)
        G[:, 2] = 0.0
        G[fixed] = 0.0
        X = X + G
    E2 = (X - P)[~fixed]
    E, steps, _ = _flow(P, F, fixed, L, float(np.sum(E2**2)))
    assert steps == 2
    np.testing.assert_allclose(E, E2, atol=1e-10)
    before = np.linalg.norm(P - Q)
    after = np.linalg.norm(X - Q)
    assert after < 0.7 * before  # a regular grid's jitter is what the steps remove


def test_budget_floor_cap_and_formula() -> None:
    floor, f = tg.SHARE_FLOOR, tg.BUDGET_FACTOR
    assert tg.tangential_budget(floor, 3.0) == 0.0
    assert tg.tangential_budget(0.1, 3.0) == 0.0
    assert tg.tangential_budget(1.0, 3.0) == pytest.approx(f * 2 * 3.0)
    assert tg.tangential_budget(2.5, 3.0) == pytest.approx(f * 2 * 3.0)  # capped at 1
    rho = 0.8
    expected = f * 2 * 3.0 * (rho**2 - floor**2) / (1 - floor**2)
    assert tg.tangential_budget(rho, 3.0) == pytest.approx(expected)


def _big_grid(noise: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    P, F = grid_mesh(40, 40)
    h = 1.0 / 39
    rng = np.random.default_rng(seed)
    E = rng.normal(0.0, 0.2 * h, P.shape)
    if noise == "normal":
        E[:, :2] = 0.0
    return P + E, F


def test_share_reads_white_isotropic_noise_as_one_and_normal_noise_as_small() -> None:
    import scipy.sparse as sp

    for noise, lo, hi in (("iso", 0.85, 1.15), ("normal", 0.0, 0.2)):
        P, F = _big_grid(noise)
        A = sp.csr_matrix(np.abs(_dense_uniform_laplacian(F, len(P))) > 0, dtype=float)
        A.setdiag(0.0)
        A.eliminate_zeros()
        share = tg.tangential_share(P, A, np.tile(UP, (len(P), 1)))
        assert lo <= share <= hi, (noise, share)


def test_unfold_reverts_a_fold_and_keeps_the_other_moves() -> None:
    base, F = grid_mesh(8, 8)
    h = 1.0 / 7
    X = base.copy()
    i = 3 * 8 + 3  # interior vertex pushed across its neighbour at (4, 3): folds faces
    X[i, 0] += 1.6 * h
    j = 6 * 8 + 6  # a small move far from it
    X[j, :2] += 0.1 * h
    assert tg.fold_mask(X, F, len(X)).any()
    Y, reverted = tg.unfold(X, base, F)
    assert not tg.fold_mask(Y, F, len(Y)).any()
    assert reverted >= 1
    assert Y[i, 0] < X[i, 0]
    np.testing.assert_array_equal(Y[j], X[j])


def _sphere(noise: str, seed: int = 1) -> tuple[Geometry, np.ndarray]:
    m = trimesh.creation.icosphere(4)
    Q = np.asarray(m.vertices)
    h = float(np.mean(m.edges_unique_length))
    rng = np.random.default_rng(seed)
    if noise == "normal":
        P = Q + Q * rng.normal(0.0, 0.25 * h, (len(Q), 1))
    else:
        P = Q + rng.normal(0.0, 0.25 * h, Q.shape)
    return Geometry(P, faces=np.asarray(m.faces)), Q


def test_default_removes_isotropic_noise_along_the_sphere() -> None:
    g, Q = _sphere("iso")
    off = smooth(g, SmoothingParams(tangential="off"))
    auto = smooth(g, SmoothingParams())
    err = lambda X: float(np.sqrt(np.mean(np.sum((X - Q) ** 2, axis=1))))  # noqa: E731
    assert auto.tangential is not None and auto.tangential["budget"] > 0
    assert 0.8 < auto.tangential["share"] < 1.2
    assert err(auto.points) < 0.6 * err(off.points)
    assert auto.checks["new_folds"] == 0
    # the normal solve's deviation plus the tangential one is the whole deviation
    total = float(np.sum((auto.points - g.points) ** 2))
    assert total == pytest.approx(off.phi + auto.tangential["psi"], rel=1e-6)


def test_default_leaves_normal_noise_to_the_normal_solve() -> None:
    g, _ = _sphere("normal")
    off = smooth(g, SmoothingParams(tangential="off"))
    auto = smooth(g, SmoothingParams())
    assert auto.tangential is not None and auto.tangential["budget"] == 0.0
    assert auto.tangential["share"] < tg.SHARE_FLOOR
    np.testing.assert_array_equal(auto.points, off.points)


@pytest.mark.parametrize(
    "params",
    [
        SmoothingParams(displacement="normal"),
        SmoothingParams(preset="report"),
        SmoothingParams(rms=0.01),
        SmoothingParams(displacement="free"),
        SmoothingParams(tangential="off"),
    ],
)
def test_the_step_runs_only_for_the_default_normal_solve(params: SmoothingParams) -> None:
    g, _ = _sphere("iso")
    assert smooth(g, params).tangential is None


def test_an_explicit_normal_with_an_explicit_auto_runs_it() -> None:
    g, _ = _sphere("iso")
    res = smooth(g, SmoothingParams(displacement="normal", tangential="auto"))
    assert res.tangential is not None and res.tangential["budget"] > 0
    assert res.report()["tangential"] == res.tangential


def _random_hull_sphere(seed: int = 21) -> tuple[np.ndarray, np.ndarray]:
    pts = np.random.default_rng(seed).normal(size=(1500, 3))
    hull = trimesh.convex.convex_hull(pts / np.linalg.norm(pts, axis=1, keepdims=True))
    return np.asarray(hull.vertices), np.asarray(hull.faces)


def test_valence_irregularity_of_regular_and_random_triangulations() -> None:
    _, F = grid_mesh(10, 10)
    assert tg.valence_irregularity(F, 100) == 0.0  # interior valence 6 everywhere
    m = trimesh.creation.icosphere(3)
    assert tg.valence_irregularity(np.asarray(m.faces), len(m.vertices)) == 0.0  # 6 and 5
    Q, F = _random_hull_sphere()
    valence = np.bincount(np.asarray(trimesh.Trimesh(Q, F).edges_unique).ravel())
    top2 = np.sort(np.bincount(valence))[-2:].sum()  # closed: every vertex is interior
    assert tg.valence_irregularity(F, len(Q)) == pytest.approx(1 - top2 / len(Q))
    assert tg.valence_irregularity(F, len(Q)) > tg.IRREGULAR_VALENCE


def test_an_irregular_triangulation_keeps_normal_displacement() -> None:
    Q, F = _random_hull_sphere()
    h = float(np.mean(trimesh.Trimesh(Q, F).edges_unique_length))
    P = Q + Q * np.random.default_rng(2).normal(0.0, 0.1 * h, (len(Q), 1))
    g = Geometry(P, faces=F)
    auto = smooth(g, SmoothingParams())
    off = smooth(g, SmoothingParams(tangential="off"))
    assert auto.tangential is not None and auto.tangential["budget"] == 0.0
    assert auto.tangential["irregular"] > tg.IRREGULAR_VALENCE
    np.testing.assert_array_equal(auto.points, off.points)
