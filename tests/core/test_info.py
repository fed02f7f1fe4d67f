"""describe(): sizes, phi(0) against closed forms, valid ranges, JSON-ready output."""

from __future__ import annotations

import json

import numpy as np

from service.core import Geometry, SmoothingParams, smooth
from service.core.info import describe
from tests.core.core_fixtures import noisy_icosphere, polyline_edges


def test_mesh_phi0_is_centroid_deviation() -> None:
    P, F = noisy_icosphere(2, 0.01)
    d = describe(Geometry(P, faces=F), SmoothingParams(displacement="free"))
    assert d["kind"] == "mesh" and d["n_points"] == len(P) and d["n_faces"] == len(F)
    assert d["n_edges"] == 3 * len(F) // 2  # closed triangle mesh: E = 3F/2
    phi0 = float(np.sum((P - P.mean(axis=0)) ** 2))
    assert np.isclose(d["phi0"], phi0, rtol=1e-12)
    assert d["tau_range"] == [0.0, d["phi0"]]
    assert np.isclose(d["rms_range"][1], np.sqrt(phi0 / len(P)))
    assert np.allclose(d["bbox"]["min"], P.min(axis=0))
    json.dumps(d)  # JSON-ready: no numpy scalars


def test_two_parts_phi0_per_component_and_spacing() -> None:
    t = np.linspace(0, 1, 11)
    a = np.column_stack([t, np.zeros_like(t)])
    b = a + np.array([0.0, 5.0])
    P = np.vstack([a, b])
    E = np.vstack([polyline_edges(11), polyline_edges(11, offset=11)])
    d = describe(Geometry(P, edges=E), SmoothingParams(ends="pulled"))  # fixed ends: phi0 = 0
    phi0 = 2 * float(np.sum((a - a.mean(axis=0)) ** 2))  # each part onto its own centroid
    assert np.isclose(d["phi0"], phi0)
    assert np.isclose(d["mean_spacing"], 0.1)
    assert d["n_edges"] == 20


def test_phi0_with_fixed_points_is_the_limit_of_smooth() -> None:
    t = np.linspace(0, np.pi, 30)
    P = np.column_stack([t, np.sin(t)])
    g = Geometry(P, edges=polyline_edges(30))
    params = {"fix_boundary": True, "order": 1}
    d = describe(g, SmoothingParams(tau=1.0, **params))
    # lambda -> 0 with both ends fixed: the chord between the ends
    X = smooth(g, SmoothingParams(lam=1e-9, **params)).points
    assert np.isclose(d["phi0"], float(np.sum((X - P) ** 2)), rtol=1e-4)
    assert d["rms_range"][1] == np.sqrt(d["phi0"] / 28)


def test_cloud_spacing_is_nearest_neighbour_distance() -> None:
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2) * 0.5
    P = np.column_stack([g, np.zeros(len(g))])
    d = describe(Geometry(P), SmoothingParams(tau=1.0, neighborhood="knn", k=4))
    assert d["kind"] == "cloud" and np.isclose(d["mean_spacing"], 0.5)


def test_noise_estimate_and_suggestion() -> None:
    P, F = noisy_icosphere(4, 0.01, seed=3)
    g = Geometry(P, faces=F)
    d = describe(g)
    assert abs(d["sigma_estimate"] / 0.01 - 1) < 0.15
    assert 0 < d["suggested_tau"] < d["phi0"]
    assert np.isclose(d["suggested_rms"] ** 2 * len(P), d["suggested_tau"])
    res = smooth(g, SmoothingParams())  # the automatic tau is the suggestion
    assert np.isclose(res.tau, d["suggested_tau"]) and res.sigma_estimate == d["sigma_estimate"]


def test_phi0_follows_the_displacement_mode() -> None:
    """The valid range describe() states is the one smooth() enforces, in every mode."""
    import pytest

    from service.core.errors import TauOutOfRange

    P, F = noisy_icosphere(2, 0.02, seed=4)
    g = Geometry(P, faces=F)
    for mode in ("free", "normal"):
        phi0 = describe(g, SmoothingParams(displacement=mode))["phi0"]
        smooth(g, SmoothingParams(tau=0.99 * phi0, displacement=mode))
        with pytest.raises(TauOutOfRange):
            smooth(g, SmoothingParams(tau=1.01 * phi0, displacement=mode))
