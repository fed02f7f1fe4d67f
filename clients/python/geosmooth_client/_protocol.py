"""What the sync and the async client share: requests, retries and job watching, without I/O.

:class:`Client` and :class:`AsyncClient` only send what this module builds and feed it what
they receive, so the two stay alike by construction:

* :class:`Upload` turns a path, bytes, a geometry mapping or a points array plus parameters into
  the multipart form of ``POST /v1/jobs``; its file part is a :class:`TrackedFile`, which knows
  whether the whole file went out and stops the upload when asked (Ctrl-C before the end of the
  body leaves no job on the server: the service never sees a complete request).
* :class:`RetryPolicy` says whether and when to send a request again.
* :class:`Watch` follows a job from events or from polled states, calls the progress callback
  on each change and tells when the job is finished.
"""

from __future__ import annotations

import io
import json
import os
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import httpx

from geosmooth_client.errors import ConnectionFailed, WaitTimeout, error_from_response
from geosmooth_client.models import Job, JobProgress
from geosmooth_client.sse import ServerSentEvent

__all__ = [
    "ProgressCallback",
    "RetryPolicy",
    "TrackedFile",
    "Upload",
    "UploadAborted",
    "Watch",
    "check",
    "job_path",
    "transport_error",
]

#: Called with the job each time its status or progress changes.
ProgressCallback = Callable[[Job], None]

USER_AGENT = "geosmooth-client/0.1.0"
JOBS = "/v1/jobs"


def job_path(job_id: str, tail: str = "") -> str:
    """``/v1/jobs/{id}`` (+ ``/result``, ``/report``, ``/events``)."""
    if not job_id or "/" in job_id:
        raise ValueError(f"not a job id: {job_id!r}")
    return f"{JOBS}/{job_id}{tail}"


def check(response: httpx.Response) -> httpx.Response:
    """``response`` if it is a success, else its typed :class:`ApiError` (body already read)."""
    if response.is_success:
        return response
    raise error_from_response(response)


def transport_error(url: str, exc: httpx.TransportError) -> ConnectionFailed:
    """A connection failure as :class:`ConnectionFailed` (one line, without internals)."""
    reason = " ".join(str(exc).split()) or type(exc).__name__
    return ConnectionFailed(url, reason)


# --------------------------------------------------------------------------- upload


class UploadAborted(Exception):
    """Raised inside the upload when it is stopped before the end of the file."""


class TrackedFile(io.RawIOBase):
    """A readable file that knows whether it was read to the end, and can stop a read.

    Parameters
    ----------
    raw : binary file
        The data (an open file or a ``BytesIO``).
    """

    def __init__(self, raw: IO[bytes]) -> None:
        super().__init__()
        self._raw = raw
        self._lock = threading.Lock()
        self._stopped = False
        self.sent = False  # every byte of the file was handed to the connection

    def stop(self) -> bool:
        """Make the next read raise :class:`UploadAborted`; returns whether it was all sent.

        Atomic with :meth:`read`: when it returns ``False``, the end of the file is never
        read, so the request body is never complete and the service makes no job of it.
        """
        with self._lock:
            self._stopped = True
            return self.sent

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def fileno(self) -> int:  # lets httpx find the length (a Content-Length, not chunks)
        return self._raw.fileno()

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        return self._raw.seek(offset, whence)

    def tell(self) -> int:
        return self._raw.tell()

    def read(self, size: int = -1) -> bytes:
        with self._lock:
            if self._stopped and not self.sent:
                raise UploadAborted("upload stopped")
            chunk = self._raw.read(size)
            if not chunk:
                self.sent = True
            return chunk

    def readinto(self, buffer: Any) -> int:  # pragma: no cover - httpx calls read()
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self._raw.close()
        super().close()


def _jsonable(value: Any) -> Any:
    """numpy arrays and scalars to lists and numbers (no numpy import needed)."""
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


def params_dict(params: Any, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Smoothing parameters as a JSON object: a mapping or a pydantic model, plus keywords.

    ``None`` values are left out (the service's defaults apply).
    """
    if params is None:
        base: dict[str, Any] = {}
    elif isinstance(params, Mapping):
        base = dict(params)
    elif hasattr(params, "model_dump"):
        base = params.model_dump(mode="json", exclude_unset=True)
    else:
        raise TypeError(f"params must be a mapping or a pydantic model, not {type(params)}")
    base.update(overrides)
    return {k: _jsonable(v) for k, v in base.items() if v is not None}


@dataclass(frozen=True)
class Upload:
    """One ``POST /v1/jobs`` multipart request, re-sendable (a retry opens the data again).

    Build it with :meth:`build`; :meth:`request` gives the keyword arguments of one attempt.
    """

    opener: Callable[[], IO[bytes]]
    filename: str
    form: dict[str, str]
    idempotency_key: str = field(default_factory=lambda: uuid.uuid4().hex)

    @classmethod
    def build(
        cls,
        source: Any,
        params: Mapping[str, Any],
        *,
        fmt: str | None = None,
        filename: str | None = None,
        weld: bool = False,
        webhook_url: str | None = None,
        idempotency_key: str | None = None,
    ) -> Upload:
        """Validate the input locally and prepare the form.

        Parameters
        ----------
        source : path, bytes, mapping or array_like
            A file path; the file's bytes (give ``fmt`` or a ``filename`` with an extension
            unless the service can tell the format from the content); a geometry in the JSON
            format's schema (``{"points": ..., "faces": ...}``, numpy arrays allowed); or the
            points themselves, an ``(n, s)`` array-like (a point cloud).
        """
        form = {"params": json.dumps(dict(params), allow_nan=False)}
        if isinstance(source, str | os.PathLike):
            path = Path(source)
            if not path.is_file():
                raise FileNotFoundError(2, "No such file", str(path))
            opener: Callable[[], IO[bytes]] = lambda: path.open("rb")  # noqa: E731
            name = filename or path.name
        elif isinstance(source, bytes | bytearray | memoryview):
            data = bytes(source)
            opener = lambda: io.BytesIO(data)  # noqa: E731
            name = filename or (f"input.{fmt}" if fmt else "input")
        else:
            geometry = source if isinstance(source, Mapping) else {"points": source}
            text = json.dumps(_jsonable(geometry), allow_nan=False, separators=(",", ":"))
            data = text.encode("utf-8")
            opener = lambda: io.BytesIO(data)  # noqa: E731
            name, fmt = filename or "geometry.json", fmt or "json"
        if fmt:
            form["format"] = fmt
        if weld:
            form["weld"] = "true"
        if webhook_url:
            form["webhook_url"] = webhook_url
        key = idempotency_key or uuid.uuid4().hex
        return cls(opener=opener, filename=name, form=form, idempotency_key=key)

    def request(self) -> tuple[TrackedFile, dict[str, Any]]:
        """The file part of one attempt and the ``httpx`` keyword arguments that send it."""
        body = TrackedFile(self.opener())
        kwargs = {
            "data": self.form,
            "files": {"file": (self.filename, body, "application/octet-stream")},
            "headers": {"Idempotency-Key": self.idempotency_key},
        }
        return body, kwargs


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
    """The state of one :meth:`Client.wait`: the job as last seen and the deadlines.

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
