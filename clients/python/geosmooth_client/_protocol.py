"""What the sync and the async client share: requests, retries and job watching, without I/O.

:class:`~geosmooth_client.Client` and :class:`~geosmooth_client.AsyncClient` only send what
this module builds and feed it what they receive, so the two stay alike by construction:

* :class:`~geosmooth_client._upload.Upload` builds ``POST /v1/jobs`` (see that module).
* :class:`RetryPolicy` says whether and when to send a request again.
* :class:`Watch` follows a job from events or from polled states, calls the progress callback
  on each change and tells when the job is finished.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import httpx

from geosmooth_client.errors import ConnectionFailed, WaitTimeout, error_from_response
from geosmooth_client.models import Job, JobProgress
from geosmooth_client.sse import ServerSentEvent, SSEDecoder

__all__ = [
    "ClientBase",
    "ProgressCallback",
    "RetryPolicy",
    "Watch",
    "check",
    "job_path",
    "transport_error",
]

#: Called with the job each time its status or progress changes.
ProgressCallback = Callable[[Job], None]

H = TypeVar("H", httpx.Client, httpx.AsyncClient)
USER_AGENT = "geosmooth-client/0.1.0"
JOBS = "/v1/jobs"
EVENTS_READ_TIMEOUT = 45.0  # the service pings every 15 s


def job_path(job_id: str, tail: str = "") -> str:
    """``/v1/jobs/{id}`` (+ ``/result``, ``/report``, ``/events``, ``/cancel``)."""
    if not job_id or "/" in job_id:
        raise ValueError(f"not a job id: {job_id!r}")
    return f"{JOBS}/{job_id}{tail}"


def check(response: httpx.Response) -> httpx.Response:
    """``response`` if a success, else its typed :class:`~geosmooth_client.errors.ApiError`.

    The body is already read.
    """
    if response.is_success:
        return response
    raise error_from_response(response)


def transport_error(url: str, exc: httpx.TransportError) -> ConnectionFailed:
    """A connection failure as :class:`ConnectionFailed` (one line, without internals)."""
    reason = " ".join(str(exc).split()) or type(exc).__name__
    return ConnectionFailed(url, reason)


# --------------------------------------------------------------------------- clients


class ClientBase(Generic[H]):
    """What :class:`~geosmooth_client.Client` and :class:`~geosmooth_client.AsyncClient` hold alike.

    Parameters: see :class:`~geosmooth_client.Client`.

    A subclass opens its ``httpx`` client (sync or async) in :meth:`_connect`.
    """

    def __init__(
        self,
        url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        retry: RetryPolicy | None = None,
        reconnect_seconds: float = 30.0,
        cancel_grace: float = 30.0,
        transport: Any = None,
    ) -> None:
        self.url = url.rstrip("/")
        self.retry = retry or RetryPolicy()
        self.reconnect_seconds = reconnect_seconds
        self.cancel_grace = cancel_grace
        self.headers = {"User-Agent": USER_AGENT}
        if api_key:
            self.headers["Authorization"] = f"Bearer {api_key}"
        self._events: bool | None = None  # None: not tried yet; False: the service has none
        self._http: H = self._connect(timeout, transport)

    def _connect(self, timeout: float, transport: Any) -> H:
        raise NotImplementedError

    @property
    def uses_events(self) -> bool | None:
        """Whether the service streams job events (``None`` until a wait found out)."""
        return self._events

    def _has_events(self) -> bool:
        return self._events is not False

    def _events_request(self, watch: Watch, connect: float | None) -> dict[str, Any]:
        """Keyword arguments of one ``GET /v1/jobs/{id}/events`` (resuming after the last id)."""
        headers = {"Accept": "text/event-stream"}
        if watch.last_event_id is not None:
            headers["Last-Event-ID"] = watch.last_event_id
        left = watch.remaining()
        read = EVENTS_READ_TIMEOUT if left is None else min(EVENTS_READ_TIMEOUT, left + 0.1)
        return {
            "method": "GET",
            "url": job_path(watch.job_id, "/events"),
            "headers": headers,
            "timeout": httpx.Timeout(connect, read=read),
        }


# --------------------------------------------------------------------------- retries


@dataclass(frozen=True)
class RetryPolicy:
    """When to send a request again: connection failures and 429/502/503/504 answers.

    Parameters
    ----------
    attempts : int
        Tries in all (1: never retry).
    backoff : float
        First delay in seconds; doubled on each retry (``Retry-After`` wins when sent).
    max_delay : float
        No single wait is longer.
    """

    attempts: int = 3
    backoff: float = 0.5
    max_delay: float = 30.0
    statuses: frozenset[int] = frozenset({429, 502, 503, 504})

    def delay(self, attempt: int, response: httpx.Response | None) -> float | None:
        """Seconds to wait before attempt ``attempt + 1``; ``None``: do not retry.

        ``response`` is ``None`` after a connection failure.
        """
        if attempt + 1 >= self.attempts:
            return None
        if response is not None and response.status_code not in self.statuses:
            return None
        wait: float = self.backoff * 2.0**attempt
        if response is not None:
            from geosmooth_client.errors import retry_after_seconds

            after = retry_after_seconds(response.headers.get("Retry-After"))
            wait = wait if after is None else after
        return min(wait, self.max_delay)


# --------------------------------------------------------------------------- watching


class Watch:
    """The state of one :meth:`~geosmooth_client.Client.wait`: the job last seen, the deadlines.

    Parameters
    ----------
    job_id : str
        The job followed.
    progress : callable, optional
        Called with the job on every change of status or progress.
    timeout : float, optional
        Seconds before :class:`WaitTimeout`.
    reconnect : float
        Seconds the service may stay unreachable (a restart) before giving up.
    job : Job, optional
        The state already known (e.g. the submit answer).
    """

    def __init__(
        self,
        job_id: str,
        progress: ProgressCallback | None,
        timeout: float | None,
        reconnect: float,
        job: Job | None = None,
    ) -> None:
        self.job_id = job_id
        self.progress = progress
        self.timeout = timeout
        self.deadline = None if timeout is None else time.monotonic() + timeout
        self.reconnect = reconnect
        self.job = job
        self.last_event_id: str | None = None
        self._decoder = SSEDecoder()
        self._down_since: float | None = None
        self._shown: tuple[Any, ...] | None = None if job is None else _key(job)

    def remaining(self) -> float | None:
        """Seconds left (``None``: no timeout); raises :class:`WaitTimeout` at the deadline."""
        if self.deadline is None:
            return None
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise WaitTimeout(self.job_id, float(self.timeout or 0.0), self.job)
        return left

    def sleep_time(self, wanted: float) -> float:
        left = self.remaining()
        return wanted if left is None else max(0.0, min(wanted, left))

    def on_job(self, job: Job) -> Job | None:
        """A state seen (polled or from an event); returns it once it is final."""
        self._down_since = None
        self.job = job
        key = _key(job)
        if key != self._shown:
            self._shown = key
            if self.progress is not None:
                self.progress(job)
        return job if job.finished else None

    def new_stream(self) -> None:
        """A new connection to the events stream begins."""
        self._decoder = SSEDecoder()

    def on_line(self, line: str) -> Job | None:
        """A line of the events stream; returns the job once a final ``status`` arrives."""
        event = self._decoder.feed(line)
        self.last_event_id = self._decoder.last_event_id or self.last_event_id
        return None if event is None else self.on_event(event)

    def on_event(self, event: ServerSentEvent) -> Job | None:
        """An event of the stream; returns the job once a final ``status`` arrives."""
        if event.event == "status":
            return self.on_job(Job.from_dict(event.json()))
        if event.event == "progress":
            progress = JobProgress.from_dict(event.json())
            base = self.job or Job(id=self.job_id, status="running")
            return self.on_job(base.with_progress(progress))
        return None

    def lost(self, error: ConnectionFailed) -> float:
        """The service is unreachable: seconds to wait before trying again, or raise."""
        now = time.monotonic()
        self._down_since = self._down_since or now
        if now - self._down_since > self.reconnect:
            raise error
        return self.sleep_time(min(1.0, self.reconnect))


def _key(job: Job) -> tuple[Any, ...]:
    return (job.status, job.progress)
