"""Output formats that cannot hold an input are refused with 422 naming ``format`` (issue 25.1),
before smoothing for ``POST /v1/smooth``; ``/v1/info`` takes what ``/v1/jobs`` takes and
``GET /v1/limits`` states the key's bounds (issue 25.5). Against the live test server."""

from __future__ import annotations

import json

import httpx

from tests.api.api_helpers import encode, noisy_plane_cloud, noisy_sphere, wait_done


def _problem(r: httpx.Response, status: int, field: str) -> dict[str, object]:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    body = r.json()
    assert body["field"] == field and "\n" not in body["detail"]
    return body  # type: ignore[no-any-return]


def test_sync_refuses_before_smoothing(client: httpx.Client) -> None:
    pts, faces = noisy_sphere(1, seed=3)
    r = client.post(
        "/v1/smooth",
        params={"format": "gpx"},
        files={"file": ("sphere.ply", encode("ply", pts, faces))},
        data={"params": json.dumps({"tau": 1e9})},  # out of range: smoothing would fail with 4xx
    )
    body = _problem(r, 422, "format")  # the format is refused first, nothing was smoothed
    assert body["code"] == "output-format-refused"
    assert "GPX holds lines, not faces; write ply, obj, json, stl, off, glb, dxf instead" in str(
        body["detail"]
    )


def test_job_result_in_a_format_that_cannot_hold_it(client: httpx.Client) -> None:
    pts = noisy_plane_cloud(300, seed=5)
    r = client.post(
        "/v1/jobs",
        files={"file": ("plane.xyz", encode("xyz", pts, None))},
        data={"params": json.dumps({"rms": 0.005})},
    )
    assert r.status_code == 202, r.text
    job = wait_done(client, r.json()["id"])
    assert job["status"] == "succeeded", job
    body = _problem(client.get(f"/v1/jobs/{job['id']}/result", params={"format": "stl"}), 422,
                    "format")  # fmt: skip
    assert "STL holds faces, not a point cloud" in str(body["detail"])
    ok = client.get(f"/v1/jobs/{job['id']}/result", params={"format": "pcd"})
    assert ok.status_code == 200 and ok.content.startswith(b"# .PCD")


def test_info_takes_large_clouds_with_the_bound_jobs_use(client: httpx.Client) -> None:
    limits = client.get("/v1/limits").json()
    n = int(limits["exact_analysis_points"]) + 1000
    pts = noisy_plane_cloud(n, seed=6)
    r = client.post("/v1/info", files={"file": ("big.xyz", encode("xyz", pts, None))})
    assert r.status_code == 200, r.text
    info = r.json()
    assert info["n_points"] == n and info["phi0_exact"] is False and info["n_edges"] is None
    bound = float(((pts - pts.mean(axis=0)) ** 2).sum())  # closed form, computed here
    assert abs(info["phi0"] - bound) <= 1e-9 * bound
    small = client.post("/v1/info", files={"file": ("s.xyz", encode("xyz", pts[:500], None))})
    assert small.status_code == 200 and small.json()["phi0_exact"] is True


def test_limits_are_the_keys(client: httpx.Client) -> None:
    limits = client.get("/v1/limits").json()
    config = client.get("/app/config.json").json()
    for name in ("max_points", "max_upload_bytes", "sync_max_points"):
        assert limits[name] == config[name]
    kinds = {f["name"]: f["kinds"] for f in config["formats"]}
    assert kinds["stl"] == ["mesh"] and kinds["gpx"] == ["polyline"]
