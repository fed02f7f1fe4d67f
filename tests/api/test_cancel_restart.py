"""Cancelling a running job stops its solver process; a killed server loses no accepted job."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.api.api_helpers import (
    LiveServer,
    cpu_ticks,
    descendants,
    encode,
    noisy_plane_cloud,
    noisy_sphere,
    parse_points,
    phi,
    wait_done,
)

# About 20-30 s of solving (k = 64 neighbours on 40K points): long enough to cancel mid-run.
SLOW_PARAMS = {"tau": 1.0, "tolerance": 1e-9, "neighborhood": "knn", "k": 64}


def _slow_input() -> bytes:
    return encode("xyz", noisy_plane_cloud(40000, seed=11), None)


def _wait_running(client: httpx.Client, job_id: str, timeout: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] != "queued":
            return job
        time.sleep(0.02)
    raise AssertionError(f"job {job_id} did not start")


def _busy_descendant(pid: int, exclude: set[int]) -> int:
    """The descendant of ``pid`` burning CPU (the solver), found by sampling CPU ticks."""
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        before = {p: cpu_ticks(p) for p in descendants(pid) - exclude}
        time.sleep(0.5)
        used = {p: (cpu_ticks(p) or 0) - (t or 0) for p, t in before.items() if t is not None}
        if used and max(used.values()) >= 3:  # >= 6% of a core, while the others idle
            return max(used, key=lambda p: used[p])
    raise AssertionError("no busy worker process found")


def test_cancel_running_job_stops_its_process(client: httpx.Client, server: LiveServer) -> None:
    assert server.proc is not None
    idle = descendants(server.proc.pid)  # forkserver & co., before the job starts
    files = {"file": ("slow.xyz", _slow_input())}
    r = client.post("/v1/jobs", files=files, data={"params": json.dumps(SLOW_PARAMS)})
    assert r.status_code == 202, r.text
    job_id = r.json()["id"]
    assert _wait_running(client, job_id)["status"] == "running"
    solver = _busy_descendant(server.proc.pid, idle)

    early = client.get(f"/v1/jobs/{job_id}/result")  # not ready: 409 with Retry-After
    assert early.status_code == 409
    assert early.headers["content-type"] == "application/problem+json"
    assert early.json()["code"] == "result-not-ready" and "retry-after" in early.headers

    r = client.post(f"/v1/jobs/{job_id}/cancel")
    assert r.status_code == 200, r.text
    assert r.json()["status"] == "cancelled"
    deadline = time.monotonic() + 5
    while cpu_ticks(solver) is not None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert cpu_ticks(solver) is None, "the solver process still runs after the cancel"

    time.sleep(0.5)
    job = client.get(f"/v1/jobs/{job_id}").json()
    assert job["status"] == "cancelled" and job["report"] is None
    gone = client.get(f"/v1/jobs/{job_id}/result")
    assert gone.status_code == 409 and gone.json()["code"] == "no-result"

    r = client.delete(f"/v1/jobs/{job_id}")  # a finished (cancelled) job is deleted
    assert r.status_code == 204
    assert client.get(f"/v1/jobs/{job_id}").status_code == 404


def test_delete_running_job_stops_it_and_removes_it(
    client: httpx.Client, server: LiveServer
) -> None:
    """``DELETE`` of a running job: its solver process is gone and every route of it is 404."""
    assert server.proc is not None
    idle = descendants(server.proc.pid)
    files = {"file": ("slow.xyz", _slow_input())}
    r = client.post("/v1/jobs", files=files, data={"params": json.dumps(SLOW_PARAMS)})
    assert r.status_code == 202, r.text
    job_id = r.json()["id"]
    assert _wait_running(client, job_id)["status"] == "running"
    solver = _busy_descendant(server.proc.pid, idle)

    r = client.delete(f"/v1/jobs/{job_id}")
    assert r.status_code == 204 and r.content == b"", r.text
    assert cpu_ticks(solver) is None, "the solver process still runs after the 204"
    for method, tail in (("GET", ""), ("GET", "/result"), ("GET", "/report"),
                         ("GET", "/events"), ("POST", "/cancel"), ("DELETE", "")):  # fmt: skip
        gone = client.request(method, f"/v1/jobs/{job_id}{tail}")
        assert gone.status_code == 404, (method, tail, gone.text)
        assert gone.headers["content-type"] == "application/problem+json"
        assert gone.json()["code"] == "job-not-found"
    assert job_id not in [i["id"] for i in client.get("/v1/jobs").json()["items"]]


def test_cancel_queued_job(make_server: Callable[..., LiveServer]) -> None:
    live = make_server(workers=1)
    with live.client() as c:
        files = {"file": ("slow.xyz", _slow_input())}
        slow = c.post("/v1/jobs", files=files, data={"params": json.dumps(SLOW_PARAMS)}).json()
        pts, faces = noisy_sphere(2)
        body = {"geometry": json.loads(encode("json", pts, faces)), "params": {"tau": 0.05}}
        queued = c.post("/v1/jobs", json=body).json()
        assert c.get(f"/v1/jobs/{queued['id']}").json()["status"] == "queued"
        r = c.post(f"/v1/jobs/{queued['id']}/cancel")
        assert r.status_code == 200 and r.json()["status"] == "cancelled"
        assert c.post(f"/v1/jobs/{queued['id']}/cancel").json()["status"] == "cancelled"
        assert c.post(f"/v1/jobs/{slow['id']}/cancel").json()["status"] == "cancelled"


@pytest.mark.slow
def test_restart_after_sigkill_completes_every_job(
    make_server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    """Jobs queued and running when the server is SIGKILLed all complete after a restart."""
    data_dir = tmp_path / "store"
    first = make_server(data_dir, workers=1)
    inputs: dict[str, tuple[np.ndarray, float, str]] = {}
    with first.client() as c:
        # The first job runs ~1-2 s, so the kill lands while it runs and the others wait.
        big = noisy_plane_cloud(20000, seed=21)
        params = {"tau": 0.5, "tolerance": 1e-6}
        r = c.post(
            "/v1/jobs",
            files={"file": ("big.xyz", encode("xyz", big, None))},
            data={"params": json.dumps(params)},
        )
        inputs[r.json()["id"]] = (big, 0.5, "xyz")
        for i, fmt in enumerate(["ply", "obj", "json", "ply", "obj"]):
            pts, faces = noisy_sphere(2, seed=30 + i)
            r = c.post(
                "/v1/jobs",
                files={"file": (f"s{i}.{fmt}", encode(fmt, pts, faces))},
                data={"params": json.dumps({"tau": 0.05})},
            )
            assert r.status_code == 202
            inputs[r.json()["id"]] = (pts, 0.05, fmt)
        _wait_running(c, next(iter(inputs)))
        statuses = {j: c.get(f"/v1/jobs/{j}").json()["status"] for j in inputs}
    assert "running" in statuses.values() and "queued" in statuses.values(), statuses
    first.kill()

    second = make_server(data_dir, workers=2)
    with second.client() as c:
        for job_id, (pts, tau, fmt) in inputs.items():
            done = wait_done(c, job_id, timeout=60)
            assert done["status"] == "succeeded", done
            after = parse_points(c.get(f"/v1/jobs/{job_id}/result").content, fmt)
            tol = 1e-6 if fmt == "xyz" else 1e-3
            assert abs(phi(pts, after) - tau) / tau <= tol
        listed = c.get("/v1/jobs", params={"limit": 100}).json()
        assert listed["total"] == len(inputs)
