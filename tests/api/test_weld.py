"""Welding over HTTP: a mesh stored with split vertices (featuretype.ply) smooths as one mesh."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest

from service.io import read_geometry
from tests.api.api_helpers import parse_points, wait_done
from tests.shared_data import shared_data_dir

DATA = shared_data_dir()


def _groups(points: np.ndarray) -> np.ndarray:
    """Label of each point's exact position (coincident points share a label)."""
    _, inverse = np.unique(points, axis=0, return_inverse=True)
    return inverse.ravel()


def test_weld_form_field_smooths_split_mesh_as_one(client: httpx.Client) -> None:
    path = DATA / "featuretype.ply"
    if not path.exists():
        pytest.skip("shared data not available")
    raw = path.read_bytes()
    before = read_geometry(raw, "ply", weld=False).geometry.points  # the file's 5096 vertices
    params = {"rms": 0.01, "laplacian": "feature"}
    r = client.post(
        "/v1/jobs",
        files={"file": ("featuretype.ply", raw)},
        data={"params": json.dumps(params), "weld": "true"},
    )
    assert r.status_code == 202, r.text
    job = wait_done(client, r.json()["id"])
    assert job["status"] == "succeeded", job
    report = job["report"]
    assert report["n_points"] == 1722  # welded (MANIFEST: 1722 distinct positions)
    out = client.get(f"/v1/jobs/{job['id']}/result")
    assert out.status_code == 200
    after = parse_points(out.content, "ply")
    assert after.shape == before.shape == (5096, 3)  # the file's vertices are kept
    # copies of one position stay together, and the deviation over welded points is phi
    groups = _groups(before)
    for g in np.unique(groups)[:200]:
        members = np.flatnonzero(groups == g)
        assert np.all(after[members] == after[members[0]])
    first = np.unique(groups, return_index=True)[1]
    dev = float(np.sum((after[first] - before[first]) ** 2))
    # the download keeps the input's float32 coordinates (issue 11: float32 in, float32 out),
    # so phi from the file agrees with the report to float32 rounding (about 1e-7 of 1.9)
    assert dev == pytest.approx(report["phi"], rel=1e-4)
    assert abs(report["phi"] - report["tau"]) / report["tau"] <= 1e-3
    # converting the welded result to another format keeps the file's vertices too
    as_json = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "json"})
    assert len(as_json.json()["points"]) == 5096


def test_weld_in_json_body_and_bad_values(client: httpx.Client) -> None:
    # two triangles sharing an edge, stored with duplicated edge vertices
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0.1], [1, 0, 0], [0, 1, 0.1], [1, 1, 0], [2, 2, 0.3]]
    geometry = {"points": pts, "faces": [[0, 1, 2], [3, 5, 4]], "edges": [[5, 6]]}
    body = {"geometry": geometry, "params": {"lam": 0.5}, "weld": True}
    r = client.post("/v1/smooth", params={"format": "json"}, json=body)
    assert r.status_code == 200, r.text
    out = np.array(r.json()["geometry"]["points"])
    assert out.shape == (7, 3)
    assert np.array_equal(out[1], out[3]) and np.array_equal(out[2], out[4])
    assert r.json()["report"]["n_points"] == 5
    bad = client.post("/v1/jobs", json={**body, "weld": "yes"})
    assert bad.status_code == 422
    assert bad.headers["content-type"].startswith("application/problem+json")
    assert bad.json()["field"] == "weld"
    bad = client.post(
        "/v1/jobs",
        files={"file": ("a.json", json.dumps(geometry).encode())},
        data={"params": '{"lam": 1}', "weld": "maybe"},
    )
    assert bad.status_code == 422 and bad.json()["field"] == "weld"


def test_stl_is_welded_unless_the_request_says_no(client: httpx.Client) -> None:
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=1)
    mesh.vertices = mesh.vertices + 0.02 * np.random.default_rng(5).standard_normal(
        mesh.vertices.shape
    )
    stl = mesh.export(file_type="stl")  # 80 triangles, 240 corners, 42 positions
    counts: dict[str | None, int] = {}
    for weld in (None, "false"):
        data = {"params": '{"lam": 1}'} | ({} if weld is None else {"weld": weld})
        r = client.post(
            "/v1/smooth", params={"format": "json"}, files={"file": ("s.stl", stl)}, data=data
        )
        assert r.status_code == 200, r.text
        counts[weld] = r.json()["report"]["n_points"]
    assert counts == {None: 42, "false": 240}
