"""Neighbourhoods along the mesh (issue 40): thin plates, folds and walls keep their sides apart,
and the noise is read per side."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from benchmarks.quality import harmshapes as hs
from benchmarks.quality.cad import _rotation
from service.core import Geometry
from service.core.noise.estimate import noise_of
from service.core.noise.pointfits import mesh_neighbours
from tests.core.core_fixtures import noisy_icosphere


def _side(shape: hs.Shape) -> np.ndarray:
    """Which face of the plate (sign of the offset along the plate's normal)."""
    nrm = _rotation(hs.ANGLES)[:, 2]
    return np.sign(shape.points @ nrm)


def test_plate_neighbourhoods_stay_on_their_face() -> None:
    shape = hs.plate(0.25)
    P, F = shape.points, shape.faces
    assert F is not None
    side = _side(shape)
    nrm = _rotation(hs.ANGLES)[:, 2]
    inner = np.abs(P @ nrm) > 0.1  # the two large faces
    flat = P @ _rotation(hs.ANGLES)[:, :2]  # in-plane coordinates
    away = inner & (np.abs(flat).max(axis=1) < 2.0 - 4 * shape.h)  # 4 edges from the rim
    at = np.flatnonzero(away)
    kept, nbr = mesh_neighbours(P, F, 24, at)
    assert np.array_equal(kept, at) and np.array_equal(nbr[:, 0], at)
    assert np.all(side[nbr] == side[at][:, None])
    _, knn = cKDTree(P).query(P[at], 24)  # the ball takes the other face's points
    assert np.mean(np.any(side[knn] != side[at][:, None], axis=1)) > 0.5


@pytest.mark.parametrize("build", [lambda: hs.plate(0.25), lambda: hs.fold(2.2),
                                   lambda: hs.cup(2.0)])
@pytest.mark.parametrize("level", [0.02, 0.25])
def test_noise_of_thin_parts_reads_the_noise(build, level: float) -> None:
    shape = build()
    rng = np.random.default_rng(4)
    sigma = level * shape.h
    X = shape.points + sigma * rng.normal(size=(shape.n, 1)) * shape.frame[:, :, 0]
    est = noise_of(Geometry(X, faces=shape.faces))
    assert est is not None and est.noise_found
    assert abs(est.sigma / sigma - 1.0) < 0.15


def test_unwelded_copy_reads_as_the_welded_mesh() -> None:
    P, F = noisy_icosphere(4, 0.01, seed=2)
    soup = P[F.ravel()]
    welded = noise_of(Geometry(P, faces=F))
    split = noise_of(Geometry(soup, faces=np.arange(soup.shape[0]).reshape(-1, 3)))
    assert welded is not None and split is not None
    assert split.sigma == pytest.approx(welded.sigma, rel=1e-12)
    assert welded.neighbours is not None and split.neighbours is None


def test_high_valence_fan_and_small_components() -> None:
    n = 200
    t = 2 * np.pi * np.arange(n) / n
    P = np.vstack([[0.0, 0.0, 0.0], np.column_stack([np.cos(t), np.sin(t), np.zeros(n)])])
    F = np.column_stack([np.zeros(n, int), 1 + np.arange(n), 1 + (np.arange(n) + 1) % n])
    kept, nbr = mesh_neighbours(P, F, 24, np.array([0, 1, 50]))
    assert np.array_equal(kept, [0, 1, 50])
    assert np.all(nbr[:, 0] == kept) and len({*nbr[1]}) == 24
    # the rim vertex's nearest along the mesh are the rim's, not the far side of the disc
    assert np.all(np.linalg.norm(P[nbr[1]] - P[1], axis=1) < 0.8)
    tri = np.array([[0, 1, 2]])
    kept2, _ = mesh_neighbours(np.eye(3), tri, 24, np.arange(3))
    assert kept2.size == 0  # a component smaller than the neighbourhood: left out
