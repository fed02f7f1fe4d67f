"""The halo's decay rate: closed form, and against the measured influence of one point."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import shortest_path

from service.core import Geometry, SmoothingParams, build_operator, smooth
from service.core.tiles.halo import decay_rate, halo_hops, operator_norm_bound, spectral_norm
from tests.core.tiles.terrain import terrain_cloud, terrain_mesh


def test_decay_rate_closed_form_and_limits() -> None:
    # alpha = Re arccosh(-1 + 2 i x) exactly; ~ sqrt(2 x) for small x
    for x in (1e-6, 1e-3, 0.1, 1.0):
        z = complex(-1.0, 2 * x)
        expect = abs(np.arccosh(z).real)
        assert decay_rate(x * x, 1.0) == pytest.approx(expect, rel=1e-9)
    assert decay_rate(1e-12, 1.0) == pytest.approx(math.sqrt(2e-6), rel=1e-3)
    # quarter power of lambda, inverse square root of the norm, weights scale lambda
    assert decay_rate(16e-8, 1.0) / decay_rate(1e-8, 1.0) == pytest.approx(2.0, rel=1e-3)
    assert decay_rate(1e-8, 4.0) / decay_rate(1e-8, 1.0) == pytest.approx(0.5, rel=1e-3)
    assert decay_rate(1e-8, 1.0, 0.5) == pytest.approx(decay_rate(0.25e-8, 1.0), rel=1e-12)


def test_halo_hops_meets_eps() -> None:
    for alpha in (0.05, 0.3, 1.0):
        for order in (1, 2, 3):
            h = halo_hops(alpha, order, 1e-3)
            assert h ** (order - 1) * math.exp(-alpha * h) <= 1e-3
            g = h - 1
            assert g ** (order - 1) * math.exp(-alpha * g) > 1e-3
    assert halo_hops(0.5, 1, 1e-3, extra=7) == halo_hops(0.5, 1, 1e-3) + 7


def test_spectral_norm_against_dense() -> None:
    P = terrain_cloud(1500, side=30.0)
    op = build_operator(Geometry(P), SmoothingParams())
    true = float(np.linalg.svd(op.L.toarray(), compute_uv=False)[0])
    assert true <= spectral_norm(op.L) <= 1.03 * true
    assert spectral_norm(op.L) <= operator_norm_bound(op.L)


def _measured_rate(geometry: Geometry, params: SmoothingParams, lam: float) -> float:
    """Fit of ln max_{d(i, j) = h} |dX_j| against the hop distance h, for a unit change of
    one central point."""
    P = geometry.points
    given = params.model_copy(update={"lam": lam, "tau": None})
    base = smooth(geometry, given).points
    i0 = int(np.argmin(np.sum((P[:, :2] - P[:, :2].mean(axis=0)) ** 2, axis=1)))
    P2 = P.copy()
    P2[i0, -1] += 0.1
    moved = smooth(Geometry(P2, faces=geometry.faces), given).points
    d = np.linalg.norm(moved - base, axis=1)
    op = build_operator(geometry, params)
    hops = shortest_path(op.neighborhoods.adjacency, unweighted=True, indices=[i0])[0]
    top = int(min(np.nanmax(hops[np.isfinite(hops)]), 30))
    h = np.arange(3, top + 1)
    peak = np.array([d[hops == k].max() for k in h])
    ok = peak > 1e-12 * d.max()
    return float(-np.polyfit(h[ok], np.log(peak[ok]), 1)[0])


@pytest.mark.parametrize("kind", ["cloud", "mesh"])
@pytest.mark.parametrize("lam", [1e-3, 1e-1])
def test_predicted_rate_bounds_the_measured_decay(kind: str, lam: float) -> None:
    if kind == "cloud":
        geometry = Geometry(terrain_cloud(6000, side=40.0))
    else:
        P, F = terrain_mesh(80, side=40.0)
        geometry = Geometry(P, faces=F)
    params = SmoothingParams(displacement="free", order=1)
    op = build_operator(geometry, params)
    predicted = decay_rate(lam * op.frame.scale ** (2 * op.frame.power), spectral_norm(op.L))
    measured = _measured_rate(geometry, params, lam)
    # the rate is a lower bound (safe halo) and not a loose one
    assert predicted <= measured <= 3.0 * predicted
