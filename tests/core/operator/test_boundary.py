"""End conditions (issue 21): fixed open-polyline ends, boundary rows along the boundary curve.

Every expectation is an independent computation: a straight line (zero rows), the dense solve
of eq. (4) with a hand-built Laplacian, fixed points eliminated by hand.
"""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.operator.boundary import boundary_edges, boundary_rule
from service.core.operator.build import build_laplacian, build_operator
from service.core.params import REPORT_PRESET


def _uneven_line(n: int = 30) -> np.ndarray:
    u = np.linspace(0.0, 1.0, n)
    t = u + 0.12 * np.sin(2 * np.pi * u)  # spacing ratio ~4, monotone
    return np.column_stack([t, 2.0 * t - 1.0, 0.5 * t])


def _chain(n: int) -> np.ndarray:
    i = np.arange(n - 1)
    return np.column_stack([i, i + 1])


def test_fixed_ends_keep_an_unevenly_sampled_straight_line_exactly() -> None:
    """Reciprocal weights make every interior row of a straight line zero (x_i is the
    chord-length interpolation of its neighbours); with the ends fixed nothing is left to move,
    at any lambda. The report's pulled ends contract the line along itself."""
    P = _uneven_line()
    g = Geometry(P, edges=_chain(len(P)))
    for lam in (1e-3, 1.0):
        kept = smooth(g, SmoothingParams(lam=lam, weights="reciprocal", order=1))
        np.testing.assert_allclose(kept.points, P, atol=1e-12)
    pulled = smooth(g, SmoothingParams(lam=1e-3, weights="reciprocal", order=1, ends="pulled"))
    moved = np.linalg.norm(pulled.points - P, axis=1)
    assert moved[0] > 1e-3 and moved[-1] > 1e-3
    length = np.linalg.norm(P[-1] - P[0])
    assert np.linalg.norm(pulled.points[-1] - pulled.points[0]) < length - 1e-3


def test_fixed_ends_equal_the_dense_solve_with_the_ends_eliminated() -> None:
    rng = np.random.default_rng(3)
    n, lam = 40, 0.05
    t = np.linspace(0, np.pi, n)
    P = np.column_stack([np.cos(t), np.sin(t)]) + 0.02 * rng.normal(size=(n, 2))
    res = smooth(Geometry(P, edges=_chain(n)), SmoothingParams(lam=lam, order=1))
    # uniform weights: the row of x_i is x_i - (x_{i-1} + x_{i+1}) / 2; ends have x_0 - x_1
    L = np.eye(n)
    for i in range(1, n - 1):
        L[i, i - 1] = L[i, i + 1] = -0.5
    free = np.arange(1, n - 1)
    fixed = np.array([0, n - 1])
    # section 8: the fixed points' own rows leave the objective, their columns the unknowns;
    # min ||LF XF + LC PC||^2 + lam ||XF - PF||^2 over the free rows
    LF, LC = L[free][:, free], L[free][:, fixed]
    A = LF.T @ LF + lam * np.eye(free.size)
    XF = np.linalg.solve(A, lam * P[free] - LF.T @ (LC @ P[fixed]))
    np.testing.assert_allclose(res.points[fixed], P[fixed], atol=0)
    np.testing.assert_allclose(res.points[free], XF, atol=1e-9)


def test_closed_curves_have_no_ends_to_fix() -> None:
    n = 24
    t = 2 * np.pi * np.arange(n) / n
    P = np.column_stack([np.cos(t), np.sin(t)])
    P = P + 0.01 * np.random.default_rng(2).normal(size=P.shape)
    E = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    g = Geometry(P, edges=E)
    a = smooth(g, SmoothingParams(lam=0.1))
    b = smooth(g, SmoothingParams(lam=0.1, ends="pulled"))
    np.testing.assert_array_equal(a.points, b.points)
    op = build_operator(g, SmoothingParams(lam=0.1))
    assert op.pinned is not None and not op.pinned.any()


def _grid(m: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    P = np.column_stack([i.ravel(), j.ravel(), np.zeros(m * m)]).astype(float)
    a = (i[:-1, :-1] * m + j[:-1, :-1]).ravel()
    F = np.vstack([np.column_stack([a, a + m, a + 1]), np.column_stack([a + 1, a + m, a + m + 1])])
    return P, F.astype(np.int64)


def _hand_laplacian(P: np.ndarray, F: np.ndarray, curve: bool) -> np.ndarray:
    """Uniform L: 1-ring rows, boundary rows over the boundary neighbours with ``curve``."""
    n = len(P)
    count: dict[tuple[int, int], int] = {}
    for f in F:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(a, b), max(a, b))
            count[key] = count.get(key, 0) + 1
    ring: list[set[int]] = [set() for _ in range(n)]
    bnd: list[set[int]] = [set() for _ in range(n)]
    for (a, b), c in count.items():
        ring[a].add(b)
        ring[b].add(a)
        if c == 1:
            bnd[a].add(b)
            bnd[b].add(a)
    L = np.eye(n)
    for i in range(n):
        nbrs = bnd[i] if curve and bnd[i] else ring[i]
        for j in nbrs:
            L[i, j] = -1.0 / len(nbrs)
    return L


def test_boundary_curve_rows_keep_a_plane_grid_and_match_the_hand_built_laplacian() -> None:
    m = 7
    P, F = _grid(m)
    g = Geometry(P, faces=F)
    L_curve, *_ = build_laplacian(g, SmoothingParams(boundary="curve"))
    L_ring, *_ = build_laplacian(g, SmoothingParams(boundary="ring"))
    np.testing.assert_allclose(L_curve.toarray(), _hand_laplacian(P, F, True), atol=1e-14)
    np.testing.assert_allclose(L_ring.toarray(), _hand_laplacian(P, F, False), atol=1e-14)
    # on the regular grid, rows along the straight border vanish; only the 4 corners pull
    rows = np.linalg.norm(L_curve @ P, axis=1)
    corners = [0, m - 1, m * (m - 1), m * m - 1]
    assert np.count_nonzero(rows > 1e-12) == 4 and set(np.flatnonzero(rows > 1e-12)) == set(
        corners
    )
    assert np.count_nonzero(np.linalg.norm(L_ring @ P, axis=1) > 1e-12) > 4


def test_boundary_curve_free_solution_equals_the_dense_solve() -> None:
    rng = np.random.default_rng(5)
    P, F = _grid(6)
    Q = P @ np.array([[1.0, 0.0, 0.3], [0.0, 1.0, -0.2], [0.0, 0.0, 1.0]])  # a tilted plane
    Q = Q + 0.05 * rng.normal(size=Q.shape)
    lam = 0.3
    res = smooth(
        Geometry(Q, faces=F),
        SmoothingParams(lam=lam, displacement="free", order=1, boundary="curve"),
    )
    L = _hand_laplacian(P, F, True)
    X = np.linalg.solve(L.T @ L + lam * np.eye(len(Q)), lam * Q)
    np.testing.assert_allclose(res.points, X, atol=1e-9)


def test_auto_rules_and_the_report_preset() -> None:
    P, F = _grid(4)
    g = Geometry(P + 0.01, faces=F)
    assert boundary_rule(SmoothingParams(displacement="free"), g) == "curve"
    assert boundary_rule(SmoothingParams(method="windowed-sinc"), g) == "curve"
    assert boundary_rule(SmoothingParams(), g) == "ring"  # normal displacement for meshes
    assert boundary_rule(SmoothingParams(displacement="normal", boundary="curve"), g) == "curve"
    assert boundary_rule(SmoothingParams(displacement="free"), Geometry(P)) == "ring"
    assert REPORT_PRESET["ends"] == "pulled" and REPORT_PRESET["boundary"] == "ring"
    report = SmoothingParams(preset="report")
    assert report.ends == "pulled" and report.boundary == "ring"


def test_boundary_edges_of_a_square_of_two_triangles() -> None:
    F = np.array([[0, 1, 2], [0, 2, 3]])
    got = {tuple(e) for e in boundary_edges(F, 4)}
    assert got == {(0, 1), (1, 2), (2, 3), (0, 3)}


@pytest.mark.parametrize("ends", ["fixed", "pulled"])
def test_automatic_tau_on_an_open_curve_stays_finite(ends: str) -> None:
    rng = np.random.default_rng(8)
    n = 200
    t = np.linspace(0, 3 * np.pi, n)
    P = np.column_stack([t, np.sin(t)]) + 0.02 * rng.normal(size=(n, 2))
    res = smooth(Geometry(P, edges=_chain(n)), SmoothingParams(ends=ends))  # type: ignore[arg-type]
    assert np.all(np.isfinite(res.points))
    assert res.tau is not None and res.tau > 0
