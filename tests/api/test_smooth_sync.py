"""``POST /v1/smooth``: the synchronous answer, as JSON or as a file with the report header."""

from __future__ import annotations

import json

import httpx
import pytest

from service.api.results import REPORT_HEADER
from tests.api.api_helpers import (
    encode,
    json_geometry,
    noisy_plane_cloud,
    noisy_sphere,
    parse_points,
    phi,
)


def test_json_body_answers_geometry_and_report(client: httpx.Client) -> None:
    pts, faces = noisy_sphere(2, seed=7)
    body = {"geometry": json_geometry(pts, faces), "params": {"tau": 0.05}}
    r = client.post("/v1/smooth", json=body)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/json"
    out = r.json()
    assert set(out) == {"geometry", "report"}
    after = parse_points(json.dumps(out["geometry"]).encode(), "json")
    assert out["geometry"]["faces"] == faces.tolist()
    dev = phi(pts, after)
    assert abs(dev - 0.05) / 0.05 <= 1e-3
    assert out["report"]["phi"] == pytest.approx(dev, rel=1e-9)
    assert out["report"]["converged"] is True


@pytest.mark.parametrize("fmt", ["ply", "obj", "xyz"])
def test_file_upload_answers_file_with_report_header(client: httpx.Client, fmt: str) -> None:
    if fmt == "xyz":
        pts, faces, tau = noisy_plane_cloud(500, seed=8), None, 0.01
    else:
        (pts, faces), tau = noisy_sphere(2, seed=8), 0.05
    r = client.post(
        "/v1/smooth",
        files={"file": (f"in.{fmt}", encode(fmt, pts, faces))},
        data={"params": json.dumps({"tau": tau})},
    )
    assert r.status_code == 200, r.text
    assert f'filename="in.smoothed.{fmt}"' in r.headers["content-disposition"]
    report = json.loads(r.headers[REPORT_HEADER])
    dev = phi(pts, parse_points(r.content, fmt))
    assert abs(dev - tau) / tau <= 1e-3
    assert report["phi"] == pytest.approx(dev, rel=1e-9)
    assert report["n_points"] == len(pts)


def test_output_format_query(client: httpx.Client) -> None:
    pts, faces = noisy_sphere(2, seed=9)
    r = client.post(
        "/v1/smooth",
        params={"format": "json"},
        files={"file": ("in.ply", encode("ply", pts, faces))},
        data={"params": json.dumps({"lam": 0.01})},
    )
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["report"]["tau"] is None
    assert out["report"]["lambda"] == pytest.approx(0.01, rel=1e-12)  # the internal frame rescales
    assert len(out["geometry"]["points"]) == len(pts)
    r = client.post(
        "/v1/smooth",
        params={"format": "obj"},
        json={"geometry": json_geometry(pts, faces), "params": {"lam": 0.01}},
    )
    assert r.status_code == 200 and r.headers["content-type"].startswith("model/obj")
    assert parse_points(r.content, "obj").shape == pts.shape
