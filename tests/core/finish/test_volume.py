"""Volume and area preservation (report sections 8-9)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.core import Geometry, ParameterError, SmoothingParams, smooth
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def test_volume_preserved_on_closed_mesh() -> None:
    P, F = noisy_icosphere(3, 0.02)
    before = trimesh.Trimesh(P, F, process=False).volume
    plain = smooth(Geometry(P, faces=F), SmoothingParams(lam=1e-3, preset="report"))
    kept = smooth(
        Geometry(P, faces=F), SmoothingParams(lam=1e-3, preserve_volume=True, preset="report")
    )
    assert trimesh.Trimesh(plain.points, F, process=False).volume < 0.95 * before  # shrinks
    assert trimesh.Trimesh(kept.points, F, process=False).volume == pytest.approx(before, rel=1e-9)
    assert kept.volume_scale > 1.0


def test_area_preserved_on_closed_polygon() -> None:
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    P = np.c_[np.cos(t), np.sin(t)] + np.random.default_rng(0).normal(0, 0.03, (100, 2))

    def area(X: np.ndarray) -> float:
        x, y = X[:, 0], X[:, 1]
        return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    res = smooth(
        Geometry(P, edges=polyline_edges(100, closed=True)),
        SmoothingParams(rms=0.05, preserve_volume=True),
    )
    assert area(res.points) == pytest.approx(area(P), rel=1e-9)


def test_preserve_volume_needs_closed_shape() -> None:
    P = np.random.default_rng(0).normal(size=(10, 2))
    with pytest.raises(ParameterError) as info:
        smooth(Geometry(P, edges=polyline_edges(10)), SmoothingParams(lam=1, preserve_volume=True))
    assert info.value.field == "params.preserve_volume"
