"""``POST /v1/smooth`` on the inputs of issue 20: a noise-free mesh answers 200 with its points
unchanged and "no noise found"; ``strict`` turns a shape warning into a 422 problem of its own
type, with the warnings and checks."""

from __future__ import annotations

import httpx
import numpy as np

from tests.api.api_helpers import json_geometry, noisy_sphere


def test_noise_free_mesh_answers_200_unchanged(client: httpx.Client) -> None:
    x, y = np.meshgrid(np.arange(15.0), np.arange(15.0))
    grid = np.column_stack([x.ravel(), y.ravel(), np.zeros(225)])
    idx = np.arange(225).reshape(15, 15)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    r = client.post("/v1/smooth", json={"geometry": json_geometry(grid, tris), "params": {}})
    assert r.status_code == 200, r.text
    out = r.json()
    assert np.array_equal(np.asarray(out["geometry"]["points"], dtype=float), grid)
    rep = out["report"]
    assert rep["noise_found"] is False and rep["sigma_estimate"] == 0.0
    assert "no noise found" in rep["tau_how"] and rep["warnings"]


def test_strict_shape_loss_is_a_problem_of_its_own(client: httpx.Client) -> None:
    pts, faces = noisy_sphere(2, seed=5)
    body = {"geometry": json_geometry(pts, faces), "params": {"rms": 0.5, "strict": True}}
    r = client.post("/v1/smooth", json=body)
    assert r.status_code == 422, r.text
    problem = r.json()
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "shape-lost" in (problem.get("type", "") + str(problem.get("code", ""))), problem
    body["params"]["strict"] = False
    ok = client.post("/v1/smooth", json=body)
    assert ok.status_code == 200 and ok.json()["report"]["shape_warnings"]
