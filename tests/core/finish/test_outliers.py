"""Outliers after the solve (issue 31): flagged clouds keep their input positions bit for bit,
meshes pull their spikes in no further than their ring reaches, drop is for clouds only."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from service.core.errors import ParameterError
from service.core.finish.outliers import bound_to_ring
from service.core.geometry import Geometry
from service.core.params import SmoothingParams
from service.core.pipeline import smooth_one as smooth


def _cloud_with_strays(seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A noisy unit sphere cloud (sigma 0.01) with 6 points thrown 0.3 - 0.6 off it."""
    rng = np.random.default_rng(seed)
    U = rng.normal(size=(3000, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    P = U * (1 + 0.01 * rng.normal(size=(3000, 1)))
    strays = np.array([10, 400, 999, 1500, 2222, 2900])
    P[strays] = U[strays] * (1 + rng.uniform(0.3, 0.6, (6, 1)))
    return P, strays


def test_a_cloud_flags_its_strays_by_default_and_keeps_them_bit_for_bit() -> None:
    P, strays = _cloud_with_strays()
    res = smooth(Geometry(P), SmoothingParams())
    assert set(strays.tolist()) <= set(res.outliers.tolist())
    assert res.outlier_mode == "flag"
    assert np.array_equal(res.points[res.outliers], P[res.outliers])  # bit-identical
    assert res.plan is not None and res.plan.outliers.value == "flag"
    report = res.report()
    assert report["outlier_mode"] == "flag" and report["outliers"] == res.outliers.tolist()
    text = " ".join(map(str, res.warnings))
    assert "flagged as outliers" in text and "tau" not in text.split("flagged")[0]
    assert not res.shape_warnings
    # the bulk is smoothed all the same: closer to the sphere than its input
    bulk = np.setdiff1d(np.arange(len(P)), res.outliers)
    before = np.abs(np.linalg.norm(P[bulk], axis=1) - 1).mean()
    after = np.abs(np.linalg.norm(res.points[bulk], axis=1) - 1).mean()
    assert after < 0.8 * before


def test_pull_on_a_cloud_moves_them_and_drop_keeps_them_in_place_for_the_writer() -> None:
    P, strays = _cloud_with_strays()
    pulled = smooth(Geometry(P), SmoothingParams(outliers="pull"))
    assert pulled.outlier_mode == "pull"
    assert np.all(np.abs(np.linalg.norm(pulled.points[strays], axis=1) - 1) < 0.1)
    dropped = smooth(Geometry(P), SmoothingParams(outliers="drop"))
    assert dropped.outlier_mode == "drop"
    assert np.array_equal(dropped.points[dropped.outliers], P[dropped.outliers])


def test_drop_is_refused_on_a_mesh() -> None:
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.1]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    with pytest.raises(ParameterError, match="drop"):
        smooth(Geometry(P, faces=F), SmoothingParams(outliers="drop"))


def test_a_mesh_spike_is_pulled_back_within_its_ring() -> None:
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(11)
    U = rng.normal(size=(1500, 3))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    F = ConvexHull(U).simplices
    P = U * (1 + 0.01 * rng.normal(size=(1500, 1)))
    P[77] = 3.0 * U[77]
    res = smooth(Geometry(P, faces=F), SmoothingParams())
    assert res.outlier_mode == "pull" and 77 in res.outliers.tolist()
    ring = np.unique(F[(F == 77).any(axis=1)])
    ring = ring[ring != 77]
    Q = res.points[ring]
    c = Q.mean(axis=0)
    assert np.linalg.norm(res.points[77] - c) <= np.max(np.linalg.norm(Q - c, axis=1)) + 1e-12
    assert not any("tau" in w for w in res.shape_warnings)


def test_bound_to_ring_clips_onto_the_ball_of_the_neighbours() -> None:
    """A path 0-1-2 with point 1 far off: clipped onto the ball about the centroid of 0 and 2
    whose radius is their distance to it; a point inside stays."""
    X = np.array([[0.0, 0.0], [1.0, 5.0], [2.0, 0.0]])
    L = sp.csr_matrix(np.array([[1, -1, 0], [-0.5, 1, -0.5], [0, -1, 1]], float))
    out = bound_to_ring(X, L, np.array([1]))
    assert out[1] == pytest.approx([1.0, 1.0])
    assert np.array_equal(out[[0, 2]], X[[0, 2]])
    inside = X.copy()
    inside[1] = [1.0, 0.5]
    assert np.array_equal(bound_to_ring(inside, L, np.array([1])), inside)
