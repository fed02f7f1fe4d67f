"""Guard rails: measurements against closed forms; warnings on a melted bunny, silence on a
sensible smoothing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from service.core import Geometry, SmoothingParams, smooth
from service.core.checks.guards import guard_warnings, shape_checks
from tests.core.core_fixtures import grid_mesh, noisy_icosphere, polyline_edges

DATA = Path(os.environ.get("GEOSMOOTH_SHARED_DATA", Path(__file__).parents[4] / "shared" / "data"))


def test_checks_against_closed_forms() -> None:
    P, F = noisy_icosphere(3, 0.0)
    g = Geometry(P, faces=F)
    c = shape_checks(g, 0.9 * P)  # shrink by 10 %: volume x 0.729, area x 0.81
    assert c.flipped_faces == 0 and np.isclose(c.volume_change, 0.729 - 1)
    assert np.isclose(c.area_change, 0.81 - 1)
    Q, G = grid_mesh(6, 5)
    Y = Q.copy()
    Y[:, 0] *= -1  # a planar grid mirrored in its plane: every face turns over
    assert shape_checks(Geometry(Q, faces=G), Y).flipped_faces == len(G)
    far = P.copy()
    far[0] += 100.0  # one point far away, the rest still
    assert shape_checks(g, far).moved_far == 1
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    circle = Geometry(np.column_stack([np.cos(t), np.sin(t)]), edges=polyline_edges(100, True))
    cc = shape_checks(circle, 0.5 * circle.points)
    assert np.isclose(cc.volume_change, -0.75) and np.isclose(cc.area_change, -0.5)


def test_warnings_name_the_parameter() -> None:
    P, F = noisy_icosphere(3, 0.0)
    c = shape_checks(Geometry(P, faces=F), 0.5 * P)
    for target, word in (("tau", "lower tau"), ("rms", "lower rms"), ("lam", "increase lam"),
                         ("auto", "give a smaller tau or rms")):
        ws = guard_warnings(c, target)
        assert ws and all(word in w for w in ws)


@pytest.mark.skipif(not (DATA / "bunny.ply").is_file(), reason="shared data not available")
def test_melted_bunny_warns_and_sensible_tau_is_silent() -> None:
    from service.io import read_geometry

    g = read_geometry(DATA / "bunny.ply").geometry
    melted = smooth(g, SmoothingParams(tau=0.5))  # the README's former HTTP example
    assert any("tau" in w and "flattened" in w for w in melted.warnings), melted.warnings
    assert melted.checks["area_change"] < -0.3 and melted.checks["flipped_faces"] > 0
    sensible = smooth(g, SmoothingParams(tau=2e-4))
    assert not [w for w in sensible.warnings if "tau" in w], sensible.warnings
    auto = smooth(g, SmoothingParams())
    assert auto.checks["flipped_faces"] <= melted.checks["flipped_faces"]
    assert not [w for w in auto.warnings if "destroyed" in w or "flattened" in w]
