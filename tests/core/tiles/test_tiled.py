"""Stitched against untiled: clouds, meshes and curves, fixed points and weights, one tau."""

from __future__ import annotations

import numpy as np
import pytest

from service.core import Geometry, ParameterError, SmoothingParams, smooth
from service.core.progress import ProgressEvent
from service.core.tiles import smooth_tiled
from service.core.tiles.lam import LambdaDecision, ProbeTile
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
    # the halos are real halos, not the whole input (the probe's provisional one may be)
    assert all(t.points + t.halo < g.n for t in tiled.tiles if t.index != tiled.probe)
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


def _stray_cloud() -> Geometry:
    """A noisy terrain cloud with 0.3 % of its points thrown 1-3 m up or down."""
    P = terrain_cloud(30000, side=60.0, sigma=0.1)
    rng = np.random.default_rng(5)
    at = rng.choice(P.shape[0], 90, replace=False)
    P[at, 2] += rng.uniform(1, 3, at.size) * rng.choice([-1.0, 1.0], at.size)
    return Geometry(P)


def test_tiles_share_one_noise_estimate_and_flag_the_strays() -> None:
    g = _stray_cloud()
    untiled = smooth(g, SmoothingParams())
    tiled = smooth_tiled(g, SmoothingParams(), g.n // 4)
    res = tiled.result
    assert len(tiled.tiles) == 4
    assert all(t.points + t.halo < g.n for t in tiled.tiles if t.index != tiled.probe)
    # one noise estimate: the untiled run's, bit for bit (not pooled from tiles)
    assert res.sigma_estimate == untiled.sigma_estimate
    # the data weights ran in the tiles (core + halo): the outliers are the untiled ones
    assert untiled.outliers.size >= 90
    common = np.intersect1d(untiled.outliers, res.outliers).size
    assert common >= 0.95 * untiled.outliers.size
    assert res.outliers.size <= 1.05 * untiled.outliers.size
    # flagged outliers stay at their input positions (outliers="auto": flagged and kept)
    assert np.array_equal(res.points[res.outliers], g.points[res.outliers])
    # one note with the stitched count (a tile counts its halo's outliers too)
    notes = [w.message for w in res.warnings if " as outliers (" in w.message]
    assert len(notes) == 1 and notes[0].startswith(f"{res.outliers.size} points")
    # the rule's target over the whole input, and how far the stitched phi is from it
    assert res.tau == pytest.approx(untiled.tau, rel=0.05)
    assert res.relative_error == pytest.approx(abs(res.phi - res.tau) / res.tau)


@pytest.mark.xfail(strict=True, reason="issue 43, not met: outlier decisions flip with a tile's "
                   "own residual calibration, and the probe tile's lambda is not the whole "
                   "input's (service/core/tiles/README.md); 4.3 % here, 1.5-4.5 % at 1M")
@pytest.mark.parametrize("make", [CASES["cloud"], _stray_cloud], ids=["noisy", "stray"])
def test_tiled_default_equals_untiled_default(make: object) -> None:
    g = make()  # type: ignore[operator]
    untiled = smooth(g, SmoothingParams())
    tiled = smooth_tiled(g, SmoothingParams(), g.n // 4)
    assert _relative(tiled.result.points, untiled.points, g.points) <= 1e-2


def test_tiles_at_the_rule_lambda_are_the_untiled_default_at_that_lambda() -> None:
    """The lambda rule is a plug: given the untiled run's lambda, every tile (probe included)
    runs the default at it, and the result is the untiled default's to the halo's truncation."""
    g = _stray_cloud()
    untiled = smooth(g, SmoothingParams())
    calls: list[float] = []

    def rule(probe: ProbeTile, params: SmoothingParams, run_tile: object) -> LambdaDecision:
        calls.append(probe.share)
        return LambdaDecision(untiled.lam, "the untiled run's")

    tiled = smooth_tiled(g, SmoothingParams(), g.n // 4, rule=rule)
    assert len(calls) == 1 and 0.25 < calls[0] <= 1  # one decision; the probe tile's weight
    assert tiled.result.lam == untiled.lam
    assert _relative(tiled.result.points, untiled.points, g.points) <= 1e-2


def test_given_tau_is_met_over_the_whole_input() -> None:
    g = CASES["cloud"]()
    tau = smooth(g, SmoothingParams()).phi
    tiled = smooth_tiled(g, SmoothingParams(tau=tau), g.n // 4).result
    phi = float(np.sum((tiled.points - g.points) ** 2))  # recomputed from the points
    assert tiled.tau == tau
    assert tiled.phi == pytest.approx(phi, rel=1e-9)
    assert abs(phi - tau) / tau <= 0.05  # the probe's share of tau, not a budget over tiles
    ref = smooth(g, SmoothingParams(tau=tau))
    assert _relative(tiled.points, ref.points, g.points) <= 2e-2


def test_no_noise_found_returns_the_input() -> None:
    P = terrain_cloud(14000, side=60.0, sigma=0.0)  # the shape's own detail, no noise
    g = Geometry(P)
    assert smooth(g, SmoothingParams()).lam == 0.0
    tiled = smooth_tiled(g, SmoothingParams(), g.n // 4)
    assert np.array_equal(tiled.result.points, P)
    assert tiled.result.sigma_estimate == 0.0


def test_progress_counts_tiles_and_time_left() -> None:
    g = CASES["cloud"]()
    events: list[ProgressEvent] = []
    smooth_tiled(g, SmoothingParams(), g.n // 4, progress=events.append)
    ticks = [e for e in events if e.tiles_total]
    done = [e.tiles_done for e in ticks]
    assert done[-3:] == [2, 3, 4] and done[0] in (0, 1)  # the probe (when kept), one per tile
    assert all(e.tiles_total == 4 for e in ticks)
    timed = [e for e in ticks if e.tiles_done]
    assert all(e.seconds_left is not None and e.seconds_left >= 0 for e in timed)
    assert ticks[-1].seconds_left == 0 and ticks[-1].fraction == 1.0
    # equal cores (k-d split of 14000 points): the fraction is the share of tiles done
    assert [e.fraction for e in timed] == pytest.approx([d / 4 for d in done if d], abs=1e-9)


@pytest.mark.parametrize(
    "update,field",
    [
        ({"preserve_volume": True}, "params.preserve_volume"),
        ({"max_deviation": 0.1}, "params.max_deviation"),
        ({"tau": "gcv"}, "params.tau"),
        ({"method": "windowed-sinc"}, "params.method"),
        ({"laplacian": "feature"}, "params.laplacian"),
    ],
)
def test_options_without_a_tiled_form_are_refused(update: dict, field: str) -> None:
    g = Geometry(terrain_cloud(2000))
    with pytest.raises(ParameterError) as err:
        smooth_tiled(g, SmoothingParams(**update), 1000)
    assert err.value.field == field
