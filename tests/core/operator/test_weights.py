"""Neighbour weights against closed forms (report sections 4.2-4.4)."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.operator.neighborhoods import curve_neighborhoods, mesh_neighborhoods
from service.core.operator.weights import neighbor_weights
from tests.core.core_fixtures import grid_mesh, noisy_icosphere


def _row(W, i: int) -> dict[int, float]:
    lo, hi = W.indptr[i], W.indptr[i + 1]
    return dict(zip(W.indices[lo:hi].tolist(), W.data[lo:hi].tolist(), strict=True))


def test_reciprocal_weights_fig2() -> None:
    """w = b/(a+b) for p_{i+1} and a/(a+b) for p_{i-1} (report fig. 2)."""
    P = np.array([[0.0, 0.0], [1.0, 0.5], [4.0, 1.0]])
    nb = curve_neighborhoods(np.array([[0, 1], [1, 2]]), 3)
    W = neighbor_weights(P, nb, "reciprocal")
    a = np.linalg.norm(P[1] - P[0])
    b = np.linalg.norm(P[2] - P[1])
    row = _row(W, 1)
    assert row[2] == pytest.approx(a / (a + b))  # 1/b normalized: (1/b)/(1/a+1/b) = a/(a+b)
    assert row[0] == pytest.approx(b / (a + b))
    assert _row(W, 0) == {1: 1.0}


def _fan(angles: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ring = np.c_[radii * np.cos(angles), radii * np.sin(angles), np.zeros(angles.size)]
    P = np.vstack([[0.0, 0.0, 0.0], ring])
    m = angles.size
    F = np.array([[0, 1 + t, 1 + (t + 1) % m] for t in range(m)])
    return P, F


def test_mean_value_weights_closed_form() -> None:
    """Floater: w_j = (tan(a_{j-1}/2) + tan(a_j/2)) / r_j, normalized."""
    ang = np.array([0.0, 1.0, 2.2, 3.0, 4.4, 5.5])
    rad = np.array([1.0, 2.0, 0.7, 1.5, 1.1, 0.9])
    P, F = _fan(ang, rad)
    W = neighbor_weights(P, mesh_neighborhoods(F, len(P)), "mean-value")
    gaps = np.diff(np.r_[ang, ang[0] + 2 * np.pi])
    raw = (np.tan(np.roll(gaps, 1) / 2) + np.tan(gaps / 2)) / rad
    row = _row(W, 0)
    np.testing.assert_allclose([row[j + 1] for j in range(6)], raw / raw.sum(), rtol=1e-12)
    # reproduction: the centre is the weighted combination of its ring
    np.testing.assert_allclose(W[0] @ P, P[0:1], atol=1e-14)


def test_cotangent_weights_closed_form() -> None:
    ang = np.array([0.0, 1.2, 2.1, 3.3, 4.5, 5.4])
    rad = np.array([1.0, 1.3, 0.8, 1.1, 1.0, 0.9])
    P, F = _fan(ang, rad)
    W = neighbor_weights(P, mesh_neighborhoods(F, len(P)), "cotangent")

    def cot_at(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:  # angle at a
        u, v = b - a, c - a
        return float(u @ v / np.linalg.norm(np.cross(u, v)))

    raw = []
    for j in range(6):
        nxt, prv = 1 + (j + 1) % 6, 1 + (j - 1) % 6
        raw.append(0.5 * (cot_at(P[nxt], P[0], P[1 + j]) + cot_at(P[prv], P[0], P[1 + j])))
    raw = np.array(raw)
    assert np.all(raw > 0)
    row = _row(W, 0)
    np.testing.assert_allclose([row[j + 1] for j in range(6)], raw / raw.sum(), rtol=1e-12)


@pytest.mark.parametrize("scheme", ["uniform", "reciprocal", "mean-value", "cotangent"])
def test_rows_stochastic_and_positive(scheme: str) -> None:
    P, F = noisy_icosphere(2, 0.05)
    W = neighbor_weights(P, mesh_neighborhoods(F, len(P)), scheme)
    assert np.all(W.data > 0)
    np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel(), 1.0, rtol=1e-12)


def test_cotangent_clamped_positive_on_obtuse_mesh() -> None:
    P, F = grid_mesh(8, 8, jitter=0.45, seed=3)
    W = neighbor_weights(P, mesh_neighborhoods(F, len(P)), "cotangent")
    assert np.all(W.data > 0) and np.all(np.isfinite(W.data))


def test_degenerate_neighbourhoods_fall_back_without_nan() -> None:
    # all three vertices coincide: no angle is defined
    P = np.array([[1.0, 1.0, 1.0]] * 3 + [[0.0, 0.0, 0.0]])
    F = np.array([[0, 1, 2]])
    for scheme in ("mean-value", "cotangent", "reciprocal"):
        W = neighbor_weights(P, mesh_neighborhoods(F, 4), scheme)
        assert np.all(np.isfinite(W.data))
        np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel()[:3], 1.0)
        assert W.indptr[4] == W.indptr[3]  # the unreferenced vertex has no neighbours
