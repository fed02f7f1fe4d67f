"""``GET /v1/jobs/{id}/events``: a job's progress as server-sent events.

The server reads the job record every ``events_poll_seconds`` (default 0.2 s) through the
:class:`~service.jobs.queue.JobQueue` protocol, so the stream works the same for every queue
backend, and sends what changed:

* ``event: progress``: ``data`` = the job's ``progress`` object (stage, iteration, lambda, phi,
  tau, ...), whenever it changes while the job runs;
* ``event: status``: ``data`` = the job, exactly as ``GET /v1/jobs/{id}`` answers it, on the first
  read and on every status change. The last one carries a final status (succeeded, failed,
  cancelled), and then the stream ends.

Every event has an increasing ``id:``; a client that reconnects with ``Last-Event-ID`` gets ids
that continue from it (and the current state again). ``: ping`` comments keep idle connections
open (every ``events_ping_seconds``, default 15 s). The stream stops reading the queue as soon
as the client disconnects. One key (or client address) holds at most ``events_max_streams``
streams (default 32); one more is answered 429 with ``Retry-After`` (and a connection over the
server's connection bounds 429/503 with ``Retry-After``, :mod:`service.api.http.protocol`).

Programs can read it with any SSE client; the web page uses ``fetch()`` and a stream reader so
that it can send the ``Authorization`` header (``EventSource`` cannot).
"""

from __future__ import annotations

import json
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Header, Request
from sse_starlette import EventSourceResponse, ServerSentEvent
from starlette.concurrency import run_in_threadpool
from starlette.types import Receive, Scope, Send

from service.api.deps import JobDep, PrincipalDep, QueueDep, SettingsDep
from service.api.docs import problem_responses
from service.api.errors import ApiProblem
from service.jobs.queue import JobQueue, JobRecord

__all__ = ["job_event_stream", "router"]

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

_SEP = "\n"
_EXAMPLE = (
    'id: 1\nevent: status\ndata: {"id": "3f2a9c", "status": "running", ...}\n\n'
    'id: 2\nevent: progress\ndata: {"stage": "search", "iteration": 3, '
    '"lambda": 0.011, "phi": 0.47, "tau": 0.5, ...}\n\n'
    ": ping\n\n"
    'id: 7\nevent: status\ndata: {"id": "3f2a9c", "status": "succeeded", ...}\n\n'
)


#: One event of the stream (the schema each event follows; ``data`` is JSON text).
_EVENT_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "event": {"type": "string", "enum": ["progress", "status"]},
        "data": {"type": "string", "description": "JSON: a progress object or the job."},
        "id": {"type": "string"},
        "retry": {"type": "integer"},
    },
}


def _job_json(record: JobRecord) -> dict[str, Any]:
    """The job exactly as ``GET /v1/jobs/{id}`` renders it."""
    return record.public_dict()


def _event(kind: str, data: dict[str, Any], seq: int) -> ServerSentEvent:
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return ServerSentEvent(data=text, event=kind, id=str(seq), sep=_SEP)


async def job_event_stream(
    queue: JobQueue,
    first: JobRecord,
    *,
    poll_seconds: float,
    disconnected: Callable[[], Awaitable[bool]],
    start_id: int = 0,
) -> AsyncIterator[ServerSentEvent]:
    """The events of one job, from ``first`` (its current record) until it is finished.

    Parameters
    ----------
    queue : JobQueue
        Read with ``queue.get(id)`` every ``poll_seconds``.
    first : JobRecord
        The record already read (and authorized) by the route.
    poll_seconds : float
        Interval between two reads of the record.
    disconnected : callable
        ``await disconnected()`` is true once the client has gone: the stream stops.
    start_id : int
        The first event gets id ``start_id + 1``.
    """
    seq = start_id
    status: str | None = None
    progress: Any = None
    record: JobRecord | None = first
    while record is not None:
        job = _job_json(record)
        if job["status"] != status:  # first: a queued job has a progress (stage "queued") too
            status = job["status"]
            seq += 1
            yield _event("status", job, seq)
        if job.get("progress") is not None and job["progress"] != progress:
            progress = job["progress"]
            seq += 1
            yield _event("progress", progress, seq)
        if record.finished:
            return
        await anyio.sleep(poll_seconds)
        if await disconnected():
            return
        record = await run_in_threadpool(queue.get, record.id)
    # The job was deleted meanwhile (e.g. its TTL ran out): nothing more will happen to it.


class StreamSlots:
    """Open event streams per rate-limit bucket (key, or client address without keys)."""

    def __init__(self) -> None:
        self.open: dict[str, int] = {}

    def take(self, bucket: str, limit: int) -> None:
        """Count a new stream of ``bucket``; 429 + ``Retry-After`` when it holds ``limit``."""
        if self.open.get(bucket, 0) >= limit:
            raise ApiProblem(
                429,
                f"this key already has {limit} event streams open; close one, or poll "
                "GET /v1/jobs/{id}",
                code="too-many-streams",
                headers={"Retry-After": str(_RETRY_AFTER)},
                retry_after=_RETRY_AFTER,
                max_streams=limit,
            )
        self.open[bucket] = self.open.get(bucket, 0) + 1

    def release(self, bucket: str) -> None:
        left = self.open.get(bucket, 1) - 1
        if left > 0:
            self.open[bucket] = left
        else:
            self.open.pop(bucket, None)


_RETRY_AFTER = 5


class _CountedStream(EventSourceResponse):
    """An event stream that gives its slot back however it ends (also before its first event)."""

    def __init__(self, release: Callable[[], None], *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._release = release

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            self._release()


def _stream_slots(request: Request) -> StreamSlots:
    state = request.app.state
    if not hasattr(state, "event_streams"):
        state.event_streams = StreamSlots()
    return state.event_streams  # type: ignore[no-any-return]


def _last_id(value: str | None) -> int:
    try:
        return max(0, int(value or 0))
    except ValueError:
        return 0


@router.get(
    "/{job_id}/events",
    summary="Job progress as server-sent events",
    description=(
        "A ``text/event-stream`` of the job's progress: ``event: progress`` (data: the job's "
        "``progress`` object, whenever it changes: stage, iteration, lambda, phi, tau, ...) and "
        "``event: status`` (data: the job as ``GET /v1/jobs/{id}`` returns it, first at once "
        "and then on every status change). The last ``status`` event carries the final state "
        "(succeeded, failed or cancelled) and the stream ends after it. Events have increasing "
        "``id``s (continued after ``Last-Event-ID`` on reconnection); ``: ping`` comments are "
        "sent every 15 s (``GEOSMOOTH_EVENTS_PING_SECONDS``). The server reads the job every "
        "0.2 s (``GEOSMOOTH_EVENTS_POLL_SECONDS``), whatever the queue backend."
    ),
    response_class=EventSourceResponse,
    responses={
        200: {
            "description": "The event stream (ends after the final status).",
            "content": {"text/event-stream": {"schema": _EVENT_SCHEMA, "example": _EXAMPLE}},
        },
        **problem_responses(404, 503),
    },
)
async def job_events(
    request: Request,
    job: JobDep,
    queue: QueueDep,
    settings: SettingsDep,
    principal: PrincipalDep,
    last_event_id: Annotated[
        str | None,
        Header(description="Id of the last event received (reconnection); ids continue after it."),
    ] = None,
) -> EventSourceResponse:
    slots = _stream_slots(request)
    slots.take(principal.bucket, settings.events_max_streams)
    stream = job_event_stream(
        queue,
        job,
        poll_seconds=settings.events_poll_seconds,
        disconnected=request.is_disconnected,
        start_id=_last_id(last_event_id),
    )
    return _CountedStream(
        lambda: slots.release(principal.bucket),
        stream,
        ping=settings.events_ping_seconds,
        sep=_SEP,
        ping_message_factory=lambda: ServerSentEvent(comment="ping", sep=_SEP),
    )
