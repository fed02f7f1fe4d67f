"""The job queue contract: job states, the job record and the :class:`JobQueue` protocol.

The HTTP layer only talks to a :class:`JobQueue`; the embedded default is
:class:`service.jobs.embedded.queue.LocalQueue` (SQLite + worker processes), the distributed one
:class:`service.jobs.distributed.queue.RQQueue` (Redis + RQ workers + a shared blob store). Arrays
never
travel through a queue: only job ids and small metadata do; inputs and results live in the blob
store.
"""

from __future__ import annotations

import builtins
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from service.workflows.admission import Admission, JobSize  # the submit check NewJob carries

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.io import GeometryDocument

__all__ = [
    "FINISHED",
    "JobInput",
    "JobQueue",
    "JobRecord",
    "JobSize",
    "JobStatus",
    "NewJob",
    "QueueHealth",
    "job_location",
]

#: What ``submit`` stores: the bytes of the file, or a spooled file that is moved into the store.
JobInput = bytes | Path

_PROBLEM_TYPE = "urn:geosmooth:problem:"


class JobStatus(StrEnum):
    """Life cycle of a job: ``queued -> running -> succeeded | failed | cancelled``.

    A ``running`` job whose server or worker went away is put back to ``queued``.
    """

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def finished(self) -> bool:
        """Whether the job reached a final state (it can be deleted, its results expire)."""
        return self in FINISHED


FINISHED: frozenset[JobStatus] = frozenset(
    {JobStatus.SUCCEEDED, JobStatus.FAILED, JobStatus.CANCELLED}
)


def _iso(ts: float | None) -> str | None:
    if ts is None:
        return None
    return datetime.fromtimestamp(ts, tz=UTC).isoformat().replace("+00:00", "Z")


def job_location(job_id: str) -> str:
    """Path of the job's status resource (relative to the API root)."""
    return f"/v1/jobs/{job_id}"


@dataclass(frozen=True)
class NewJob:
    """A checked request to run a job: what the API's intake produces and ``submit`` stores.

    ``input``: the file's bytes, or a spooled file moved into the store; ``fmt`` a known format
    and ``params`` validated (the intake also checked the file, the key's bounds and ``tau``);
    ``size`` from the parsed input (``None``: the queue reads the input if it has a memory
    limit); ``admission`` the submit check's result
    (:func:`service.workflows.admission.check_submit`): the queue takes its decision instead of
    estimating again when it was made against the queue's own limits; the rest as in
    :class:`JobRecord`. ``submit`` checks only what needs the queue.
    """

    input: JobInput
    fmt: str
    params: SmoothingParams
    size: JobSize | None = None
    filename: str | None = None
    weld: bool = False
    tenant: str | None = None
    webhook_url: str | None = None
    idempotency_key: str | None = None
    admission: Admission | None = None

    @classmethod
    def check(
        cls, input: JobInput, fmt: str, params: SmoothingParams | Mapping[str, Any], **members: Any
    ) -> NewJob:
        """A :class:`NewJob` from unchecked values (callers without the API's intake); raises
        ``ValueError`` for an unknown format, ``pydantic.ValidationError`` for bad params."""
        from service.core.params import SmoothingParams
        from service.io import FORMATS

        name = str(fmt).lower()
        if name not in FORMATS:
            raise ValueError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
        if not isinstance(params, SmoothingParams):
            params = SmoothingParams.model_validate(dict(params))
        return cls(input, name, params, **members)


@dataclass(frozen=True)
class JobRecord:
    """Everything known about one job (metadata only, never arrays).

    Attributes
    ----------
    id : str
        Job id (32 lowercase hex digits).
    status : JobStatus
        Current state.
    fmt : str
        Input format (a name of ``service.io.FORMATS``).
    filename : str or None
        Name of the uploaded file, if given.
    params : dict
        The :class:`~service.core.params.SmoothingParams` as JSON (``exclude_none``).
    input_bytes : int
        Size of the stored input file.
    created_at, updated_at, started_at, finished_at, expires_at : float or None
        Unix timestamps (seconds). ``started_at`` is the start of the latest attempt;
        ``expires_at`` is when a finished job and its files are purged.
    weld : bool
        Exactly coincident vertices are merged when the input is read.
    tenant : str or None
        Owner of the job (``None``: no authentication).
    webhook_url : str or None
        Where the finished job is POSTed.
    attempts, max_attempts : int
        Runs started so far; runs allowed before an interrupted job is given up.
    progress : dict or None
        ``{stage, iteration, lambda, phi, tau, relative_error, percent, eta_seconds,
        elapsed_seconds}`` of the latest run (the final values once succeeded).
    problem : dict or None
        Why a job failed: ``{"code", "title", "detail", "field"?, ...}`` (no HTTP status).
    report : dict or None
        ``SmoothResult.report()`` of a succeeded job (read by ``get``, not by ``list``).
    run_seconds : float or None
        Wall time of the successful run (read, smooth, write) in the worker.
    pid : int or None
        Worker process of the current run (internal; not public).
    """

    id: str
    status: JobStatus
    fmt: str
    filename: str | None
    params: dict[str, Any]
    input_bytes: int
    created_at: float
    updated_at: float
    started_at: float | None = None
    finished_at: float | None = None
    expires_at: float | None = None
    weld: bool = False
    tenant: str | None = None
    webhook_url: str | None = None
    attempts: int = 0
    max_attempts: int = 3
    progress: dict[str, Any] | None = None
    problem: dict[str, Any] | None = None
    report: dict[str, Any] | None = None
    run_seconds: float | None = None
    pid: int | None = field(default=None, compare=False)

    @property
    def finished(self) -> bool:
        """Whether the job is in a final state."""
        return self.status.finished

    def _progress(self, key: str) -> Any:
        return None if self.progress is None else self.progress.get(key)

    @property
    def iteration(self) -> int | None:
        """Latest lambda iteration (``None`` before the first)."""
        return self._progress("iteration") or None

    @property
    def lam(self) -> float | None:
        """Latest lambda."""
        return self._progress("lambda")  # type: ignore[no-any-return]

    @property
    def phi(self) -> float | None:
        """``phi(lambda)`` of the latest lambda."""
        return self._progress("phi")  # type: ignore[no-any-return]

    @property
    def tau(self) -> float | None:
        """The engine's resolved target tau, once known."""
        return self._progress("tau")  # type: ignore[no-any-return]

    @property
    def relative_error(self) -> float | None:
        """``|phi - tau| / tau``, once both are known."""
        return self._progress("relative_error")  # type: ignore[no-any-return]

    def public_dict(self, *, with_report: bool = True) -> dict[str, Any]:
        """Exactly the JSON of ``GET /v1/jobs/{id}`` (ISO 8601 UTC times, relative links).

        Parameters
        ----------
        with_report : bool
            Include the diagnostics of a succeeded job (left out of list pages).
        """
        base = job_location(self.id)
        active = self.status in (JobStatus.QUEUED, JobStatus.RUNNING)
        return {
            "id": self.id,
            "status": self.status.value,
            "input_format": self.fmt,
            "format": self.fmt,  # deprecated name of input_format
            "filename": self.filename,
            "params": dict(self.params),
            "weld": self.weld,
            "webhook_url": self.webhook_url,
            "created_at": _iso(self.created_at),
            "started_at": _iso(self.started_at),
            "finished_at": _iso(self.finished_at),
            "expires_at": _iso(self.expires_at),
            "attempts": self.attempts,
            "max_attempts": self.max_attempts,
            "run_seconds": self.run_seconds,
            "progress": dict(self.progress) if active and self.progress else None,
            "report": self.report if with_report else None,
            "error": _public_problem(self.problem),
            "links": {
                "status": base,
                "result": f"{base}/result",
                "report": f"{base}/report",
            },
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form of the record (internal view: ``input_bytes``, ``updated_at``, ...)."""
        return {
            **self.public_dict(),
            "input_bytes": self.input_bytes,
            "updated_at": _iso(self.updated_at),
            "tenant": self.tenant,
            "progress": dict(self.progress) if self.progress else None,
            "problem": dict(self.problem) if self.problem else None,
        }


def _public_problem(problem: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if not problem:
        return None
    out = dict(problem)
    code = out.get("code")
    out.setdefault("type", f"{_PROBLEM_TYPE}{code}" if code else "about:blank")
    out.setdefault("title", "Job failed")
    out.setdefault("detail", out["title"])
    return out


@dataclass(frozen=True)
class QueueHealth:
    """Readiness of a queue backend (``/readyz``).

    Attributes
    ----------
    ok : bool
        The queue accepts jobs.
    checks : dict
        One entry per component, ``"ok"`` or the condition: ``storage`` (``"full"``,
        ``"read-only"``, ``"unavailable"``), ``database`` (``"corrupt"``, ``"unavailable"``),
        ``broker`` (RQ: ``"unreachable"``), ``workers`` (RQ: ``"none"``, a warning only).
    detail : str or None
        One line saying what is wrong (no paths).
    """

    ok: bool
    checks: dict[str, str]
    detail: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"ok": self.ok, "checks": dict(self.checks), "detail": self.detail}


@runtime_checkable
class JobQueue(Protocol):
    """What the HTTP layer needs from a job queue (the backend is interchangeable).

    ``tenant`` scopes every call that names a job: a job of another tenant is unknown
    (``None`` / ``False`` / not listed). ``tenant=None`` means no authentication (every job).
    """

    def start(self) -> None:
        """Start executing jobs (app startup). Interrupted jobs of a previous run are requeued."""
        ...

    def stop(self) -> None:
        """Stop executing jobs (app shutdown). No accepted job is lost."""
        ...

    def submit(self, job: NewJob) -> JobRecord:
        """Store the input durably and enqueue the job; returns the ``queued`` record.

        The spooled input file is moved into the store. Nothing the intake checked is checked
        again (see :class:`NewJob`).

        Raises
        ------
        IdempotencyConflict
            Same tenant and key as an earlier job, different request (same request: the
            earlier job is returned).
        JobTooLarge
            The estimated memory is above the per-job limit.
        StorageFull, StorageUnavailable
            The store is out of space (507), or read-only / unreachable (503).
        """
        ...

    def get(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """The job's record (with its report once succeeded), ``None`` if unknown."""
        ...

    def list(
        self,
        offset: int = 0,
        limit: int = 50,
        status: JobStatus | str | None = None,
        *,
        tenant: str | None = None,
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first (without reports), and the total count matching."""
        ...

    def cancel(self, job_id: str, *, tenant: str | None = None) -> JobRecord | None:
        """Cancel a queued or running job (its process is gone on return); ``None`` if unknown.

        A finished job is returned unchanged.
        """
        ...

    def delete(self, job_id: str, *, tenant: str | None = None) -> bool:
        """Delete a finished job's record and files; ``False`` if unknown or not finished."""
        ...

    def result(self, job_id: str) -> GeometryDocument | None:
        """The input document with the smoothed points, ``None`` unless the job succeeded."""
        ...

    def result_file(self, job_id: str, fmt: str) -> Path | None:
        """A local file holding the result in ``fmt`` (stored formats only), else ``None``."""
        ...

    def result_url(self, job_id: str, fmt: str) -> str | None:
        """A time-limited download URL of the stored result (S3 presigned), else ``None``."""
        ...

    def stats(self) -> dict[str, Any]:
        """Counts by status, queue depth, workers and run durations (for Prometheus)."""
        ...

    def health(self) -> QueueHealth:
        """Whether the queue can accept jobs now, and why not (for ``/readyz``)."""
        ...
