"""Stitched against untiled: clouds, meshes and curves, fixed points and weights, one tau."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, ParameterError, SmoothingParams, smooth
from service.core.tiles import smooth_tiled
from service.core.tiles.partition import kd_split, tile_geometry
from tests.core.tiles.terrain import terrain_cloud, terrain_mesh


def _relative(stitched: np.ndarray, untiled: np.ndarray, P: np.ndarray) -> float:
    """RMS difference over the RMS displacement of the untiled solve."""
    diff = np.sqrt(np.mean(np.sum((stitched - untiled) ** 2, axis=1)))
    return float(diff / np.sqrt(np.mean(np.sum((untiled - P) ** 2, axis=1))))


def _noisy_spiral(n: int) -> Geometry:
    rng = np.random.default_rng(3)
    t = np.linspace(0, 12 * np.pi, n)
    P = np.c_[(1 + t) * np.cos(t), (1 + t) * np.sin(t)] + 0.01 * rng.standard_normal((n, 2))
    edges = np.c_[np.arange(n - 1), np.arange(1, n)]
    return Geometry(P, edges=edges)


def _mesh() -> Geometry:
    P, F = terrain_mesh(110, side=60.0)
    return Geometry(P, faces=F)


CASES = {
    "cloud": lambda: Geometry(terrain_cloud(14000, side=60.0, sigma=0.1)),  # noise found
    "mesh": _mesh,
    "curve": lambda: _noisy_spiral(12000),
}


def test_kd_split_partitions() -> None:
    P = terrain_cloud(5000)
    cores = kd_split(P, 700)
    assert len(cores) == 8
    allc = np.concatenate(cores)
    assert np.array_equal(np.sort(allc), np.arange(5000))
    assert all(c.size <= 700 for c in cores)


def test_tile_geometry_keeps_faces_inside_and_renumbers() -> None:
    g = _mesh()
    members = np.arange(0, g.n, 2)
    sub = tile_geometry(g, members)
    assert sub.faces is not None
    # every kept face maps back to a face of the input whose vertices are all members
    back = members[sub.faces]
    faces = {tuple(sorted(f)) for f in g.faces.tolist()}  # type: ignore[union-attr]
    assert all(tuple(sorted(f)) in faces for f in back.tolist())
    inside = np.isin(g.faces, members).all(axis=1)  # type: ignore[arg-type]
    assert sub.faces.shape[0] == int(inside.sum())


@pytest.mark.parametrize("kind", sorted(CASES))
def test_stitched_equals_untiled_at_the_same_lambda(kind: str) -> None:
    g = CASES[kind]()
    untiled = smooth(g, SmoothingParams())
    # the curve's default (lambda 2.5e-6) smooths over more than a quarter of the spiral, so
    # its halos would be the whole input: the tiles are compared at a 40x lighter lambda there
    params = SmoothingParams(lam=untiled.lam * (40.0 if kind == "curve" else 1.0))
    ref = smooth(g, params)
    tiled = smooth_tiled(g, params, g.n // 4)
    assert len(tiled.tiles) == 4
    # the halos are real halos, not the whole input
    assert all(t.points + t.halo < g.n for t in tiled.tiles)
    assert _relative(tiled.result.points, ref.points, g.points) <= 1e-2
    phi = float(np.sum((tiled.result.points - g.points) ** 2))
    assert tiled.result.phi == pytest.approx(phi, rel=1e-9)


def test_fixed_points_and_weights_are_respected() -> None:
    rng = np.random.default_rng(7)
    P = terrain_cloud(12000, side=50.0)
    w = rng.uniform(0.5, 2.0, P.shape[0])
    fixed = rng.choice(P.shape[0], 300, replace=False)
    g = Geometry(P, weights=w, fixed=fixed)
    params = SmoothingParams(lam=0.3)
    ref = smooth(g, params)
    tiled = smooth_tiled(g, params, 3000)
    assert np.array_equal(tiled.result.points[fixed], P[fixed])
    assert _relative(tiled.result.points, ref.points, P) <= 1e-2
    phi = float(np.sum(w**2 * np.sum((tiled.result.points - P) ** 2, axis=1)))
    assert tiled.result.phi == pytest.approx(phi, rel=1e-9)


@pytest.mark.parametrize("kind", ["cloud", "curve"])
def test_one_global_tau(kind: str) -> None:
    g = CASES[kind]()
    untiled = smooth(g, SmoothingParams())
    tau = untiled.phi
    tiled = smooth_tiled(g, SmoothingParams(tau=tau), g.n // 4)
    phi = float(np.sum((tiled.result.points - g.points) ** 2))  # recomputed from the points
    assert abs(phi - tau) / tau <= 1e-3
    assert tiled.result.converged
    ref = smooth(g, SmoothingParams(tau=tau))
    assert _relative(tiled.result.points, ref.points, g.points) <= 1e-2


def test_automatic_tau_pools_the_noise() -> None:
    g = CASES["cloud"]()
    untiled = smooth(g, SmoothingParams())
    tiled = smooth_tiled(g, SmoothingParams(), g.n // 4)
    res = tiled.result
    assert res.tau is not None and untiled.tau is not None
    assert abs(res.phi - res.tau) / res.tau <= 1e-3
    # pooled noise and budget close to the untiled automatic rule (noise 0.05 in the data)
    assert res.sigma_estimate == pytest.approx(untiled.sigma_estimate, rel=0.1)
    assert res.tau == pytest.approx(untiled.tau, rel=0.1)


@pytest.mark.parametrize(
    "update,field",
    [
        ({"preserve_volume": True}, "params.preserve_volume"),
        ({"max_deviation": 0.1}, "params.max_deviation"),
        ({"tau": "gcv"}, "params.tau"),
        ({"method": "windowed-sinc"}, "params.method"),
        ({"laplacian": "feature"}, "params.laplacian"),
        ({"robust": "tukey"}, "params.robust"),
        ({"noise_weights": "local"}, "params.noise_weights"),
    ],
)
def test_options_without_a_tiled_form_are_refused(update: dict, field: str) -> None:
    g = Geometry(terrain_cloud(2000))
    with pytest.raises(ParameterError) as err:
        smooth_tiled(g, SmoothingParams(**update), 1000)
    assert err.value.field == field
