"""smooth(): numbers against independent computations (dense solves, closed forms, the report)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from service.core import Geometry, ParameterError, SmoothingParams, TauOutOfRange, smooth
from service.core.operator.build import build_laplacian
from tests.core.core_fixtures import grid_mesh, noisy_icosphere, polyline_edges, random_rotation


def _curve_network(seed: int = 0) -> Geometry:
    """Two components: a 'Y' junction network (degree-3 vertex) and a closed noisy loop."""
    rng = np.random.default_rng(seed)
    arm = np.linspace(0.1, 1, 10)
    pts = [np.zeros((1, 3))]
    edges = []
    for k, d in enumerate([[1, 0, 0], [0, 1, 0], [-1, -1, 0.5]]):
        start = 1 + 10 * k
        pts.append(arm[:, None] * np.array(d, float))
        edges += [[0, start]] + [[start + i, start + i + 1] for i in range(9)]
    t = np.linspace(0, 2 * np.pi, 25, endpoint=False)
    pts.append(np.c_[np.cos(t) + 3, np.sin(t), 0 * t])
    edges += polyline_edges(25, closed=True, offset=31).tolist()
    P = np.concatenate(pts) + rng.normal(0, 0.02, (56, 3))
    return Geometry(P, edges=np.array(edges))


def _cases() -> list[tuple[str, Geometry, dict]]:
    rng = np.random.default_rng(7)
    P, F = noisy_icosphere(1, 0.03, seed=1)
    mesh = Geometry(P, faces=F, weights=rng.uniform(0.5, 2.0, len(P)), fixed=[0, 5])
    cloud = Geometry(rng.normal(size=(120, 3)) * [1, 1, 0.1], weights=rng.uniform(0.5, 2, 120))
    cases: list[tuple[str, Geometry, dict]] = []
    for w, v in itertools.product(
        ["uniform", "reciprocal", "mean-value", "cotangent"], ["normalized", "curvature", "feature"]
    ):
        cases.append((f"mesh-{w}-{v}", mesh, {"weights": w, "laplacian": v}))
    for w, v in itertools.product(
        ["uniform", "reciprocal"], ["normalized", "curvature", "feature"]
    ):
        cases.append((f"curve-{w}-{v}", _curve_network(), {"weights": w, "laplacian": v}))
    for nbk, w in [
        ("delaunay", "mean-value"),
        ("delaunay", "cotangent"),
        ("delaunay", "uniform"),
        ("knn", "reciprocal"),
        ("knn", "uniform"),
    ]:
        cases.append(
            (
                f"cloud-{nbk}-{w}",
                cloud,
                {"weights": w, "neighborhood": nbk, "k": 8, "laplacian": "feature"},
            )
        )
    return cases


@pytest.mark.parametrize(("name", "geometry", "kw"), _cases(), ids=[c[0] for c in _cases()])
def test_matches_dense_least_squares(name: str, geometry: Geometry, kw: dict) -> None:
    """X(lambda) equals the dense least-squares solution of the stacked system (eq. 16)."""
    lam = 0.37
    params = SmoothingParams(lam=lam, preset="report", **kw)  # eq. (4) itself
    res = smooth(geometry, params)
    L = build_laplacian(geometry, params)[0].toarray()
    P, omega = geometry.points, geometry.omega()
    fixed = geometry.fixed_mask()
    F, C = ~fixed, fixed
    A = L[F][:, F]
    B = L[F][:, C]
    s = np.sqrt(lam) * omega[F]
    top = -B @ P[C]
    stacked = np.vstack([A, np.diag(s)])
    rhs = np.vstack([top, s[:, None] * P[F]])
    X_F = np.linalg.lstsq(stacked, rhs, rcond=None)[0]
    np.testing.assert_allclose(res.points[F], X_F, rtol=0, atol=1e-9 * np.abs(P).max())
    assert np.array_equal(res.points[C], P[C])
    phi = float(np.sum(omega[F, None] ** 2 * (X_F - P[F]) ** 2))
    assert res.phi == pytest.approx(phi, rel=1e-8)


def test_limit_large_lambda_returns_input() -> None:
    P, F = noisy_icosphere(2, 0.02)
    res = smooth(Geometry(P, faces=F), SmoothingParams(lam=1e12))
    assert res.max_displacement < 1e-9


@pytest.mark.parametrize("kind", ["mesh", "curve"])
def test_limit_small_lambda_tends_to_weighted_centroid(kind: str) -> None:
    """Eqs. (13)-(14): X -> weighted centroid as lambda -> 0."""
    rng = np.random.default_rng(2)
    if kind == "mesh":
        P, F = noisy_icosphere(1, 0.05, seed=4)
        g = Geometry(P, faces=F, weights=rng.uniform(0.2, 3.0, len(P)))
    else:
        P = rng.normal(size=(30, 2))
        g = Geometry(P, edges=polyline_edges(30), weights=rng.uniform(0.2, 3.0, 30))
    w2 = g.omega() ** 2
    centroid = (w2[:, None] * g.points).sum(0) / w2.sum()
    errs = []
    for lam in (1e-6, 1e-8, 1e-10):
        X = smooth(g, SmoothingParams(lam=lam, preset="report")).points
        errs.append(np.abs(X - centroid).max())
    assert errs[2] < 1e-4 * np.abs(P).max()
    # X(lambda) - centroid = O(lambda): two decades of lambda give about two decades of error
    assert errs[0] > 30 * errs[1] > 900 * errs[2]


def _tau_cases() -> list[tuple[str, Geometry]]:
    rng = np.random.default_rng(11)
    P, F = noisy_icosphere(3, 0.01)
    out = [("mesh", Geometry(P, faces=F))]
    t = np.linspace(0, 4 * np.pi, 300)
    out.append(
        (
            "polyline-3d",
            Geometry(
                np.c_[np.cos(t), np.sin(t), t / 5] + rng.normal(0, 0.02, (300, 3)),
                edges=polyline_edges(300),
            ),
        )
    )
    out.append(("network", _curve_network(3)))
    for s in (2, 3, 5):
        Q = rng.normal(size=(800, 2)) @ random_rotation(s)[:2] if s >= 2 else None
        Q = Q + rng.normal(0, 0.02, Q.shape)  # noisy plane in R^s
        out.append((f"cloud-{s}d", Geometry(Q)))
        out.append((f"cloud-knn-{s}d", Geometry(Q)))
    t = np.sort(rng.uniform(0, 2 * np.pi, 200))
    c5 = np.c_[np.cos(t), np.sin(t), np.cos(2 * t), np.sin(2 * t), t] @ random_rotation(5)
    out.append(
        ("polyline-5d", Geometry(c5 + rng.normal(0, 0.01, c5.shape), edges=polyline_edges(200)))
    )
    return out


@pytest.mark.parametrize(("name", "geometry"), _tau_cases(), ids=[c[0] for c in _tau_cases()])
def test_tau_is_met_within_tolerance(name: str, geometry: Geometry) -> None:
    nbk = "knn" if "knn" in name else "delaunay"
    phi0_bound = float(np.sum((geometry.points - geometry.points.mean(0)) ** 2))
    for frac, tol in ((1e-3, 1e-3), (0.05, 1e-4)):
        tau = frac * phi0_bound
        seen: list[tuple[int, float, float]] = []
        res = smooth(
            geometry,
            SmoothingParams(tau=tau, tolerance=tol, neighborhood=nbk, preset="report"),
            progress=lambda e, seen=seen: seen.append((e.iteration, e.lam, e.phi))
            if e.stage == "search"
            else None,
        )
        assert res.converged, res.history
        assert abs(res.phi - tau) / tau <= tol
        dev = float(np.sum((res.points - geometry.points) ** 2))
        assert dev == pytest.approx(res.phi, rel=1e-9)
        assert [s[0] for s in seen] == list(range(1, res.iterations + 1))
        assert [(lam, phi) for _, lam, phi in seen] == res.history
        assert res.iterations <= 15


def test_rms_is_tau_per_point() -> None:
    P, F = noisy_icosphere(3, 0.01)
    res = smooth(Geometry(P, faces=F), SmoothingParams(rms=0.004))
    assert res.tau == pytest.approx(len(P) * 0.004**2)
    assert res.rms_displacement == pytest.approx(0.004, rel=1e-3)


def test_phi_decreases_monotonically_in_lambda() -> None:
    P, F = noisy_icosphere(2, 0.03)
    g = Geometry(P, faces=F)
    lams = np.logspace(-5, 4, 19)
    phis = [smooth(g, SmoothingParams(lam=lam)).phi for lam in lams]
    assert all(a > b for a, b in itertools.pairwise(phis))


def test_tau_out_of_range_gives_valid_range() -> None:
    P, F = noisy_icosphere(2, 0.03)
    g = Geometry(P, faces=F)
    phi0 = float(np.sum((P - P.mean(0)) ** 2))  # eq. (14) with D = I
    with pytest.raises(TauOutOfRange) as info:
        smooth(g, SmoothingParams(tau=phi0 * 1.0001, preset="report"))
    assert info.value.tau_max == pytest.approx(phi0, rel=1e-12)
    assert f"{phi0:.6g}" in str(info.value)
    with pytest.raises(TauOutOfRange) as info2:
        smooth(g, SmoothingParams(rms=10.0, preset="report"))
    assert info2.value.field == "params.rms"
    smooth(g, SmoothingParams(tau=phi0 * 0.999, preset="report"))  # just inside is fine


def test_fixed_points_bit_identical() -> None:
    P, F = noisy_icosphere(3, 0.02)
    fixed = np.arange(0, len(P), 17)
    g = Geometry(P * 1e3 + np.pi, faces=F, fixed=fixed)
    tau = float(np.sum((g.points - g.points.mean(0)) ** 2)) * 1e-3
    res = smooth(g, SmoothingParams(tau=tau, preset="report"))
    assert np.array_equal(res.points[fixed], g.points[fixed])
    assert res.n_fixed == fixed.size
    weights = np.ones(len(P))
    weights[[3, 4]] = np.inf
    res2 = smooth(Geometry(P, faces=F, weights=weights), SmoothingParams(lam=0.01))
    assert np.array_equal(res2.points[[3, 4]], P[[3, 4]])


def test_boundary_switch_fixes_exactly_the_boundary() -> None:
    P, F = grid_mesh(12, 9, jitter=0.3)
    P[:, 2] = np.random.default_rng(0).normal(0, 0.01, len(P))
    # independent boundary: edges used by exactly one face
    counts: dict[tuple[int, int], int] = {}
    for f in F:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(a, b), max(a, b))
            counts[key] = counts.get(key, 0) + 1
    boundary = sorted({v for e, c in counts.items() if c == 1 for v in e})
    res = smooth(Geometry(P, faces=F), SmoothingParams(lam=0.05, fix_boundary=True))
    moved = np.flatnonzero(np.any(res.points != P, axis=1))
    assert res.n_fixed == len(boundary)
    assert sorted(set(range(len(P))) - set(moved.tolist())) == boundary
    # open polyline: exactly the two endpoints of each open component
    Q = np.random.default_rng(1).normal(size=(20, 2))
    E = np.concatenate([polyline_edges(10), polyline_edges(10, offset=10)])
    res = smooth(Geometry(Q, edges=E), SmoothingParams(lam=0.1, fix_boundary=True))
    still = np.flatnonzero(np.all(res.points == Q, axis=1)).tolist()
    assert still == [0, 9, 10, 19]


@pytest.mark.parametrize("weights", ["reciprocal", "mean-value", "cotangent"])
def test_reproduction_property(weights: str) -> None:
    """Points on a line / plane are left invariant (report section 4.3)."""
    rng = np.random.default_rng(5)
    if weights == "reciprocal":  # uneven samples on a line in 3D, ends fixed
        t = np.sort(rng.uniform(0, 1, 40))
        P = np.outer(t, [1.0, 2.0, -0.5]) + np.ones(3)
        g = Geometry(P, edges=polyline_edges(40))
        uniform = Geometry(P, edges=polyline_edges(40))
    else:  # irregular planar mesh (no flipped triangles) in a tilted plane, boundary fixed
        P2, F = grid_mesh(10, 10, jitter=0.3)
        if weights == "cotangent":  # positive cotangents need a Delaunay triangulation
            F = Delaunay(P2[:, :2]).simplices
        P = P2 @ random_rotation(3, seed=2)
        g = Geometry(P, faces=F)
        uniform = g
    res = smooth(g, SmoothingParams(lam=1e-3, weights=weights, fix_boundary=True, preset="report"))
    assert np.abs(res.points - P).max() < 1e-10
    moved = smooth(
        uniform, SmoothingParams(lam=1e-3, weights="uniform", fix_boundary=True, preset="report")
    )
    assert np.abs(moved.points - P).max() > 1e-3  # uniform weights do not reproduce


def test_reproduction_on_planar_point_cloud() -> None:
    """Delaunay neighbourhoods + mean-value weights reproduce a planar cloud (section 4.4)."""
    rng = np.random.default_rng(8)
    x, y = np.meshgrid(np.arange(20.0), np.arange(20.0))
    Q = np.c_[x.ravel(), y.ravel()] + rng.uniform(-0.3, 0.3, (400, 2))
    P = np.c_[Q, np.zeros(400)] @ random_rotation(3, seed=9)
    border = np.flatnonzero((Q.min(1) < 2) | (Q.max(1) > 17))
    res = smooth(Geometry(P, fixed=border), SmoothingParams(lam=1e-3, k=12, preset="report"))
    assert np.abs(res.points - P).max() < 1e-9
    assert res.weights == "mean-value"


def test_messy_mesh_smooths_without_nan() -> None:
    """Duplicate / zero-area faces, unreferenced vertices, non-manifold edges, bowties, islands."""
    P, F = noisy_icosphere(2, 0.01)
    n = len(P)
    extra = np.array([[5.0, 5, 5], [6, 6, 6], [7, 7, 7], [5, 5, 5], [9, 9, 9], [10, 10, 10]])
    P = np.vstack([P, extra, [[0.0, 0, 0]] * 2, [[4.0, 4.0, 4.0]]])
    faces = np.vstack(
        [
            F,
            F[:10],  # duplicates
            F[:5, ::-1],  # duplicates with opposite winding
            [[F[0, 0], F[0, 1], n]],  # non-manifold edge (third face on an edge)
            [[F[0, 0], n + 1, n + 2]],  # bowtie at F[0, 0]
            [[n, n + 1, n + 3]],  # zero-area: n and n+3 coincide
            [[n + 6, n + 7, n + 4]],  # zero-area: two coincident points
        ]
    )
    unreferenced = [n + 5, n + 8]
    g = Geometry(P, faces=faces)
    for lap in ("normalized", "curvature", "feature"):
        for w in ("mean-value", "cotangent", "reciprocal"):
            res = smooth(g, SmoothingParams(rms=0.005, laplacian=lap, weights=w))
            assert np.all(np.isfinite(res.points))
            assert np.array_equal(res.points[unreferenced], P[unreferenced])
            assert res.converged


def test_triangle_weights_need_triangles() -> None:
    g = Geometry(np.random.default_rng(0).normal(size=(10, 2)), edges=polyline_edges(10))
    with pytest.raises(ParameterError) as info:
        smooth(g, SmoothingParams(tau=0.1, weights="mean-value"))
    assert info.value.field == "params.weights"
    with pytest.raises(ParameterError):
        smooth(
            Geometry(np.random.default_rng(0).normal(size=(30, 3))),
            SmoothingParams(tau=0.1, weights="cotangent", neighborhood="knn"),
        )


def test_all_fixed_or_single_point() -> None:
    P = np.random.default_rng(0).normal(size=(5, 3))
    res = smooth(Geometry(P, edges=polyline_edges(5), fixed=range(5)), SmoothingParams(lam=1.0))
    assert np.array_equal(res.points, P) and res.warnings
    with pytest.raises(TauOutOfRange):
        smooth(Geometry(P[:1]), SmoothingParams(tau=1.0))


def test_superlu_matches_cholmod_and_fallback(monkeypatch: pytest.MonkeyPatch) -> None:
    P, F = noisy_icosphere(2, 0.02)
    g = Geometry(P, faces=F, fixed=[1, 2])
    a = smooth(g, SmoothingParams(tau=0.05))
    b = smooth(g, SmoothingParams(tau=0.05, solver="superlu"))
    assert (a.solver, b.solver) == ("cholmod", "superlu")
    np.testing.assert_allclose(a.points, b.points, atol=1e-10)
    from service.core.linalg import solver

    monkeypatch.setattr(solver, "_cholmod", None)
    c = smooth(g, SmoothingParams(tau=0.05))
    assert c.solver == "superlu"
    assert any(w.code == "solver-fallback" and "SuperLU" in w.message for w in c.warnings)
    np.testing.assert_allclose(a.points, c.points, atol=1e-10)


def test_one_analysis_and_one_factorization_per_lambda(monkeypatch: pytest.MonkeyPatch) -> None:
    """The report's search (rational, section 6.3): one numeric factorization per lambda tried
    and one symbolic analysis per run (the analysis cache is emptied first)."""
    from service.core.linalg import cache, solver

    cache.clear()

    calls = {"analyze": 0}
    real = solver._cholmod.analyze

    def counting(*args: object, **kwargs: object) -> object:
        calls["analyze"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(solver._cholmod, "analyze", counting)
    P, F = noisy_icosphere(2, 0.02)
    res = smooth(Geometry(P, faces=F), SmoothingParams(tau=0.05, preset="report"))
    assert calls["analyze"] == 1
    assert res.factorizations == res.iterations


def test_report_keys() -> None:
    P, F = noisy_icosphere(1, 0.02)
    rep = smooth(Geometry(P, faces=F), SmoothingParams(tau=0.01)).report()
    for key in (
        "lambda",
        "phi",
        "tau",
        "relative_error",
        "converged",
        "iterations",
        "factorizations",
        "history",
        "n_points",
        "dimension",
        "laplacian",
        "weights",
        "rms_displacement",
        "max_displacement",
        "timings",
        "solver",
    ):
        assert key in rep
    assert set(rep["timings"]) >= {
        "neighborhoods",
        "laplacian",
        "analysis",
        "factorization",
        "solve",
        "total",
    }
    assert rep["history"][-1] == {"lambda": rep["lambda"], "phi": rep["phi"]}


def test_laplacian_is_sparse_and_normalized() -> None:
    P, F = noisy_icosphere(2, 0.02)
    L = build_laplacian(Geometry(P, faces=F), SmoothingParams(lam=1.0))[0]
    assert sp.issparse(L)
    np.testing.assert_allclose(L.diagonal(), 1.0)
    np.testing.assert_allclose(np.asarray(L.sum(axis=1)).ravel(), 0.0, atol=1e-12)


def test_progress_carries_the_engines_tau_from_the_start() -> None:
    """Regression (issue 10): ``rms`` with ``fix_boundary`` on a 12 x 9 grid. The engine's tau
    sums over the free (interior) points only; every event from ``analysis`` on carries it, so
    progress shows the relative error the final report has."""
    nx, ny = 12, 9
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    rng = np.random.default_rng(7)
    P = np.column_stack([x.ravel(), y.ravel(), 0.01 * rng.standard_normal(nx * ny)])
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    F = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    events: list = []
    res = smooth(
        Geometry(P, faces=F), SmoothingParams(rms=0.003, fix_boundary=True), progress=events.append
    )
    n_free = (nx - 2) * (ny - 2)
    assert res.tau == pytest.approx(n_free * 0.003**2, rel=1e-12)  # 6.3e-4, not 9.72e-4
    stages = [e.stage for e in events]
    assert stages[0] == "neighborhoods" and "analysis" in stages
    first_tau = stages.index("analysis")
    assert stages.index("search") > first_tau  # tau known before the first factorization
    assert all(e.tau == res.tau for e in events[first_tau:])
    last = [e for e in events if e.stage == "search"][-1]
    assert last.relative_error == pytest.approx(res.relative_error, rel=1e-12)
