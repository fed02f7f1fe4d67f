"""Issue 21's benchmark families: the fixed split, exact ground truth, the stated noise levels."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from benchmarks.quality.cases import FULL, make_case
from benchmarks.quality.families import CASES, CASES31, KIND, SPLIT, half_cases, half_of
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

    assert set(SPLIT) == {family(k) for k in [*CASES, *FULL, *CASES31]}  # no family without a case


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


def test_peer_defaults_are_the_libraries_own() -> None:
    import trimesh
    from trimesh.smoothing import filter_humphrey, filter_laplacian, filter_taubin

    from benchmarks.quality.defaults import DEFAULT_PEERS, SUFFIX
    from benchmarks.quality.peers import QUALITY_PEERS

    assert [p.name for p in DEFAULT_PEERS] == [p.name + SUFFIX for p in QUALITY_PEERS]
    case = make_case("hemisphere/iso-0.25")
    F = case.shape.faces
    assert F is not None
    twins = {p.name: p for p in DEFAULT_PEERS}
    for name, f in (("trimesh filter_laplacian", filter_laplacian),
                    ("trimesh filter_taubin", filter_taubin),
                    ("trimesh filter_humphrey", filter_humphrey)):
        twin = twins[name + SUFFIX]
        (setting,) = twin.grid(case.shape, False)
        ours = twin.run(case.points, case.shape, setting)
        theirs = f(trimesh.Trimesh(case.points.copy(), F, process=False)).vertices
        assert np.allclose(ours, theirs)


def test_half_table_counts_the_targets() -> None:
    from benchmarks.quality.halftable import render, targets

    def case(key: str, auto: tuple[float, float], mode: tuple[float, float],
             peer: tuple[float, float], flips: int) -> dict[str, object]:
        return {"key": key, "half": "test", "shape": key.split("/")[0], "noise": "iso",
                "kind": "mesh", "n": 10, "sigma": 1.0, "input": {"flipped": 2},
                "auto": {"vertex": auto[0], "surface": auto[1], "flipped": flips,
                         "report": {"sigma_estimate": 1.1}},
                "modes": {"default": {"vertex": {"vertex": mode[0]},
                                      "surface": {"surface": mode[1]}}},
                "peers": {"p": {"swept": {"vertex": {"vertex": peer[0]},
                                          "surface": {"surface": peer[1]}},
                                "defaults": {"vertex": 0.9, "surface": 0.8, "flipped": 0}}}}

    doc = {"machine": {"date": "d", "cpu": "c", "cores": 2, "memory_gib": 1, "os": "o",
                       "python": "p", "system_blas": "b", "load_average": [1.0]},
           "peers": {"trimesh": "4"}, "half": "test", "seconds": 1.0, "load_end": [1.0],
           "modes": ["default"], "refine": 4,
           "cases": [case("a/iso-1", (0.5, 0.3), (0.4, 0.2), (0.45, 0.35), 1),
                     case("b/iso-1", (0.6, 0.5), (0.5, 0.5), (0.45, 0.35), 3),
                     case("c/iso-1", (1.2, 0.9), (0.3, 0.3), (0.4, 0.4), 0)]}
    t = targets(doc)
    assert t["auto_le_peer_s"] == (1, 3)  # 0.3 <= 0.35 only
    assert t["auto_115_peer_v"] == (1, 3)  # 0.5 <= 0.5175; 0.6 and 1.2 are not
    assert t["best_le_peer_v"] == (2, 3) and t["best_le_peer_s"] == (2, 3)
    assert t["not_worse"] == (2, 3) and t["sigma_15"] == (3, 3)
    assert t["flips_le_input"] == (2, 3)
    text = render(doc)
    assert "| a/iso-1 | mesh | 10 | 0.500 | 0.300 |" in text and "1/3 (33 %)" in text


def test_cheap_oracle_finds_the_minimum_of_a_smooth_valley() -> None:
    from benchmarks.quality.halves import cheap_oracle

    calls: list[float] = []

    def f(x: float) -> float:
        calls.append(x)
        return (x + 3.3) ** 2 + 0.1 * (x + 3.3) ** 4  # minimum at log lambda = -3.3

    x = cheap_oracle(f, 0.0, decades=2, refine=3)  # starts 1.3 decades off the window
    assert abs(x + 3.3) < 0.05 and len(calls) <= 12
