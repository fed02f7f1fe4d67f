"""Outlier counts only beyond what the noise and the smoothing explain (issue 31 item 4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from service.core import Geometry, SmoothingParams, smooth
from service.core.finish.outliers import EXTREME_ALPHA, beyond_noise
from tests.shared_data import shared_data_dir

DATA = shared_data_dir()


def test_beyond_noise_against_the_gaussian_extreme_and_the_rest() -> None:
    rng = np.random.default_rng(2)
    n, sigma = 5000, 0.01
    P = rng.normal(size=(n, 3))
    X = P.copy()
    X[:, 2] += rng.normal(0, sigma, n)  # every point moved by Gaussian noise along one axis
    extreme = sigma * np.sqrt(chi2.isf(EXTREME_ALPHA / n, 1))
    idx = np.array([0, 1, 2, 3])
    X[0, 2] = P[0, 2] + 1.5 * extreme  # beyond both the extreme and every other move
    X[1, 2] = P[1, 2] + 0.9 * extreme  # within the Gaussian extreme
    got = beyond_noise(P, X, idx, sigma, 1)
    assert got.tolist() == [0]
    X[4, 2] = P[4, 2] + 2.0 * extreme  # a point not in idx that moved further: detail, not spike
    assert beyond_noise(P, X, idx, sigma, 1).size == 0
    assert beyond_noise(P, X, idx, None, 1).tolist() == idx.tolist()  # no noise level: all


def _horse(spikes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from service.io import read_geometry

    g = read_geometry(DATA / "horse.ply").geometry
    P, F = g.points, g.faces
    assert F is not None
    h = float(np.linalg.norm(P[F[:, 0]] - P[F[:, 1]], axis=1).mean())
    rng = np.random.default_rng(1)
    Q = P + rng.normal(0, 0.1 * h, P.shape)
    idx = rng.choice(len(P), spikes, replace=False)
    Q[idx] += 10 * h * rng.normal(size=(spikes, 3))
    return Q, F, idx


@pytest.mark.skipif(not (DATA / "horse.ply").is_file(), reason="shared data not available")
@pytest.mark.xfail(strict=True, reason=(
    "issue 37 (known, open): the risk rule smooths the horse lighter than the knee did (RMS "
    "move 0.8 sigma), so one of the 21 fine-detail points the residual test flags (3763) "
    "moves 12.9 sigma, beyond every other point's 11.3 sigma, and is counted"))
def test_a_scanned_mesh_with_gaussian_noise_has_no_outlier_count() -> None:
    """The horse at 0.1 edge of Gaussian noise: the residual test flags 21 points of fine detail
    (moves up to 13.7 sigma, others' up to 16.4 under the former rule): no count."""
    Q, F, _ = _horse(0)
    r = smooth(Geometry(Q, faces=F), SmoothingParams())
    assert r.outliers is not None and r.outliers.size == 0
    assert not [w for w in r.warnings if w.code == "outliers"], r.warnings


@pytest.mark.skipif(not (DATA / "horse.ply").is_file(), reason="shared data not available")
def test_a_scanned_mesh_with_spikes_counts_them() -> None:
    """With 20 spikes of 10 edges: the spikes are counted, nothing else."""
    Q, F, idx = _horse(20)
    r = smooth(Geometry(Q, faces=F), SmoothingParams())
    assert r.outliers is not None and 15 <= r.outliers.size <= 20
    assert np.isin(r.outliers, idx).all()
    assert [w.numbers["count"] for w in r.warnings if w.code == "outliers"] == [r.outliers.size]
