"""Frozen configurations of the two job backends, built from :class:`service.settings.Settings`.

A queue takes one config instead of a long list of keywords: :class:`LocalConfig` for the
embedded queue (and its worker pool), :class:`RQConfig` for the API side of the distributed
one. ``from_settings`` is how the service builds them; tests and scripts build them directly
with keywords. Every default that is also a setting is the setting's
(:func:`service.settings.default`); ``kill_grace``, ``poll_interval``, ``progress_interval`` and
the sweep intervals are not settings and keep their own defaults here.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.jobs.limits import default_job_memory
from service.jobs.runner import DEFAULT_RUNNER
from service.settings import default

if TYPE_CHECKING:
    from service.settings import Settings

__all__ = ["LocalConfig", "RQConfig", "job_memory_limit"]


def job_memory_limit(settings: Settings) -> int | None:
    """The per-job memory limit of these settings: ``job_memory_limit``, else a share of the
    machine's memory per worker (:func:`~service.jobs.limits.default_job_memory`); 0: none."""
    limit = settings.job_memory_limit
    if limit is None:
        limit = default_job_memory(settings.workers)
    return limit or None


@dataclass(frozen=True)
class LocalConfig:
    """The embedded queue (:class:`~service.jobs.embedded.queue.LocalQueue`) and its pool.

    Attributes
    ----------
    data_dir : Path
        Job store: ``jobs.sqlite3`` and ``jobs/<id>/`` (created if missing).
    workers : int
        Jobs running at once, each in its own process (``None`` given: ``os.cpu_count()``).
    job_timeout : float or None
        Seconds a run may take before it is killed and the job failed (``None`` or 0: no limit).
    result_ttl : float or None
        Seconds finished jobs and their files are kept (``None`` or 0: forever).
    runner : str
        Job function ``"module:function"`` (default: the real smoothing job). Tests inject fakes.
    max_attempts : int
        Runs allowed for a job whose runs keep being interrupted.
    start_method : str, optional
        ``"forkserver"`` (default on Linux) or ``"spawn"``.
    lease : float
        Seconds without a heartbeat after which another server takes over a running job.
    kill_grace : float
        Seconds between SIGTERM and SIGKILL when killing a job.
    sweep_interval : float
        Seconds between sweeps (expired results, runs of dead servers, webhooks, temp files);
        ``None`` given: a quarter of ``result_ttl``, between 1 and 60 s.
    poll_interval : float
        Seconds between looks at the store when idle (jobs submitted by other processes) and
        between ownership checks of a running job (cancelled from another process).
    progress_interval : float
        Minimum seconds between two progress writes of a job within one stage.
    retry_backoff : float
        Seconds before an interrupted job may run again (doubled per attempt, at most 300 s), so
        a burst of server crashes does not use up the attempts of the jobs at the head of the
        queue.
    memory_limit : int or None
        Per-job memory limit (bytes): refused at submit above it, ``RLIMIT_AS`` while running.
    threads_per_job : int or None
        BLAS/OpenMP threads per job process (``None``: cores / workers, see :attr:`threads`).
    min_free_bytes : int
        Free space a submit must leave in the store (else 507).
    reserve_bytes : int
        Size of the reserve file kept next to the database and released when the disk is full,
        so that running jobs can still be recorded as failed (0: none).
    settings : Settings, optional
        For webhook delivery (secret, SSRF policy, retries); ``None``: from the environment.
    """

    data_dir: Path
    workers: int = 0
    job_timeout: float | None = default("job_timeout")
    result_ttl: float | None = default("result_ttl")
    runner: str = DEFAULT_RUNNER
    max_attempts: int = default("max_attempts")
    start_method: str | None = None
    lease: float = default("worker_lease")
    kill_grace: float = 2.0
    sweep_interval: float = 0.0
    poll_interval: float = 0.5
    progress_interval: float = 0.2
    retry_backoff: float = default("retry_backoff")
    memory_limit: int | None = None
    threads_per_job: int | None = None
    min_free_bytes: int = default("min_free_bytes")
    reserve_bytes: int = default("reserve_bytes")
    settings: Settings | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.max_attempts < 1:
            raise ValueError("max_attempts must be >= 1")
        ttl = self.result_ttl or None
        sweep = self.sweep_interval or min(60.0, max(1.0, (ttl or 240.0) / 4))
        fixed = {
            "data_dir": Path(self.data_dir),
            "workers": int(self.workers or os.cpu_count() or 1),
            "job_timeout": self.job_timeout or None,
            "result_ttl": ttl,
            "sweep_interval": sweep,
        }
        for name, value in fixed.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_settings(cls, settings: Settings, **overrides: Any) -> LocalConfig:
        """The embedded queue the service runs with these settings (``overrides`` win)."""
        return cls(**{
            "data_dir": settings.data_dir,
            "workers": settings.workers,
            "job_timeout": settings.job_timeout,
            "result_ttl": settings.result_ttl,
            "max_attempts": settings.max_attempts,
            "lease": settings.worker_lease,
            "retry_backoff": settings.retry_backoff,
            "memory_limit": job_memory_limit(settings),
            "threads_per_job": settings.threads_per_job,
            "min_free_bytes": settings.min_free_bytes,
            "reserve_bytes": settings.reserve_bytes,
            "settings": settings,
            **overrides,
        })  # fmt: skip

    @property
    def threads(self) -> int:
        """BLAS/OpenMP threads per job process: ``threads_per_job``, else cores / workers."""
        from service.core.linalg.threads import threads_per_worker

        return self.threads_per_job or threads_per_worker(self.workers)

    def replace(self, **changes: Any) -> LocalConfig:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class RQConfig:
    """The API side of the distributed queue (:class:`~service.jobs.distributed.queue.RQQueue`).

    Attributes
    ----------
    settings : Settings
        Redis, blob store, limits, webhooks (shared with the workers).
    memory_limit : int or None
        Per-job memory limit for admission (bytes); ``None``: none.
    sweep_interval : float
        Seconds between sweeps (lost runs, due retries, TTL, webhooks).
    reconcile_interval : float
        Seconds between checks for queued jobs whose RQ job was lost.
    """

    settings: Settings = field(compare=False, repr=False)
    memory_limit: int | None = None
    sweep_interval: float = 1.0
    reconcile_interval: float = 60.0

    @classmethod
    def from_settings(cls, settings: Settings, **overrides: Any) -> RQConfig:
        """The distributed queue the API runs with these settings (``overrides`` win)."""
        return cls(**{"settings": settings, "memory_limit": job_memory_limit(settings),
                      **overrides})  # fmt: skip
