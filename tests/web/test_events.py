"""``GET /v1/jobs/{id}/events``: the event stream a program (or the page) reads.

Against a live uvicorn server with the embedded queue (real solver processes): events, ids,
final status and end of stream, reconnection ids, cancel, 404; and, on an in-process server,
keep-alive pings and that the server stops reading the queue once the client is gone.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn

from service.api.app import create_app
from service.jobs.config import LocalConfig
from service.jobs.embedded.queue import LocalQueue
from service.settings import Settings
from tests.web.web_helpers import WebServer, free_port, grid_mesh, ply_ascii

FINAL = ("succeeded", "failed", "cancelled")


def read_stream(response: httpx.Response) -> Iterator[dict[str, Any]]:
    """Parse an event stream (written here, independently of the page's parser)."""
    event: dict[str, Any] = {"data": []}
    for line in response.iter_lines():
        if line == "":
            if event["data"] or event.get("comment"):
                yield {**event, "data": "\n".join(event["data"])}
            event = {"data": []}
        elif line.startswith(":"):
            event["comment"] = line[1:].strip()
        else:
            name, _, value = line.partition(":")
            value = value[1:] if value.startswith(" ") else value
            if name == "data":
                event["data"].append(value)
            else:
                event[name] = value


def submit_grid(client: httpx.Client, m: int, rms: float, slow: bool = False) -> dict[str, Any]:
    points, faces = grid_mesh(m)
    files = {"file": ("grid.ply", ply_ascii(points, faces))}
    params: dict[str, Any] = {"rms": rms}
    if slow:  # the report's search with SuperLU: 7 factorizations instead of 1
        params.update(search="rational", solver="superlu")
    response = client.post("/v1/jobs", files=files, data={"params": json.dumps(params)})
    assert response.status_code == 202, response.text
    return response.json()


def test_events_follow_a_job_to_its_final_status(web_server: WebServer) -> None:
    with web_server.client() as client:
        job = submit_grid(client, 150, 0.004)
        with client.stream("GET", f"/v1/jobs/{job['id']}/events") as response:
            assert response.status_code == 200
            assert response.headers["content-type"].startswith("text/event-stream")
            events = [e for e in read_stream(response) if "event" in e]  # stream ends by itself
        final = client.get(f"/v1/jobs/{job['id']}").json()
    ids = [int(e["id"]) for e in events]
    assert ids == list(range(1, len(ids) + 1))
    assert events[0]["event"] == "status"
    assert json.loads(events[0]["data"])["status"] in ("queued", "running")
    assert events[-1]["event"] == "status"
    last = json.loads(events[-1]["data"])
    assert last == final and last["status"] == "succeeded"
    statuses = [json.loads(e["data"])["status"] for e in events if e["event"] == "status"]
    assert len(statuses) == len(set(statuses))  # one event per status change
    report = final["report"]
    tau = 150 * 150 * 0.004**2
    progress = [json.loads(e["data"]) for e in events if e["event"] == "progress"]
    assert progress, events  # the search takes ~1 s; the worker writes progress every 0.2 s
    iterations = [p["iteration"] for p in progress]
    assert iterations == sorted(iterations) and iterations[-1] <= report["iterations"]
    history = {(h["lambda"], h["phi"]) for h in report["history"]}
    early = ("queued", "reading", "neighborhoods", "laplacian")  # before the engine resolves tau
    assert any(p["stage"] not in early for p in progress)
    for p in progress:
        if p["stage"] not in early:
            assert p["tau"] == pytest.approx(tau, rel=1e-12)
        if p["iteration"]:  # each lambda reported live is one the search tried
            assert (p["lambda"], p["phi"]) in history


def test_events_of_a_finished_job_and_reconnection_ids(web_server: WebServer) -> None:
    with web_server.client() as client:
        job = submit_grid(client, 20, 0.004)
        with client.stream("GET", f"/v1/jobs/{job['id']}/events") as response:
            first = [e for e in read_stream(response) if "event" in e]
        assert json.loads(first[-1]["data"])["status"] in FINAL
        headers = {"Last-Event-ID": "41"}
        with client.stream("GET", f"/v1/jobs/{job['id']}/events", headers=headers) as response:
            again = [e for e in read_stream(response) if "event" in e]
    assert [e["event"] for e in again] == ["status"]  # finished: the final status, then the end
    assert again[0]["id"] == "42"
    assert json.loads(again[0]["data"])["status"] == json.loads(first[-1]["data"])["status"]


def test_events_end_with_cancelled(web_server: WebServer) -> None:
    with web_server.client() as client:
        job = submit_grid(client, 120, 0.004)
        seen: list[dict[str, Any]] = []
        cancelled = False
        with client.stream("GET", f"/v1/jobs/{job['id']}/events") as response:
            for event in read_stream(response):
                seen.append(event)
                data = json.loads(event["data"]) if "event" in event else {}
                running = event.get("event") == "progress" or data.get("status") == "running"
                if running and not cancelled:
                    assert client.post(f"/v1/jobs/{job['id']}/cancel").status_code == 200
                    cancelled = True
    assert cancelled
    last = json.loads(seen[-1]["data"])
    assert seen[-1]["event"] == "status" and last["status"] == "cancelled"


def test_events_of_an_unknown_job_is_a_problem(web_server: WebServer) -> None:
    with web_server.client() as client:
        response = client.get("/v1/jobs/0123456789abcdef0123456789abcdef/events")
    assert response.status_code == 404
    assert response.headers["content-type"] == "application/problem+json"
    assert response.json()["field"] == "job_id"


class CountingQueue:
    """The real LocalQueue, counting the reads of job records (what the event stream does)."""

    def __init__(self, queue: LocalQueue) -> None:
        self._queue = queue
        self.gets = 0

    def get(self, job_id: str, **kwargs: Any) -> Any:
        self.gets += 1
        return self._queue.get(job_id, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._queue, name)


def test_pings_and_stop_on_disconnect(tmp_path: Path) -> None:
    # parse_timeout: in the full parallel suite (2 workers, load ~4) a 40K upload's parse and
    # checks ran past 45 CPU s (and past a 60 s client timeout) three times this session while
    # taking 1.6 s in one process; the cause is open (closing note); this test is about the
    # events stream, so it uploads 22.5K points with the ingest's own 600 s budget
    settings = Settings(
        data_dir=tmp_path / "data", workers=1, events_poll_seconds=0.05, events_ping_seconds=0.1,
        parse_timeout=600.0,
    )
    queue = CountingQueue(LocalQueue(LocalConfig(settings.data_dir, workers=1)))
    app = create_app(settings, queue=queue)  # type: ignore[arg-type]
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=300) as client:
            deadline = time.monotonic() + 30
            while not server.started and time.monotonic() < deadline:
                time.sleep(0.02)
            job = submit_grid(client, 150, 0.004, slow=True)  # 22.5K points: runs for seconds
            comments = 0
            with client.stream("GET", f"/v1/jobs/{job['id']}/events") as response:
                start = time.monotonic()
                for event in read_stream(response):
                    comments += event.get("comment") == "ping"
                    if comments >= 2 or time.monotonic() - start > 20:
                        break
            assert comments >= 2  # ": ping" every 0.1 s while nothing changes
            time.sleep(0.3)  # the server notices the disconnection within a poll (0.05 s)
            reads = queue.gets
            time.sleep(0.6)  # a live stream would read the record ~12 times meanwhile
            still_running = client.get(f"/v1/jobs/{job['id']}").json()["status"] not in FINAL
            assert queue.gets - reads <= 1, "the stream kept reading the queue after disconnect"
            assert still_running, "the job finished too early to tell"
            client.delete(f"/v1/jobs/{job['id']}")
    finally:
        server.should_exit = True
        thread.join(30)
