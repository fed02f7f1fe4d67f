"""Issue 30: the report says what the output is, and the one-run path's Tikhonov part is the
exact solution at the reported lambda (to 1e-3 of the displacement)."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import SmoothingParams, smooth
from service.core.geometry import Geometry
from service.core.search.one_run_target import ONE_RUN_FROM


@pytest.fixture(scope="module")
def sphere() -> Geometry:
    trimesh = pytest.importorskip("trimesh")
    m = trimesh.creation.icosphere(6)  # 40962 vertices: the one-run path
    P = np.asarray(m.vertices)
    assert P.shape[0] >= ONE_RUN_FROM
    edge = float(np.mean(np.linalg.norm(P[m.edges_unique[:, 0]] - P[m.edges_unique[:, 1]], axis=1)))
    P = P + np.random.default_rng(7).normal(0, 0.3 * edge, P.shape)
    return Geometry(P, faces=np.asarray(m.faces))


def _total(g: Geometry, X: np.ndarray) -> float:
    return float(np.sum(g.omega() ** 2 * np.sum((X - g.points) ** 2, axis=1)))


def test_default_reports_the_output_deviation_and_its_parts(sphere: Geometry) -> None:
    res = smooth(sphere, SmoothingParams(robust="none", noise_weights="none"))
    rep = res.report()
    dev = rep["output_deviation"]
    assert rep["solver"] == "lanczos" and rep["factorizations"] == 0
    assert dev["total"] == pytest.approx(_total(sphere, res.points), rel=1e-12)
    assert dev["tikhonov"] == pytest.approx(rep["phi"])
    assert dev["tangential"] == pytest.approx((rep["tangential"] or {}).get("psi", 0.0))
    parts = dev["tikhonov"] + dev["tangential"] + dev["other"]
    assert parts == pytest.approx(dev["total"], rel=1e-12)
    assert abs(dev["other"]) <= 1e-6 * dev["total"]  # normal and tangential moves add


def test_a_given_tau_bounds_the_total(sphere: Geometry) -> None:
    rms = 0.3 * float(np.mean(np.linalg.norm(sphere.points, axis=1))) * 0.005
    res = smooth(sphere, SmoothingParams(rms=rms))
    rep = res.report()
    assert rep["tangential"] is None
    assert rep["output_deviation"]["total"] == pytest.approx(rep["phi"], rel=1e-9)
    assert rep["output_deviation"]["total"] <= rep["tau"] * (1 + 1e-3)


def test_tikhonov_part_is_the_exact_solution_at_the_reported_lambda(sphere: Geometry) -> None:
    common = {"robust": "none", "noise_weights": "none", "tangential": "off"}
    res = smooth(sphere, SmoothingParams(**common))
    assert res.solver == "lanczos"
    exact = smooth(sphere, SmoothingParams(lam=res.lam, solver="cholmod", **common))
    moved = np.linalg.norm(res.points - sphere.points)
    assert np.linalg.norm(res.points - exact.points) <= 1e-3 * moved
