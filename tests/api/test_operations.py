"""Listing, deleting, health, readiness and metrics on the live server."""

from __future__ import annotations

import json
import re
import time

import httpx

from tests.api.api_helpers import LiveServer, json_geometry, noisy_sphere, wait_done

PTS, FACES = noisy_sphere(1)


def _submit(client: httpx.Client, tau: float = 0.05) -> str:
    r = client.post(
        "/v1/jobs", json={"geometry": json_geometry(PTS, FACES), "params": {"tau": tau}}
    )
    assert r.status_code == 202, r.text
    return r.json()["id"]


def test_list_paging_and_status_filter(client: httpx.Client) -> None:
    ids = [_submit(client) for _ in range(5)]
    cancelled = _submit(client)
    assert client.post(f"/v1/jobs/{cancelled}/cancel").status_code == 200  # or it finished
    for job_id in ids:
        wait_done(client, job_id)

    everything = client.get("/v1/jobs", params={"limit": 500}).json()
    total = everything["total"]
    assert total >= 6 and len(everything["items"]) == total
    listed = [item["id"] for item in everything["items"]]
    assert listed.index(ids[-1]) < listed.index(ids[0])  # newest first
    assert all(item["report"] is None for item in everything["items"])

    page = client.get("/v1/jobs", params={"offset": 1, "limit": 2}).json()
    assert [i["id"] for i in page["items"]] == listed[1:3]
    assert page["total"] == total and page["offset"] == 1 and page["limit"] == 2
    assert page["links"]["prev"] == "/v1/jobs?offset=0&limit=2"
    assert page["links"]["next"] == "/v1/jobs?offset=3&limit=2"

    by_page = client.get("/v1/jobs", params={"page": 2, "size": 2}).json()
    assert [i["id"] for i in by_page["items"]] == listed[2:4]
    assert by_page["offset"] == 2

    done = client.get("/v1/jobs", params={"status": "succeeded", "limit": 500}).json()
    assert set(ids) <= {i["id"] for i in done["items"]}
    assert all(i["status"] == "succeeded" for i in done["items"])
    assert done["total"] == len(done["items"])


def test_delete_finished_job_removes_it(client: httpx.Client) -> None:
    job_id = _submit(client)
    assert wait_done(client, job_id)["status"] == "succeeded"
    r = client.delete(f"/v1/jobs/{job_id}")
    assert r.status_code == 204 and r.content == b""
    assert client.get(f"/v1/jobs/{job_id}").status_code == 404
    assert client.get(f"/v1/jobs/{job_id}/result").status_code == 404
    assert client.delete(f"/v1/jobs/{job_id}").status_code == 404


def test_health_and_readiness(client: httpx.Client) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    assert ready.status_code == 200
    body = ready.json()
    assert body["status"] == "ready" and body["queue"] is True
    assert set(body["checks"].values()) == {"ok"} and "spool" in body["checks"]


def _sample(text: str, name: str, labels: str = "") -> float:
    match = re.search(rf"^{re.escape(name + labels)} (\S+)$", text, re.MULTILINE)
    assert match, f"{name}{labels} not in metrics"
    return float(match.group(1))


def test_metrics_agree_with_the_job_list(client: httpx.Client, server: LiveServer) -> None:
    wait_done(client, _submit(client))
    r = client.post(
        "/v1/smooth", json={"geometry": json_geometry(PTS, FACES), "params": {"tau": 0.05}}
    )
    assert r.status_code == 200
    metrics = client.get("/metrics")
    assert metrics.status_code == 200
    assert metrics.headers["content-type"].startswith("text/plain")
    text = metrics.text
    listed = client.get("/v1/jobs", params={"status": "succeeded"}).json()["total"]
    assert _sample(text, "geosmooth_jobs", '{status="succeeded"}') == listed
    for status in ("queued", "running", "failed", "cancelled"):
        _sample(text, "geosmooth_jobs", f'{{status="{status}"}}')
    assert _sample(text, "geosmooth_queue_depth") >= 0
    assert _sample(text, "geosmooth_workers", '{state="total"}') == server.workers
    assert _sample(text, "geosmooth_job_solve_seconds_count") >= 1
    assert _sample(text, "geosmooth_job_solve_seconds_bucket", '{le="+Inf"}') >= 1
    assert _sample(text, "geosmooth_sync_solve_seconds_count") >= 1
    assert _sample(text, "geosmooth_jobs_submitted_total") >= 1
    assert json.loads(client.get("/openapi.json").text)["info"]["title"] == "geosmooth"


def test_job_events_are_logged_with_job_id(client: httpx.Client, server: LiveServer) -> None:
    """submitted (API), started/progress/succeeded (watcher) and cancelled, as JSON lines."""
    done = _submit(client)
    wait_done(client, done)
    pts = noisy_sphere(4)[0]  # 2562 points, a tight tolerance: runs long enough to be seen
    body = {
        "geometry": json_geometry(pts, noisy_sphere(4)[1]),
        "params": {"tau": 0.5, "tolerance": 1e-9, "max_iterations": 200},
    }
    cancelled = client.post("/v1/jobs", json=body).json()["id"]
    client.post(f"/v1/jobs/{cancelled}/cancel")
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        events = {(r.get("event"), r.get("job_id")) for r in server.records()}
        if {
            ("job.submitted", done),
            ("job.succeeded", done),
            ("job.cancelled", cancelled),
        } <= events:
            break
        time.sleep(0.2)
    assert ("job.submitted", done) in events and ("job.succeeded", done) in events, events
    assert ("job.cancelled", cancelled) in events
    lines = [r for r in server.records() if r.get("job_id") == done]
    assert all(r["level"] and r["timestamp"] for r in lines)
