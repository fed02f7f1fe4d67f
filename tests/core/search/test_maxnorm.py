"""max_deviation: ||x_i - p_i|| <= delta for every point, in every mode and with every target."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.finish.clip import clip_points
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def _mesh() -> Geometry:
    P, F = noisy_icosphere(3, 0.02, seed=7)
    return Geometry(P, faces=F)


def _curve() -> Geometry:
    rng = np.random.default_rng(2)
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    P = np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, 0.02, (300, 2))
    return Geometry(P, edges=polyline_edges(300, closed=True))


@pytest.mark.parametrize("make", [_mesh, _curve], ids=["mesh", "curve"])
@pytest.mark.parametrize("target", [{"tau": None}, {}, {"lam": 0.01}], ids=["tau", "auto", "lam"])
@pytest.mark.parametrize("displacement", ["free", "normal"])
def test_bound_holds_for_every_point(make, target: dict, displacement: str) -> None:
    g = make()
    weights = {"weights": "uniform"} if g.kind == "mesh" else {}
    base = smooth(g, SmoothingParams(displacement=displacement, **weights))
    unbounded = base.deviation
    delta = 0.6 * float(unbounded.max())  # binding: the largest moves must shrink
    kw = dict(target)
    if "tau" in kw:
        kw["tau"] = base.tau
    params = SmoothingParams(max_deviation=delta, displacement=displacement, **weights, **kw)
    res = smooth(g, params)
    dist = np.linalg.norm(res.points - g.points, axis=1)
    assert dist.max() <= delta
    assert res.bound is not None and res.bound["rounds"] >= 1
    if "tau" in kw:  # the budget is met (original weights) unless points had to be clipped
        phi = float(np.sum(dist**2))
        if res.bound["clipped"] == 0:
            assert abs(phi - kw["tau"]) / kw["tau"] <= 1e-3
        else:
            assert phi <= kw["tau"] * (1 + 1e-3)


def test_rounds_end_without_clipping_at_a_feasible_bound() -> None:
    g = _mesh()
    base = smooth(g, SmoothingParams(weights="uniform"))
    delta = 3.0 * base.rms_displacement
    res = smooth(g, SmoothingParams(weights="uniform", max_deviation=delta))
    assert res.bound is not None and res.bound["clipped"] == 0 and res.bound["rounds"] <= 10
    assert res.max_displacement <= delta


def test_infeasible_tau_keeps_the_bound_and_says_so() -> None:
    g = _mesh()
    delta = 0.005
    tau = 2.0 * g.n * delta**2  # more than every point moving by delta
    res = smooth(g, SmoothingParams(weights="uniform", tau=tau, max_deviation=delta))
    assert res.max_displacement <= delta
    assert any(w.code == "max-deviation" and "cannot hold" in w.message for w in res.warnings)


def test_clip_points_is_exact_in_floating_point() -> None:
    rng = np.random.default_rng(0)
    P = rng.uniform(-1e6, 1e6, (1000, 3))
    X = P + rng.normal(0, 1.0, P.shape)
    delta = 0.5
    Y, moved = clip_points(P, X, delta)
    assert moved > 0 and np.linalg.norm(Y - P, axis=1).max() <= delta
    inside = np.linalg.norm(X - P, axis=1) <= delta
    assert np.array_equal(Y[inside], X[inside])  # points within the bound are untouched
