"""Smoke test of the quality benchmark's building blocks (no peers, no sweeps)."""

from __future__ import annotations

import numpy as np

from benchmarks.quality.cases import FULL, QUICK, make_case
from benchmarks.quality.scores import Scorer
from benchmarks.quality.table import render


def test_cases_have_the_stated_noise_and_ground_truth() -> None:
    assert set(QUICK) <= set(FULL) and len(FULL) == len(set(FULL))
    case = make_case("sphere-642/normal-0.25")
    E = case.points - case.shape.points
    along = np.einsum("ij,ij->i", E, case.shape.normals)
    assert np.allclose(np.linalg.norm(E, axis=1), np.abs(along))  # normal noise only
    assert abs(np.std(along) / case.sigma - 1) < 0.1
    assert np.abs(case.shape.distance(case.shape.points)).max() < 1e-12
    sc = Scorer(case)
    full = sc.full(case.points)
    assert full["vertex"] == 1.0 and full["surface"] == 1.0
    assert np.allclose(sc.quick(case.shape.points), 0.0, atol=1e-12)
    assert sc.full(case.shape.points)["flipped"] == 0


def test_table_renders_targets() -> None:
    case = {"key": "c", "n": 10, "kind": "mesh", "noise": "aniso", "sigma": 1.0,
            "input": {"flipped": 0},
            "peers": {"p": {"vertex": {"vertex": 0.5}, "surface": {"surface": 0.4}}},
            "modes": {"default": {"vertex": {"vertex": 0.4}, "surface": {"surface": 0.3}}},
            "auto": {"vertex": 0.44, "surface": 0.33, "report": {"sigma_estimate": 1.05},
                     "flipped": 0, "cost_ratio": 1.2}}
    doc = {"machine": {"date": "d", "cpu": "c", "cores": 2, "memory_gib": 1, "os": "o",
                       "python": "p", "system_blas": "b", "load_average": [1.0]},
           "peers": {"trimesh": "4"}, "quick": True, "cases": [case], "seconds": 1.0,
           "load_end": [1.0]}
    text = render(doc)
    assert "vertex error 1/1 (100 %)" in text and "| c | 10 |" in text
