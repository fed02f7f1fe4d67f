"""Issue 21's benchmark families: the fixed split, exact ground truth, the stated noise levels."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from benchmarks.quality.cases import FULL, make_case
from benchmarks.quality.families import CASES, KIND, SPLIT, half_cases, half_of
from benchmarks.quality.surfaces import HeightField, hemisphere, terrain


def test_every_case_has_a_half_and_each_half_every_kind() -> None:
    for key in [*FULL, *CASES]:
        assert half_of(key) in ("calibration", "test")
    with pytest.raises(KeyError):
        half_of("sphere-2.5K/gps-0.5")
    cal, test = half_cases("calibration"), half_cases("test")
    assert sorted(cal + test) == sorted(CASES) and abs(len(cal) - len(test)) <= 4
    for half in (cal, test):
        assert set(Counter(KIND[k.split("/")[0]] for k in half)) == {"mesh", "grid", "curve",
                                                                     "cloud"}
    def family(k: str) -> tuple[str, str]:
        shape, spec = k.split("/")
        return shape, spec.rsplit("-", 1)[0]

    assert set(SPLIT) == {family(k) for k in [*CASES, *FULL]}  # no family without a case


@pytest.mark.parametrize("key", ["terrain/view-0.5", "hemisphere/laplace-0.5",
                                 "torusknot/gps-0.5", "saddle-irr/quant-0.5",
                                 "cloud-dens-terrain/student-0.5", "sphere-irr/vary-0.15"])
def test_ground_truth_is_exact_and_noise_has_its_level(key: str) -> None:
    case = make_case(key)
    shape = case.shape
    assert np.abs(shape.distance(shape.points)).max() < 1e-5 * shape.h
    E = case.points - shape.points
    N = shape.frame[:, :, : shape.codim]
    normal_rms = np.sqrt(np.mean(np.einsum("nsc,ns->nc", N, E) ** 2))
    assert abs(normal_rms / case.sigma - 1) < 0.12
    again = make_case(key)
    assert np.array_equal(again.points, case.points)  # fixed seed


def test_height_field_distance_matches_a_dense_search() -> None:
    shape = terrain(30)
    field = shape.distance
    assert isinstance(field, HeightField)
    rng = np.random.default_rng(0)
    X = shape.points[rng.choice(shape.n, 40)] + rng.normal(scale=0.02, size=(40, 3))
    g = np.linspace(0.0, 1.0, 401)
    U, V = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    S = np.stack([U, V, field.derivatives(U, V)[0]], axis=1)
    brute = []
    for x in X:  # nearest of a coarse grid, then of a fine grid around it
        u0, v0 = S[np.argmin(np.sum((S - x) ** 2, axis=1)), :2]
        f = np.linspace(-0.004, 0.004, 161)
        u, v = (np.clip(a.ravel(), 0, 1) for a in np.meshgrid(u0 + f, v0 + f, indexing="ij"))
        Q = np.stack([u, v, field.derivatives(u, v)[0]], axis=1)
        brute.append(np.sqrt(np.min(np.sum((Q - x) ** 2, axis=1))))
    d = field(X)
    # the grids' points lie on the surface: their nearest one is an upper bound
    assert np.all(d <= np.array(brute) + 1e-9) and np.allclose(d, brute, rtol=0, atol=1e-5)


def test_hemisphere_is_open_and_its_rim_is_measured() -> None:
    shape = hemisphere(3)
    rim_z = shape.points[:, 2].min()
    x = np.array([[0.0, 0.0, 2.0], [np.sqrt(1 - rim_z**2) + 0.1, 0.0, rim_z - 0.2]])
    assert np.allclose(shape.distance(x), [1.0, np.hypot(0.1, 0.2)])
