"""The job queue contract: job states, the job record and the :class:`JobQueue` protocol.

The HTTP layer only talks to a :class:`JobQueue`; the embedded default is
:class:`service.jobs.local.LocalQueue` (SQLite + worker processes). Another backend (e.g. Redis/RQ)
implements the same protocol. Arrays never travel through a queue: only job ids do, inputs and
results live in the job store.
"""

from __future__ import annotations

import builtins
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    from service.core.params import SmoothingParams
    from service.io import GeometryDocument

__all__ = ["FINISHED", "JobQueue", "JobRecord", "JobStatus"]


class JobStatus(StrEnum):
    """Life cycle of a job: ``queued -> running -> succeeded | failed | cancelled``.

    A ``running`` job whose server went away is put back to ``queued`` on the next start.
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
        Input format (``"ply"``, ``"obj"``, ``"xyz"``, ``"json"``).
    filename : str or None
        Name of the uploaded file, if given.
    params : dict
        The :class:`~service.core.params.SmoothingParams` as JSON (``model_dump(mode="json")``).
    input_bytes : int
        Size of the stored input file.
    created_at, started_at, finished_at, updated_at : float or None
        Unix timestamps (seconds). ``started_at`` is the start of the latest attempt.
    expires_at : float or None
        When a finished job and its files are purged (``finished_at + result_ttl``).
    attempts : int
        Runs started so far (a run interrupted by a server stop or crash is retried).
    max_attempts : int
        Runs allowed before the job is failed as poison.
    iteration : int or None
        Latest lambda iteration reported by the running solve.
    lam, phi : float or None
        lambda and ``phi(lambda)`` of the latest iteration (the final ones once succeeded).
    tau : float or None
        Target smoothing factor when known (``tau`` or derived from ``rms``).
    relative_error : float or None
        ``|phi - tau| / tau`` when ``tau`` is known.
    problem : dict or None
        Why a job failed: ``{"code", "title", "detail", "field"?, "indices"?, ...}``, the same
        members as the API's problem details (without the HTTP status).
    report : dict or None
        ``SmoothResult.report()`` of a succeeded job (only filled by ``get``, not by ``list``).
    run_seconds : float or None
        Wall time of the successful run (read, smooth, write) in the worker process.
    pid : int or None
        Worker process of the current run (internal; not part of :meth:`to_dict`).
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
    attempts: int = 0
    max_attempts: int = 3
    iteration: int | None = None
    lam: float | None = None
    phi: float | None = None
    tau: float | None = None
    relative_error: float | None = None
    problem: dict[str, Any] | None = None
    report: dict[str, Any] | None = None
    run_seconds: float | None = None
    pid: int | None = field(default=None, compare=False)

    @property
    def finished(self) -> bool:
        """Whether the job is in a final state."""
        return self.status.finished

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (ISO 8601 UTC timestamps; ``pid`` left out)."""
        progress = None
        if self.iteration is not None:
            progress = {
                "iteration": self.iteration,
                "lambda": self.lam,
                "phi": self.phi,
                "tau": self.tau,
                "relative_error": self.relative_error,
            }
        return {
            "id": self.id,
            "status": self.status.value,
            "format": self.fmt,
            "filename": self.filename,
            "params": dict(self.params),
            "input_bytes": self.input_bytes,
            "created_at": _iso(self.created_at),
            "updated_at": _iso(self.updated_at),
            "started_at": _iso(self.started_at),
            "finished_at": _iso(self.finished_at),
            "expires_at": _iso(self.expires_at),
            "attempts": self.attempts,
            "max_attempts": self.max_attempts,
            "progress": progress,
            "problem": dict(self.problem) if self.problem else None,
            "report": self.report,
            "run_seconds": self.run_seconds,
        }


@runtime_checkable
class JobQueue(Protocol):
    """What the HTTP layer needs from a job queue (the backend is interchangeable)."""

    def start(self) -> None:
        """Start executing jobs (app startup). Interrupted jobs of a previous run are requeued."""
        ...

    def stop(self) -> None:
        """Stop executing jobs (app shutdown). No accepted job is lost."""
        ...

    def submit(
        self,
        input_bytes: bytes,
        fmt: str,
        params: SmoothingParams,
        filename: str | None = None,
        *,
        weld: bool = False,
    ) -> JobRecord:
        """Store the input durably and enqueue a job; returns the ``queued`` record.

        ``weld`` merges exactly coincident vertices when the input is read (the result keeps the
        input's vertex count and order).
        """
        ...

    def get(self, job_id: str) -> JobRecord | None:
        """The job's record (with its report once succeeded), ``None`` if unknown."""
        ...

    def list(
        self, offset: int = 0, limit: int = 50, status: JobStatus | str | None = None
    ) -> tuple[builtins.list[JobRecord], int]:
        """A page of jobs, newest first, and the total count matching ``status``."""
        ...

    def cancel(self, job_id: str) -> JobRecord | None:
        """Cancel a queued or running job (its process is killed); ``None`` if unknown.

        A finished job is returned unchanged.
        """
        ...

    def delete(self, job_id: str) -> bool:
        """Delete a finished job's record and files; ``False`` if unknown or not finished."""
        ...

    def result(self, job_id: str) -> GeometryDocument | None:
        """The input document with the smoothed points, ``None`` unless the job succeeded."""
        ...

    def stats(self) -> dict[str, Any]:
        """Counts by status, queue depth and solve durations (for Prometheus metrics)."""
        ...
