"""The client against scripted answers over real HTTP: events, retries, problem details, Ctrl-C.

The scripted server (``scripted_server.py``) answers what the real service answers rarely or not
yet: an events stream cut in the middle, 503 then 202, 429 with ``Retry-After``, 401, and a body
read so slowly that an upload can be interrupted half-way.
"""

from __future__ import annotations

import _thread
import asyncio
import json
import threading
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest
from geosmooth_client import (
    AsyncClient,
    Client,
    JobInterrupted,
    RateLimited,
    RetryPolicy,
    ServerError,
    Unauthorized,
)
from geosmooth_client.sse import SSEDecoder
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from tests.client.scripted_server import ScriptedServer

FAST = RetryPolicy(attempts=3, backoff=0.01)
REPORT = {"lambda": 0.5, "phi": 0.25, "tau": 0.25, "converged": True, "iterations": 2,
          "history": [{"lambda": 1.0, "phi": 0.1}, {"lambda": 0.5, "phi": 0.25}]}  # fmt: skip


def _job(status: str, **extra: Any) -> dict[str, Any]:
    return {"id": "j1", "status": status, "attempts": 0, **extra}


#: The events of job j1, in order (their ids are 1, 2, ...).
EVENTS = [
    ("progress", {"stage": "neighborhoods", "percent": 5.0, "elapsed_seconds": 0.1}),
    ("status", _job("running")),
    ("progress", {"stage": "search", "iteration": 1, "lambda": 1.0, "phi": 0.1, "tau": 0.25}),
    ("progress", {"stage": "search", "iteration": 2, "lambda": 0.5, "phi": 0.25, "tau": 0.25}),
    ("status", _job("succeeded", report=REPORT)),
]


def _problem(status: int, title: str, headers: dict[str, str] | None = None) -> Response:
    body = {"type": "about:blank", "title": title, "status": status, "detail": f"{title}!"}
    return JSONResponse(body, status, headers=headers, media_type="application/problem+json")


def _event_lines(start: int, stop: int) -> str:
    out = [": ping\n\n"]
    for number in range(start, stop):
        name, data = EVENTS[number - 1]
        out.append(f"id: {number}\nevent: {name}\ndata: {json.dumps(data)}\n\n")
    return "".join(out)


async def _events(request: Request) -> Response:
    """The first connection is cut after event 3; a reconnection resumes after Last-Event-ID."""
    last = request.headers.get("last-event-id")
    start = int(last) + 1 if last else 1
    stop = 4 if last is None else len(EVENTS) + 1

    async def body() -> AsyncIterator[str]:
        yield _event_lines(start, stop)

    return StreamingResponse(body(), media_type="text/event-stream")


async def _submit_once(request: Request) -> Response:
    await request.form()
    return JSONResponse(_job("queued"), 202)


ROUTES = [
    Route("/v1/jobs", _submit_once, methods=["POST"]),
    Route("/v1/jobs/j1/events", _events),
    Route("/v1/jobs/j1", lambda r: JSONResponse(_job("running"))),
]


def _seen(jobs: list[Any]) -> list[tuple[Any, ...]]:
    out = []
    for job in jobs:
        p = job.progress
        out.append((job.status, p and p.stage, p and p.iteration))
    return out


EXPECTED = [
    ("queued", None, None),
    ("running", "neighborhoods", None),
    ("running", None, None),
    ("running", "search", 1),
    ("running", "search", 2),
    ("succeeded", None, None),
]


def test_sse_decoder_follows_the_standard() -> None:
    decoder = SSEDecoder()
    lines = [": comment", "id: 7", "event: progress", "data: {\"a\":", "data: 1}", "", "", "x",
             "retry: 10", "data:no-space", "\r"]  # fmt: skip
    events = [e for e in map(decoder.feed, lines) if e is not None]
    assert [(e.event, e.data, e.id) for e in events] == [
        ("progress", '{"a":\n1}', "7"),
        ("message", "no-space", "7"),
    ]
    assert events[0].json() == {"a": 1} and events[1].retry == 10


def test_wait_follows_events_and_resumes_after_a_cut() -> None:
    with ScriptedServer(ROUTES) as server, Client(server.url, retry=FAST) as client:
        seen: list[Any] = []
        result = client.smooth(b"0 0 0\n", fmt="xyz", tau=0.25, progress=seen.append)
        assert _seen(seen) == EXPECTED
        assert result.report.lam == 0.5 and result.report["history"][0]["lambda"] == 1.0
        assert client.uses_events is True
        streams = [r for r in server.requests if r["path"].endswith("/events")]
        assert [r["headers"].get("last-event-id") for r in streams] == [None, "3"]
        assert "/v1/jobs/j1" not in server.paths("GET")  # no polling when events work


def test_async_wait_follows_events() -> None:
    async def run() -> list[Any]:
        async with AsyncClient(server.url, retry=FAST) as client:
            seen: list[Any] = []
            result = await client.smooth(b"0 0 0\n", fmt="xyz", tau=0.25, progress=seen.append)
            assert result.report.converged is True
            return seen

    with ScriptedServer(ROUTES) as server:
        assert _seen(asyncio.run(run())) == EXPECTED


def test_submit_retries_with_the_same_idempotency_key() -> None:
    bodies: list[bytes] = []

    async def flaky(request: Request) -> Response:
        form = await request.form()
        bodies.append(await form["file"].read())  # type: ignore[union-attr]
        if len(bodies) == 1:
            return _problem(503, "Store unavailable", {"Retry-After": "0"})
        return JSONResponse(_job("queued"), 202)

    with ScriptedServer([Route("/v1/jobs", flaky, methods=["POST"])]) as server:
        with Client(server.url, retry=FAST) as client:
            assert client.submit(b"1 2 3\n", fmt="xyz", tau=1).id == "j1"
            client.submit(b"1 2 3\n", fmt="xyz", tau=1)
        keys = [r["headers"]["idempotency-key"] for r in server.requests]
        assert len(keys) == 3 and keys[0] == keys[1] != keys[2] and len(keys[0]) >= 16
        assert bodies == [b"1 2 3\n"] * 3  # the retry sent the whole file again


def test_rate_limit_and_auth_problems_are_typed() -> None:
    routes = [
        Route("/v1/jobs", lambda r: _problem(429, "Too many", {"Retry-After": "0.05"}),
              methods=["POST"]),
        Route("/v1/jobs/x", lambda r: _problem(401, "Unauthorized")),
        Route("/v1/jobs/y", lambda r: Response("bad gateway", 502)),
    ]  # fmt: skip
    with ScriptedServer(routes) as server, Client(server.url, "sekrit", retry=FAST) as client:
        with pytest.raises(RateLimited) as limited:
            client.submit(b"1 2 3\n", fmt="xyz", tau=1)
        assert limited.value.retry_after == 0.05 and limited.value.status == 429
        assert limited.value.message == "Too many: Too many!"
        assert server.paths("POST") == ["/v1/jobs"] * 3  # every attempt, then the error
        with pytest.raises(Unauthorized) as denied:
            client.get("x")
        assert denied.value.detail == "Unauthorized!"
        assert server.requests[-1]["headers"]["authorization"] == "Bearer sekrit"
        with pytest.raises(ServerError) as failed:
            client.get("y")
        assert failed.value.status == 502 and failed.value.detail == "bad gateway"


def _slow_reader(log: list[str]) -> Route:
    async def slow(request: Request) -> Response:
        log.append("started")
        try:
            async for _ in request.stream():
                await asyncio.sleep(0.02)
        except ClientDisconnect:
            log.append("disconnected")
            return Response(status_code=400)
        log.append("complete")
        return JSONResponse(_job("queued"), 202)

    return Route("/v1/jobs", slow, methods=["POST"])


def _when(log: list[str], entry: str, timeout: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout
    while entry not in log and time.monotonic() < deadline:
        time.sleep(0.01)
    return entry in log


def test_ctrl_c_in_the_middle_of_an_upload_makes_no_job() -> None:
    log: list[str] = []
    data = b"0 0 0\n" * 4_000_000  # 24 MB, read at a few MB/s: the upload takes seconds

    def interrupt_once_uploading() -> None:
        if _when(log, "started"):
            time.sleep(0.2)
            _thread.interrupt_main()  # as Ctrl-C: SIGINT's handler runs in the main thread

    with ScriptedServer([_slow_reader(log)]) as server, Client(server.url) as client:
        threading.Thread(target=interrupt_once_uploading, daemon=True).start()
        with pytest.raises(JobInterrupted) as info:
            client.submit(data, fmt="xyz", tau=1)
        assert (info.value.job_id, info.value.status) == (None, "not-created")
        assert info.value.stopped and "no job was created" in str(info.value)
        assert _when(log, "disconnected")
    assert log == ["started", "disconnected"]


def test_cancelling_an_async_upload_makes_no_job() -> None:
    log: list[str] = []

    async def run() -> None:
        async with AsyncClient(server.url) as client:
            task = asyncio.ensure_future(client.submit(b"0 0 0\n" * 4_000_000, fmt="xyz", tau=1))
            while "started" not in log:
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.2)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            while "disconnected" not in log:
                await asyncio.sleep(0.01)

    with ScriptedServer([_slow_reader(log)]) as server:
        asyncio.run(asyncio.wait_for(run(), 30))
    assert log == ["started", "disconnected"]
