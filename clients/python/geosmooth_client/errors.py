"""Typed errors of the client, built from the service's RFC 9457 problem details.

Every HTTP error the service answers is ``application/problem+json`` (``type``, ``title``,
``status``, ``detail``, ``code``, ``field``, ``errors``, plus extension members such as
``valid_range``). :func:`error_from_response` turns it into the :class:`ApiError` subclass whose
class attribute ``status`` matches (a new status class is one subclass here, no table), keeping
every member. Failures that are not HTTP answers have their own classes: the server cannot be
reached (:class:`ConnectionFailed`), a job ended failed or cancelled (:class:`JobFailed`,
:class:`JobCancelled`), :meth:`~geosmooth_client.Client.wait` ran out of time
(:class:`WaitTimeout`), and a Ctrl-C / task cancellation interrupted a call that owned a job
(:class:`JobInterrupted`).
"""

from __future__ import annotations

import email.utils
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import httpx

from geosmooth_client.models import Job

__all__ = [
    "ApiError",
    "BadRequest",
    "Conflict",
    "ConnectionFailed",
    "FieldError",
    "Forbidden",
    "GeosmoothClientError",
    "InsufficientStorage",
    "InvalidInput",
    "JobCancelled",
    "JobFailed",
    "JobInterrupted",
    "NotFound",
    "PayloadTooLarge",
    "RateLimited",
    "ServerError",
    "ServiceUnavailable",
    "Unauthorized",
    "UnsupportedMediaType",
    "WaitTimeout",
    "error_from_response",
    "raise_for_status",
]


class GeosmoothClientError(Exception):
    """Base class of every error this package raises."""


@dataclass(frozen=True)
class FieldError:
    """One invalid input of a validation problem (``errors`` member)."""

    field: str
    message: str
    type: str | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FieldError:
        return cls(str(data.get("field", "")), str(data.get("message", "")), data.get("type"))


class ApiError(GeosmoothClientError):
    """The service answered with an error status (problem details in the attributes).

    Attributes
    ----------
    status : int
        HTTP status code.
    type : str
        The problem type URI (``urn:geosmooth:problem:<code>`` or ``about:blank``).
    instance : str or None
        The request path.
    title, detail : str
        The problem's summary and the explanation of this occurrence.
    code : str or None
        Machine readable problem code (``"tau-out-of-range"``, ``"job-not-found"``, ...).
    field : str or None
        Dotted path of the input at fault (``"params.tau"``, ``"file"``).
    errors : list of FieldError
        Every invalid input, for validation problems.
    problem : dict
        The whole problem object, extension members included (e.g. ``valid_range``).
    retry_after : float or None
        Seconds from the ``Retry-After`` header, when the service sent one.
    """

    #: The HTTP status this class stands for (``0``: any status without a class of its own).
    status: int = 0

    def __init__(
        self,
        status: int,
        problem: Mapping[str, Any],
        *,
        retry_after: float | None = None,
    ) -> None:
        self.status = status
        self.problem = dict(problem)
        self.type = str(problem.get("type") or "about:blank")
        self.instance = _str_or_none(problem.get("instance"))
        self.title = str(problem.get("title") or f"HTTP {status}")
        self.detail = str(problem.get("detail") or self.title)
        self.code = _str_or_none(problem.get("code"))
        self.field = _str_or_none(problem.get("field"))
        raw_errors = problem.get("errors") or []
        self.errors = [FieldError.from_dict(e) for e in raw_errors if isinstance(e, Mapping)]
        self.retry_after = retry_after
        super().__init__(self.message)

    @property
    def message(self) -> str:
        """One line: ``title: detail (field ...)``."""
        text = self.title if self.detail in (self.title, "") else f"{self.title}: {self.detail}"
        if self.field and self.field not in text:
            text += f" (field {self.field})"
        return " ".join(text.split())


class BadRequest(ApiError):
    """400: a malformed file or body (``field`` is ``file`` or ``body``)."""

    status = 400


class Unauthorized(ApiError):
    """401: no API key, or a wrong one."""

    status = 401


class Forbidden(ApiError):
    """403: refused (e.g. a cross-origin request without a key)."""

    status = 403


class NotFound(ApiError):
    """404: no such job (or it belongs to another key), or no such route."""

    status = 404


class Conflict(ApiError):
    """409: e.g. the result of a job that has not succeeded (``retry_after`` while it runs)."""

    status = 409


class PayloadTooLarge(ApiError):
    """413: the body, the points or another bound of the service is exceeded."""

    status = 413


class UnsupportedMediaType(ApiError):
    """415: a format or content type the service does not read."""

    status = 415


class InvalidInput(ApiError):
    """422: invalid parameters or geometry (``field``, ``errors``; ``valid_range`` for tau)."""

    status = 422


class RateLimited(ApiError):
    """429: too many requests or jobs for this key; retry after ``retry_after`` seconds."""

    status = 429


class ServerError(ApiError):
    """5xx without a class of its own: the service failed."""

    status = 500


class ServiceUnavailable(ServerError):
    """503: the queue or the store is unavailable (``retry_after`` when known)."""

    status = 503


class InsufficientStorage(ServerError):
    """507: the service's disk is full."""

    status = 507


class ConnectionFailed(GeosmoothClientError):
    """The service cannot be reached (refused, reset, timed out, DNS, ...)."""

    def __init__(self, url: str, reason: str) -> None:
        self.url = url
        self.reason = reason
        super().__init__(f"cannot reach {url}: {reason}")


class JobFailed(GeosmoothClientError):
    """The job ended ``failed``; ``job.error`` holds the problem details."""

    def __init__(self, job: Job) -> None:
        self.job = job
        problem = job.error
        self.code = problem.code if problem else None
        self.field = problem.field if problem else None
        self.detail = problem.detail if problem else "no details"
        title = problem.title if problem else "Job failed"
        super().__init__(f"job {job.id} failed: {title}: {self.detail}")


class JobCancelled(GeosmoothClientError):
    """The job ended ``cancelled`` (by :meth:`~geosmooth_client.Client.cancel` or someone else)."""

    def __init__(self, job: Job) -> None:
        self.job = job
        super().__init__(f"job {job.id} was cancelled")


def raise_for_status(job: Job) -> Job:
    """Raise :class:`JobFailed` / :class:`JobCancelled` for those statuses; else ``job``."""
    if job.status == "failed":
        raise JobFailed(job)
    if job.status == "cancelled":
        raise JobCancelled(job)
    return job


class WaitTimeout(GeosmoothClientError, TimeoutError):
    """:meth:`~geosmooth_client.Client.wait` gave up; ``job`` is the last state seen.

    The job may still run.
    """

    def __init__(self, job_id: str, seconds: float, job: Job | None = None) -> None:
        self.job_id = job_id
        self.job = job
        super().__init__(f"job {job_id} did not finish within {seconds:g} s")


class JobInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a call that owned a job; the job was cancelled where it existed.

    A subclass of :class:`KeyboardInterrupt`, so code that catches Ctrl-C keeps working.

    Attributes
    ----------
    job_id : str or None
        The job (``None``: interrupted during the upload, before the service answered).
    status : str
        The job's status afterwards (``"cancelled"``, or the final status it had already
        reached), ``"not-created"`` (the upload was stopped before its end, so the service made
        no job) or ``"unknown"`` (the service did not answer in time).
    """

    def __init__(self, job_id: str | None, status: str) -> None:
        self.job_id = job_id
        self.status = status
        if job_id is None:
            text = (
                "interrupted during the upload; no job was created"
                if status == "not-created"
                else "interrupted after the upload; the service did not say whether it made a job"
            )
        elif status == "cancelled":
            text = f"interrupted; job {job_id} cancelled"
        elif status == "unknown":
            text = f"interrupted; job {job_id} may still run on the server"
        else:
            text = f"interrupted; job {job_id} had already {status}"
        self.message = text
        super().__init__(text)

    @property
    def stopped(self) -> bool:
        """Whether it is known that no job of this call runs on the service any more."""
        return self.status != "unknown"


def _str_or_none(value: Any) -> str | None:
    return None if value is None else str(value)


def _classes(base: type[ApiError]) -> list[type[ApiError]]:
    out = []
    for sub in base.__subclasses__():
        out.append(sub)
        out.extend(_classes(sub))
    return out


def error_class(status: int) -> type[ApiError]:
    """The :class:`ApiError` subclass whose ``status`` is ``status`` (else by class: 5xx, any)."""
    for cls in _classes(ApiError):
        if cls.status == status:
            return cls
    return ServerError if status >= 500 else ApiError


def retry_after_seconds(value: str | None, *, now: float | None = None) -> float | None:
    """``Retry-After`` as seconds (delta-seconds or an HTTP date); ``None`` if absent/invalid."""
    if not value:
        return None
    value = value.strip()
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value).timestamp()
    except (TypeError, ValueError):
        return None
    return max(0.0, when - (time.time() if now is None else now))


def problem_of(response: httpx.Response) -> dict[str, Any]:
    """The problem object of an error response (a minimal one when the body is not JSON)."""
    try:
        body = response.json()
    except ValueError:
        body = None
    if isinstance(body, Mapping):
        return dict(body)
    text = response.text.strip() if response.content else ""
    return {"title": response.reason_phrase or f"HTTP {response.status_code}", "detail": text}


def error_from_response(response: httpx.Response) -> ApiError:
    """The typed error of a non-2xx response (call after reading the body)."""
    status = response.status_code
    retry = retry_after_seconds(response.headers.get("Retry-After"))
    return error_class(status)(status, problem_of(response), retry_after=retry)
